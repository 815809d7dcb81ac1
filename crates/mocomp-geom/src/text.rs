//! Poses and number rows as text, the one way every report prints them (metres and radians:
//! the units they hold; a report that shows millimetres converts before it calls these).

use crate::{rows_from_iso, ur_pose_from_iso};
use nalgebra::Isometry3;
use std::fmt::Write;

/// Numbers in fixed-width columns (10 wide, 6 decimals), separated by one space.
pub fn row(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:>10.6}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// A title line, the 4×4 matrix of `t` and, when `with_pose`, its UR pose vector, each line
/// ending in a newline.
pub fn transform(title: &str, t: &Isometry3<f64>, with_pose: bool) -> String {
    let mut s = format!("{title}:\n");
    for r in rows_from_iso(t) {
        // Writing to a String cannot fail.
        let _ = writeln!(s, "  [{} ]", row(&r));
    }
    if with_pose {
        let _ = writeln!(
            s,
            "  pose [x, y, z, rx, ry, rz] (m, rad): [{}]",
            row(&ur_pose_from_iso(t))
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn a_transform_prints_its_matrix_rows_and_pose() {
        let t = Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 0.3),
            UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2),
        );
        let s = transform("X", &t, true);
        let lines: Vec<&str> = s.lines().collect();
        assert_eq!(lines.len(), 6);
        assert_eq!(lines[0], "X:");
        assert_eq!(lines[1], "  [  0.000000  -1.000000   0.000000   0.100000 ]");
        assert!(
            lines[5]
                .ends_with("[  0.100000  -0.200000   0.300000   0.000000   0.000000   1.570796]")
        );
        assert_eq!(transform("X", &t, false).lines().count(), 5);
        assert_eq!(row(&[1.0, -2.5]), "  1.000000  -2.500000");
    }
}
