//! Value parsers for command-line arguments. Each error is one line that clap prefixes with the
//! argument's name.

use mocomp_kin::Model;

/// Parses exactly `N` comma-separated finite numbers.
pub fn numbers<const N: usize>(s: &str) -> Result<[f64; N], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != N {
        return Err(format!(
            "expected {N} comma-separated numbers, got {}",
            parts.len()
        ));
    }
    let mut out = [0.0; N];
    for (i, (slot, text)) in out.iter_mut().zip(parts.iter()).enumerate() {
        let v: f64 = text
            .parse()
            .map_err(|_| format!("element {} ({text:?}) is not a number", i + 1))?;
        if !v.is_finite() {
            return Err(format!(
                "element {} ({text:?}) is not a finite number",
                i + 1
            ));
        }
        *slot = v;
    }
    Ok(out)
}

/// Six numbers (joints, or a UR pose vector).
pub fn six(s: &str) -> Result<[f64; 6], String> {
    numbers::<6>(s)
}

/// Two non-negative numbers: a noise level in millimetres and degrees.
pub fn noise_pair(s: &str) -> Result<[f64; 2], String> {
    let v = numbers::<2>(s)?;
    if v.iter().any(|x| *x < 0.0) {
        return Err("noise levels must not be negative".into());
    }
    Ok(v)
}

/// A robot model name.
pub fn model(s: &str) -> Result<Model, String> {
    s.parse::<Model>().map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_rejects() {
        assert_eq!(six("1, 2,3,4,5,6e-1").unwrap()[5], 0.6);
        assert!(six("1,2,3").unwrap_err().contains("got 3"));
        assert!(six("1,2,x,4,5,6").unwrap_err().contains("element 3"));
        assert!(six("1,2,3,4,5,NaN").unwrap_err().contains("not a finite"));
        assert!(six("1,2,3,4,5,inf").unwrap_err().contains("not a finite"));
        assert!(model("ur7").unwrap_err().contains("known"));
        assert_eq!(model("UR10e").unwrap(), Model::Ur10e);
    }
}
