//! SimNIBS's coil files (`.ccd`): a `#` header line that may carry `key=value;` metadata (the
//! Drakaki et al. 2022 models give `dIdtmax` in A/µs at full output, `coilname`, `stimulator`,
//! `brand`), the number of dipoles, a `#` comment, then one dipole a line: its position (m)
//! and moment (A·m² per ampere of coil current), in the coil's frame (SimNIBS's: origin under
//! the centre of the coil's bottom, +z into the head, +y pointing away from the handle).
//!
//! Read strictly: a count that does not match the rows, a row without six finite numbers, or
//! more dipoles than any coil model has is refused with the line that says so.

use crate::error::EfieldError;
use mocomp_geom::nalgebra::Vector3;

/// The most dipoles a coil file may hold: SimNIBS's models have up to a few tens of thousands.
pub const MAX_DIPOLES: usize = 200_000;

/// A coil as magnetic dipoles in its own frame.
#[derive(Debug, Clone, PartialEq)]
pub struct DipoleCoil {
    /// `coilname` from the header, if it has one.
    pub name: Option<String>,
    /// The stimulator's dI/dt at full output, A/s (the header's `dIdtmax`, given in A/µs).
    pub didt_max_a_per_s: Option<f64>,
    /// Each dipole's position, m (coil frame).
    pub positions: Vec<Vector3<f64>>,
    /// Each dipole's moment per ampere, A·m²/A = m² (coil frame).
    pub moments: Vec<Vector3<f64>>,
}

impl DipoleCoil {
    /// How many dipoles.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether it has none (a file never gives such a coil).
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}

/// The coil in `text`, the `.ccd` file `file` (named in errors).
pub fn parse_ccd(file: &str, text: &str) -> Result<DipoleCoil, EfieldError> {
    let bad = |line: usize, what: String| EfieldError::Ccd {
        file: file.into(),
        line,
        what,
    };
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    let (_, header) = lines
        .next()
        .ok_or_else(|| bad(1, "empty: a coil file begins with a `#` header line".into()))?;
    let Some(header) = header.strip_prefix('#') else {
        return Err(bad(1, format!("{header:?}: a coil file begins with `#`")));
    };
    let (name, didt_max_a_per_s) = metadata(header).map_err(|what| bad(1, what))?;
    let (n_line, count) = lines
        .next()
        .ok_or_else(|| bad(2, "no dipole count".into()))?;
    let count: usize = count.parse().map_err(|_| {
        bad(
            n_line,
            format!("{count:?}: the number of dipoles, a whole number"),
        )
    })?;
    if count == 0 || count > MAX_DIPOLES {
        return Err(bad(
            n_line,
            format!("{count} dipoles: a coil has 1 to {MAX_DIPOLES}"),
        ));
    }
    let mut positions = Vec::with_capacity(count);
    let mut moments = Vec::with_capacity(count);
    for (line, row) in lines {
        if row.is_empty() || row.starts_with('#') {
            continue;
        }
        if positions.len() == count {
            return Err(bad(
                line,
                format!("more dipoles than the {count} the file says it has"),
            ));
        }
        let mut v = [0.0; 6];
        let mut fields = row.split_whitespace();
        for (k, slot) in v.iter_mut().enumerate() {
            let name = ["x", "y", "z", "mx", "my", "mz"][k];
            let f = fields
                .next()
                .ok_or_else(|| bad(line, format!("no {name}: a dipole is x y z mx my mz")))?;
            *slot = f
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(line, format!("{name} = {f:?}: not a finite number")))?;
        }
        if let Some(extra) = fields.next() {
            return Err(bad(
                line,
                format!("{extra:?} after mz: a dipole is six numbers"),
            ));
        }
        positions.push(Vector3::new(v[0], v[1], v[2]));
        moments.push(Vector3::new(v[3], v[4], v[5]));
    }
    if positions.len() != count {
        return Err(bad(
            text.lines().count(),
            format!("{} dipoles where the file says {count}", positions.len()),
        ));
    }
    Ok(DipoleCoil {
        name,
        didt_max_a_per_s,
        positions,
        moments,
    })
}

/// The header's `coilname` and `dIdtmax` (A/µs, returned in A/s).
fn metadata(header: &str) -> Result<(Option<String>, Option<f64>), String> {
    let (mut name, mut didt) = (None, None);
    for piece in header.split(';') {
        let Some((key, value)) = piece.split_once('=') else {
            continue;
        };
        let (key, value) = (key.trim(), value.trim());
        match key {
            "coilname" => name = Some(value.to_string()),
            "dIdtmax" => {
                let v = value
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite() && *v > 0.0)
                    .ok_or_else(|| format!("dIdtmax={value}: not a positive number (A/µs)"))?;
                didt = Some(v * 1e6);
            }
            _ => {}
        }
    }
    Ok((name, didt))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    const TWO: &str = "# x.ccd version 1.0; dIdtmax=114.73;coilname=T;\n2\n# centres\n\
        0.01 0 -0.005 0 0 1e-6\n-0.01 0 -0.005 0 0 -1e-6\n";

    #[test]
    fn a_coil_file_reads_with_its_metadata() {
        let c = parse_ccd("x.ccd", TWO).unwrap();
        assert_eq!(c.len(), 2);
        assert_eq!(c.name.as_deref(), Some("T"));
        assert!((c.didt_max_a_per_s.unwrap() - 114.73e6).abs() < 1e-3);
        assert_eq!(c.positions[1], Vector3::new(-0.01, 0.0, -0.005));
        assert_eq!(c.moments[1], Vector3::new(0.0, 0.0, -1e-6));
    }

    #[test]
    fn a_bad_file_is_refused_by_its_line_and_field() {
        let cases = [
            ("", 1, "empty"),
            ("2\n", 1, "begins with"),
            ("# h\nmany\n", 2, "whole number"),
            ("# h\n0\n", 2, "1 to"),
            ("# h\n999999999\n", 2, "1 to"),
            ("# h\n1\n# c\n0 0 0 0 0\n", 4, "no mz"),
            ("# h\n1\n# c\n0 0 nan 0 0 1\n", 4, "z = \"nan\""),
            ("# h\n1\n# c\n0 0 0 0 0 1 7\n", 4, "after mz"),
            ("# h\n1\n# c\n0 0 0 0 0 1\n1 1 1 0 0 1\n", 5, "more dipoles"),
            (
                "# h\n3\n# c\n0 0 0 0 0 1\n",
                4,
                "1 dipoles where the file says 3",
            ),
            ("# dIdtmax=fast;\n1\n0 0 0 0 0 1\n", 1, "dIdtmax"),
        ];
        for (text, line, says) in cases {
            let e = parse_ccd("c.ccd", text).unwrap_err();
            let EfieldError::Ccd { line: l, .. } = &e else {
                unreachable!()
            };
            assert_eq!(*l, line, "{text:?}: {e}");
            assert!(e.to_string().contains(says), "{text:?}: {e}");
            assert!(e.to_string().starts_with("c.ccd:"), "{e}");
        }
    }

    proptest::proptest! {
        /// Any text: an answer, never a panic.
        #[test]
        fn any_text_is_read_or_refused(text in "(#[ -~]{0,30}\n)?[0-9 .e+-]{0,40}(\n[0-9 .e+-]{0,60}){0,6}") {
            let _ = parse_ccd("p.ccd", &text);
        }
    }
}
