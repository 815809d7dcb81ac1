//! What `mocomp register` reports: the registration's figures (the landmarks' errors and FRE of
//! the final fit, the sweep's fit and what was left out, the error bound at each target), why it
//! was refused, and in a rehearsal its true error; as lines for a person or one JSON object.

use crate::register::Registered;
use mocomp_nav::CONFIDENCE;
use serde_json::{Value, json};
use std::collections::BTreeMap;

/// Millimetres in a metre.
const MM_PER_M: f64 = 1000.0;

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
