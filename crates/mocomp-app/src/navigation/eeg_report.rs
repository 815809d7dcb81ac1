//! What `mocomp head eeg` reports: the positions (a line each, or one JSON object by name), and
//! how far the configuration's landmarks lie off the scalp they are measured from.

use crate::navigation::{LANDMARK_OFF_SCALP_WARN_M, mm_from_point};
use mocomp_nav::EegPosition;
use serde_json::{Map, Value, json};

use mocomp_geom::units::MM_PER_M;

/// A position's line: name, then x, y, z in mm (image RAS).
pub fn line(p: &EegPosition) -> String {
    let [x, y, z] = mm_from_point(&p.point);
    format!("{:<4} {x:8.1} {y:8.1} {z:8.1}  mm (image RAS)", p.name)
}

/// The positions as one JSON object, each name to [x, y, z] mm.
pub fn json(positions: &[EegPosition]) -> Value {
    let map: Map<String, Value> = positions
        .iter()
        .map(|p| (p.name.to_string(), json!(mm_from_point(&p.point))))
        .collect();
    Value::Object(map)
}

/// The landmarks' signed distances off the scalp (`offsets`: name and m, + outside) as a line,
/// and a warning when any is further than [`LANDMARK_OFF_SCALP_WARN_M`].
pub fn landmark_lines(offsets: &[(String, f64)]) -> Vec<String> {
    let all: Vec<String> = offsets
        .iter()
        .map(|(n, d)| format!("{n} {:+.1}", d * MM_PER_M))
        .collect();
    let mut lines = vec![format!(
        "landmarks off the scalp (mm, + outside): {}",
        all.join(", ")
    )];
    let far: Vec<String> = offsets
        .iter()
        .filter(|(_, d)| d.abs() > LANDMARK_OFF_SCALP_WARN_M)
        .map(|(n, d)| {
            let side = if *d > 0.0 { "outside" } else { "inside" };
            format!("{n} {:.1} mm {side}", d.abs() * MM_PER_M)
        })
        .collect();
    if !far.is_empty() {
        lines.push(format!(
            "warning: landmarks more than {:.0} mm from the scalp: {}; the positions are \
             measured from the scalp points nearest them: place the landmarks on the skin in \
             [head.landmarks]",
            LANDMARK_OFF_SCALP_WARN_M * MM_PER_M,
            far.join(", ")
        ));
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_landmarks_beyond_the_limit_are_warned_of_each_with_its_side() {
        let offsets = [
            ("nasion".to_string(), 0.0015),
            ("lpa".to_string(), -0.0031),
            ("rpa".to_string(), 0.0042),
        ];
        let lines = landmark_lines(&offsets);
        assert_eq!(
            lines[0],
            "landmarks off the scalp (mm, + outside): nasion +1.5, lpa -3.1, rpa +4.2"
        );
        assert_eq!(lines.len(), 2);
        assert!(lines[1].contains(": lpa 3.1 mm inside, rpa 4.2 mm outside;"));
        assert!(!lines[1].contains("nasion"));
        assert_eq!(landmark_lines(&offsets[..1]).len(), 1);
    }
}
