//! A session's pulses as a Localite TMS Navigator trigger-marker file (`TriggerMarkers_Coil0_*.xml`
//! in a session's `TMSTrigger/` folder), the layout of the real ones SimNIBS keeps for its tests:
//! a `TriggerMarkerList` in RAS with its `startTime`, each pulse a `TriggerMarker` (its
//! `recordingTime` in ms from the start, the target as its `description`, the stimulator's
//! output as `amplitudeA` in %) and the coil's `Matrix4D` in mm and Localite's coil axes (the
//! inverse of what [`crate::read`] reads: `M_localite = M_simnibs · A`, `A` its own
//! inverse). A pulse without a coil pose is written as Localite writes an untracked coil: the
//! identity, `set="false"`.
//!
//! Text only; the caller writes the file.

use crate::read::localite_axes;
use mocomp_session::{Pulse, iso8601};
use quick_xml::Writer;
use quick_xml::events::{BytesDecl, BytesEnd, BytesStart, BytesText, Event};

fn number(v: f64) -> String {
    if v.is_finite() {
        // Shortest text that reads back to the same f64 (Localite writes Java doubles alike).
        format!("{v:?}")
    } else {
        "NaN".into()
    }
}

/// The file's text for `pulses` (in the log's order).
pub fn trigger_markers(pulses: &[Pulse]) -> Result<String, std::io::Error> {
    let mut w = Writer::new_with_indent(Vec::new(), b' ', 4);
    w.write_event(Event::Decl(BytesDecl::new("1.0", Some("UTF-8"), None)))?;
    let t0 = pulses.first().map_or(0.0, |p| p.t_s);
    // Localite's start time is the clock time of day; the record's is UTC.
    let start = pulses
        .first()
        .and_then(|p| p.utc_unix_s)
        .map(iso8601)
        .and_then(|s| {
            s.split_once('T')
                .map(|(_, t)| t.trim_end_matches('Z').to_string())
        })
        .unwrap_or_default();
    w.write_event(Event::Start(
        BytesStart::new("TriggerMarkerList").with_attributes([
            ("coordinateSpace", "RAS"),
            ("isOnlineReading", "false"),
            ("startTime", start.as_str()),
        ]),
    ))?;
    w.write_event(Event::Comment(BytesText::new(
        "Written by mocomp from its pulse log. All positions are in the coordinate system of the \
         session's image (RAS, mm); startTime is UTC.",
    )))?;
    w.write_event(Event::Start(
        BytesStart::new("ResponseParameters").with_attributes([("selectedResponseChannel", "0")]),
    ))?;
    for (id, max, min, name, unit) in [
        ("response", "51200.0", "-51200.0", "Response", "uV"),
        ("valueA", "200.0", "0.0", "Value A (di/dt)", "A/us"),
        ("amplitudeA", "100.0", "0.0", "Amplitude A", "%"),
    ] {
        w.write_event(Event::Empty(
            BytesStart::new("responseDescription").with_attributes([
                ("id", id),
                ("maxValue", max),
                ("minValue", min),
                ("name", name),
                ("unit", unit),
            ]),
        ))?;
    }
    w.write_event(Event::End(BytesEnd::new("ResponseParameters")))?;
    let axes = localite_axes();
    for p in pulses {
        let recording = format!("{:.0}", ((p.t_s - t0) * 1e3).max(0.0));
        let set = if p.image_from_coil.is_some() {
            "true"
        } else {
            "false"
        };
        w.write_event(Event::Start(
            BytesStart::new("TriggerMarker").with_attributes([
                ("color", "#ffafaf"),
                ("description", p.target.as_str()),
                ("recordingTime", recording.as_str()),
                ("selected", "false"),
                ("set", set),
                ("visibility", "true"),
            ]),
        ))?;
        w.write_event(Event::Start(BytesStart::new("ResponseValues")))?;
        for (key, v) in [
            ("valueA", f64::NAN),
            ("response", f64::NAN),
            ("amplitudeA", p.output_pct.unwrap_or(f64::NAN)),
        ] {
            let v = number(v);
            w.write_event(Event::Empty(
                BytesStart::new("Value").with_attributes([("key", key), ("response", v.as_str())]),
            ))?;
        }
        w.write_event(Event::End(BytesEnd::new("ResponseValues")))?;
        let m = match &p.image_from_coil {
            Some(pose) => {
                let mut m = pose.to_homogeneous() * axes;
                for r in 0..3 {
                    m[(r, 3)] *= 1e3;
                }
                m
            }
            None => mocomp_geom::nalgebra::Matrix4::identity(),
        };
        let values: Vec<(String, String)> = (0..16)
            .map(|i| (format!("data{}{}", i / 4, i % 4), number(m[(i / 4, i % 4)])))
            .collect();
        w.write_event(Event::Empty(BytesStart::new("Matrix4D").with_attributes(
            values.iter().map(|(k, v)| (k.as_str(), v.as_str())),
        )))?;
        w.write_event(Event::End(BytesEnd::new("TriggerMarker")))?;
    }
    w.write_event(Event::End(BytesEnd::new("TriggerMarkerList")))?;
    let mut text = String::from_utf8(w.into_inner())
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))?;
    text.push('\n');
    Ok(text)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use crate::read::{Navigator, parse_poses};
    use mocomp_geom::nalgebra::{Isometry3, Vector3};

    fn pulse(t: f64, pose: Option<Isometry3<f64>>) -> Pulse {
        Pulse {
            t_s: t,
            utc_unix_s: Some(1_796_000_000.0 + t),
            stimulator_unix_s: None,
            target: "C3 & \"left\"".into(),
            position_error_m: 0.0,
            angle_error_rad: 0.0,
            scalp_distance_m: 0.0,
            output_pct: Some(62.0),
            head_speed: (0.0, 0.0),
            gate_open: true,
            why_shut: String::new(),
            image_from_coil: pose,
            dose_v_per_m: f64::NAN,
            dose_pct: f64::NAN,
        }
    }

    #[test]
    fn the_importer_reads_back_every_tracked_pulse_to_the_same_pose() {
        let poses: Vec<Isometry3<f64>> = (0..5)
            .map(|k| {
                let k = f64::from(k);
                Isometry3::new(
                    Vector3::new(-0.04 + 0.003 * k, 0.012, 0.085 - 0.001 * k),
                    Vector3::new(2.8, 0.3 * k - 0.6, 0.2),
                )
            })
            .collect();
        let mut pulses: Vec<Pulse> = poses
            .iter()
            .enumerate()
            .map(|(k, p)| pulse(10.0 + 0.2 * k as f64, Some(*p)))
            .collect();
        // An untracked pulse between them: written, and skipped by the importer as Localite's
        // own untracked markers are.
        pulses.insert(2, pulse(10.3, None));
        let text = trigger_markers(&pulses).unwrap();
        assert!(text.contains("startTime=\"00:53:30\""), "{text}");
        assert!(text.contains("recordingTime=\"300\""), "{text}");
        assert!(
            text.contains("key=\"amplitudeA\" response=\"62.0\""),
            "{text}"
        );
        assert_eq!(text.matches("<TriggerMarker ").count(), 6);
        assert_eq!(text.matches("set=\"false\"").count(), 1);
        let back = parse_poses(Navigator::Localite, "TriggerMarkers_Coil0.xml", &text).unwrap();
        assert_eq!(back.len(), poses.len());
        for (b, p) in back.iter().zip(&poses) {
            // The target's name, escaped on the way out and unescaped on the way in.
            assert_eq!(b.name, "C3 & \"left\"");
            let d = (b.image_from_coil.translation.vector - p.translation.vector).norm();
            assert!(d < 1e-12, "{d}");
            // (An angle near zero is an arccosine near one: 1e-8 is the floor of its noise.)
            assert!(b.image_from_coil.rotation.angle_to(&p.rotation) < 1e-7);
        }
    }

    #[test]
    fn the_layout_is_localites() {
        let text = trigger_markers(&[pulse(0.0, None)]).unwrap();
        for part in [
            "<?xml version=\"1.0\" encoding=\"UTF-8\"?>",
            "<TriggerMarkerList coordinateSpace=\"RAS\" isOnlineReading=\"false\" startTime=\"00:53:20\">",
            "<responseDescription id=\"valueA\" maxValue=\"200.0\" minValue=\"0.0\" name=\"Value A (di/dt)\" unit=\"A/us\"/>",
            "<Value key=\"valueA\" response=\"NaN\"/>",
            "data00=\"1.0\"",
            "data33=\"1.0\"",
            "</TriggerMarkerList>",
        ] {
            assert!(text.contains(part), "{part}: {text}");
        }
    }
}
