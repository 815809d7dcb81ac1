//! What `mocomp register` reports: the registration's figures (the landmarks' errors and FRE of
//! the final fit, the sweep's fit and what was left out, the error bound at each target), why it
//! was refused, and in a rehearsal its true error; as lines for a person or one JSON object.

use crate::AppError;
use crate::registration::register::{Checked, Registered};
use mocomp_nav::CONFIDENCE;
use serde_json::{Value, json};
use std::collections::BTreeMap;

use mocomp_geom::units::MM_PER_M;

/// The report's lines; `truth` is a rehearsal's true error at each target (m).
pub fn lines(r: &Registered, truth: Option<&[(String, f64)]>) -> Vec<String> {
    let o = &r.outcome;
    let mut out = Vec::new();
    match &o.registration {
        Err(e) => out.push(format!("no registration: {e}")),
        Ok(reg) => {
            out.push(format!(
                "registered: FRE {:.2} mm ({})",
                reg.fre_m * MM_PER_M,
                reg.landmarks
                    .iter()
                    .map(|l| format!("{} {:.2}", l.name, l.error_m * MM_PER_M))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
            if let Some(s) = reg.surface {
                let rj = o.rejects;
                out.push(format!(
                    "  sweep: {} points, {:.2} mm RMS off the scalp ({:.2} expected); left out: {} \
                     off the skin, {} on the scan's cut; tips not taken: {} approaching or \
                     lifting, {} paused, {} in the air",
                    s.used,
                    s.rms_m * MM_PER_M,
                    s.expected_rms_m * MM_PER_M,
                    s.off_skin,
                    s.on_cut,
                    rj.moving_across,
                    rj.paused,
                    rj.in_the_air
                ));
            } else {
                out.push("  no sweep: the landmarks alone".into());
            }
        }
    }
    for (name, b) in &o.bounds {
        out.push(format!(
            "  error at {name}: within {:.1} mm ({:.0} % bound)",
            b * MM_PER_M,
            CONFIDENCE * 100.0
        ));
    }
    for (name, e) in truth.unwrap_or_default() {
        out.push(format!(
            "  true error at {name}: {:.2} mm (the simulated world's truth)",
            e * MM_PER_M
        ));
    }
    if !o.refusals.is_empty() {
        out.push("REFUSED, not written:".into());
        out.extend(o.refusals.iter().map(|f| format!("  - {f}")));
    }
    out
}

/// The report as one JSON object; `file` is where it was written (none: refused).
pub fn json(r: &Registered, truth: Option<&[(String, f64)]>, file: Option<&str>) -> Value {
    let o = &r.outcome;
    let mm = |v: &[(String, f64)]| -> BTreeMap<String, f64> {
        v.iter().map(|(k, x)| (k.clone(), x * MM_PER_M)).collect()
    };
    let mut v = json!({
        "usable": r.usable(),
        "refusals": o.refusals.iter().map(ToString::to_string).collect::<Vec<_>>(),
        "confidence": CONFIDENCE,
        "tre_mm": mm(&o.bounds),
        "file": file,
        "sweep_not_taken": {
            "approaching_or_lifting": o.rejects.moving_across,
            "paused": o.rejects.paused,
            "in_the_air": o.rejects.in_the_air,
        },
    });
    if let Some(t) = truth {
        v["true_error_mm"] = json!(mm(t));
    }
    match &o.registration {
        Err(e) => v["error"] = json!(e.to_string()),
        Ok(reg) => {
            let head_from_image = reg.image_from_marker.inverse();
            let (t, rv) = (
                head_from_image.translation.vector,
                head_from_image.rotation.scaled_axis(),
            );
            v["head_from_image"] = json!([t.x, t.y, t.z, rv.x, rv.y, rv.z]);
            v["fre_mm"] = json!(reg.fre_m * MM_PER_M);
            v["landmarks"] = json!(
                reg.landmarks
                    .iter()
                    .map(|l| (
                        l.name.clone(),
                        json!({
                            "error_mm": l.error_m * MM_PER_M,
                            "skin_mm": l.skin_m * MM_PER_M,
                            "chi2": l.chi2,
                            "chi2_limit": l.chi2_limit,
                            "image_offset_mm": l.image_offset_m * MM_PER_M,
                        })
                    ))
                    .collect::<BTreeMap<_, _>>()
            );
            let s = reg.surface;
            v["surface_rms_mm"] = json!(s.map_or(0.0, |s| s.rms_m * MM_PER_M));
            v["surface_points"] = json!(s.map_or(0, |s| s.used));
            v["surface_off_skin"] = json!(s.map_or(0, |s| s.off_skin));
            v["surface_on_cut"] = json!(s.map_or(0, |s| s.on_cut));
        }
    }
    v
}

/// `register check`'s line: how far the landmark lies from where it was touched.
impl std::fmt::Display for Checked {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: {:.2} mm from where it was touched at registration{}",
            self.name,
            self.moved_m * MM_PER_M,
            if self.moved { "" } else { ": the marker holds" }
        )
    }
}

/// `register check`'s JSON.
pub fn checked_json(c: &Checked) -> Value {
    json!({
        "landmark": c.name,
        "moved_mm": c.moved_m * MM_PER_M,
        "limit_mm": c.limit_m * MM_PER_M,
        "moved": c.moved,
    })
}

/// The refusal when the head marker moved on the head since the registration.
pub fn checked_refusal(c: &Checked) -> Option<AppError> {
    c.moved.then(|| {
        AppError::Refused(format!(
            "the head marker moved on the head ({:.1} mm at the {}, more than a touch's {:.1} mm): register again",
            c.moved_m * MM_PER_M,
            c.name,
            c.limit_m * MM_PER_M
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checked(moved_m: f64) -> Checked {
        Checked {
            name: "nasion".into(),
            moved_m,
            limit_m: 0.003,
            moved: moved_m > 0.003,
        }
    }

    #[test]
    fn a_landmark_within_its_limit_holds_and_one_beyond_it_refuses_the_session() {
        let held = checked(0.0012);
        assert_eq!(
            held.to_string(),
            "nasion: 1.20 mm from where it was touched at registration: the marker holds"
        );
        assert!(checked_refusal(&held).is_none());
        let moved = checked(0.0047);
        assert_eq!(
            moved.to_string(),
            "nasion: 4.70 mm from where it was touched at registration"
        );
        let Some(AppError::Refused(why)) = checked_refusal(&moved) else {
            panic!("a moved marker must refuse");
        };
        assert!(
            why.contains("(4.7 mm at the nasion, more than a touch's 3.0 mm)"),
            "{why}"
        );
        let json = checked_json(&moved);
        assert_eq!(json["moved"], true);
        assert!((json["moved_mm"].as_f64().unwrap_or(0.0) - 4.7).abs() < 1e-9);
        assert!((json["limit_mm"].as_f64().unwrap_or(0.0) - 3.0).abs() < 1e-9);
    }
}
