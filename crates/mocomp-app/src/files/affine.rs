//! An affine from a text file (image_from_mni, mm): four rows of four numbers, for MNI
//! coordinates of targets from the literature.

use crate::AppError;
use mocomp_geom::nalgebra::Matrix4;

/// Reads an affine (image_from_mni, millimetres) from a text file: four rows of four numbers
/// (blank lines and `#` comments skipped), the last row 0 0 0 1.
pub fn read_affine(path: &std::path::Path) -> Result<Matrix4<f64>, AppError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path)
        .map_err(|e| AppError::failed(format!("reading the affine {name}"), e))?;
    parse_affine(&name, &text)
}

/// [`read_affine`] on the text of `file`.
pub fn parse_affine(file: &str, text: &str) -> Result<Matrix4<f64>, AppError> {
    let bad = |line: usize, why: String| AppError::Config(format!("{file}:{line}: {why}"));
    let mut rows: Vec<[f64; 4]> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let body = line.split('#').next().unwrap_or("").trim();
        if body.is_empty() {
            continue;
        }
        if rows.len() == 4 {
            return Err(bad(line_no, "more than four rows".into()));
        }
        let v: Vec<&str> = body
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|s| !s.is_empty())
            .collect();
        if v.len() != 4 {
            return Err(bad(line_no, format!("{} numbers, a row has 4", v.len())));
        }
        let mut row = [0.0; 4];
        for (k, (slot, s)) in row.iter_mut().zip(&v).enumerate() {
            *slot = s
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    bad(
                        line_no,
                        format!("column {}: {s:?} is not a finite number", k + 1),
                    )
                })?;
        }
        rows.push(row);
    }
    if rows.len() != 4 {
        return Err(AppError::Config(format!(
            "{file}: {} rows, an affine has 4",
            rows.len()
        )));
    }
    let last = rows[3];
    if (last[0].abs() + last[1].abs() + last[2].abs() + (last[3] - 1.0).abs()) > 1e-9 {
        return Err(AppError::Config(format!(
            "{file}: the last row is {last:?}, an affine's is 0 0 0 1"
        )));
    }
    let m = Matrix4::from_fn(|r, c| rows[r][c]);
    if m.fixed_view::<3, 3>(0, 0).determinant().abs() < 1e-9 {
        return Err(AppError::Config(format!(
            "{file}: the affine is singular (it flattens space)"
        )));
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use mocomp_geom::nalgebra::Point3;

    #[test]
    fn an_affine_file_is_read_and_every_fault_is_named_by_line() {
        let m = parse_affine(
            "a.txt",
            "# image_from_mni\n1 0 0 -2\n0 1 0 3.5\n\n0,0,1,4\n0 0 0 1\n",
        )
        .unwrap();
        assert_eq!(
            m.transform_point(&Point3::origin()),
            Point3::new(-2.0, 3.5, 4.0)
        );
        for (text, says) in [
            ("1 0 0\n", "a.txt:1: 3 numbers"),
            ("1 0 0 0\n0 1 0 0\n0 0 1 x\n0 0 0 1\n", "a.txt:3: column 4"),
            ("1 0 0 0\n0 1 0 0\n0 0 1 0\n", "3 rows"),
            ("1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n", "last row"),
            ("1 0 0 0\n0 1 0 0\n0 0 0 0\n0 0 0 1\n", "singular"),
            (
                "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n0 0 0 1\n",
                "a.txt:5: more than four",
            ),
        ] {
            let e = parse_affine("a.txt", text).unwrap_err().to_string();
            assert!(e.contains(says), "{text:?}: {e}");
        }
    }
}
