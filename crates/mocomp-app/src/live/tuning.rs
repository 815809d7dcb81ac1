//! Changing a running session's configuration (the console's `POST /api/params`): a partial
//! configuration, merged into the running one and checked as a file is, each refusal naming its
//! key. Only keys the session can take while it runs may change: `[loop]`'s (between two cycles)
//! and `[tracker.camera.params]` (the camera's pipeline, before its next frame). The rest (the
//! robot, the tracker, the frames, the goal, the models, the predictor) fixes what the session
//! connected to and computed at start, and changes with a restart.

use crate::config::Config;
use serde_json::{Map, Value};

/// The sections whose keys may change while the loop runs: the loop's parameters, and the
/// camera pipeline's.
pub const LIVE_SECTIONS: [&str; 3] = ["loop", "tracker.camera.params", "tracker.k4a.params"];

/// A change refused: the key (`loop.speed_fraction`, or the section when the whole change is
/// malformed) and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{key}: {problem}")]
pub struct Refusal {
    /// The key's dotted path.
    pub key: String,
    /// What is wrong with its value.
    pub problem: String,
}

impl Refusal {
    fn new(key: impl Into<String>, problem: impl Into<String>) -> Self {
        Self {
            key: key.into(),
            problem: problem.into(),
        }
    }
}

/// A change accepted: the configuration with it, and the keys whose values changed.
#[derive(Debug, Clone, PartialEq)]
pub struct Tuned {
    /// The running configuration with the change.
    pub config: Config,
    /// The keys (dotted paths) whose values changed.
    pub changed: Vec<String>,
}

/// `current` with `patch` (a JSON object of sections and keys, as in the file) merged in,
/// checked as a configuration file is. Refused, naming the key: a key that does not exist, a
/// value of the wrong type or out of range, a key outside [`LIVE_SECTIONS`].
pub fn apply(current: &Config, patch: &Value) -> Result<Tuned, Refusal> {
    let Value::Object(patch) = patch else {
        return Err(Refusal::new(
            "(body)",
            "must be a JSON object of sections and keys, e.g. {\"loop\": {\"speed_fraction\": 0.4}}",
        ));
    };
    let mut leaves = Vec::new();
    collect_leaves(patch, "", &mut leaves);
    if leaves.is_empty() {
        return Err(Refusal::new("(body)", "names no key"));
    }
    let mut merged = serde_json::to_value(current)
        .map_err(|e| Refusal::new("(configuration)", e.to_string()))?;
    merge(&mut merged, patch);
    // The key's whole path in a refusal (`loop.speed_fraction: invalid type …`).
    let parsed: Config = serde_path_to_error::deserialize(&merged).map_err(|e| {
        Refusal::new(
            e.path().to_string(),
            e.inner().to_string().trim_end().replace('\n', " "),
        )
    })?;
    let before = serde_json::to_value(current).unwrap_or(Value::Null);
    let after = serde_json::to_value(&parsed).unwrap_or(Value::Null);
    let changed: Vec<String> = leaves
        .into_iter()
        .filter(|k| pointer(&before, k) != pointer(&after, k))
        .collect();
    if let Some(k) = changed.iter().find(|k| {
        !LIVE_SECTIONS
            .iter()
            .any(|s| k.starts_with(&format!("{s}.")))
    }) {
        return Err(Refusal::new(
            k.clone(),
            "cannot change while the loop runs (only [loop], [tracker.camera.params] and \
             [tracker.k4a.params] keys can); change it in the configuration file and restart",
        ));
    }
    // Only the live sections are taken over: the rest of `current` stays as it was loaded (a
    // recorded motion's samples, which a round trip through JSON would not keep).
    let mut config = current.clone();
    config.params = parsed.params;
    config.tracker.camera.params = parsed.tracker.camera.params;
    config.tracker.k4a.params = parsed.tracker.k4a.params;
    config.check().map_err(|e| {
        let message = e.to_string();
        // The checks name their key first (`loop.speed_fraction = 2: must be …`).
        let key = changed
            .iter()
            .find(|k| message.starts_with(k.as_str()))
            .or(changed.first())
            .cloned()
            .unwrap_or_else(|| "(configuration)".into());
        Refusal::new(key, message)
    })?;
    Ok(Tuned { config, changed })
}

/// The dotted paths of `obj`'s leaves (values that are not objects).
fn collect_leaves(obj: &Map<String, Value>, prefix: &str, out: &mut Vec<String>) {
    for (k, v) in obj {
        let path = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            Value::Object(inner) => collect_leaves(inner, &path, out),
            _ => out.push(path),
        }
    }
}

/// Merges `patch` into `into`, object by object; other values replace.
fn merge(into: &mut Value, patch: &Map<String, Value>) {
    let Value::Object(target) = into else {
        *into = Value::Object(patch.clone());
        return;
    };
    for (k, v) in patch {
        match (target.get_mut(k), v) {
            (Some(t @ Value::Object(_)), Value::Object(p)) => merge(t, p),
            _ => {
                target.insert(k.clone(), v.clone());
            }
        }
    }
}

/// The value at a dotted path.
fn pointer<'a>(v: &'a Value, dotted: &str) -> Option<&'a Value> {
    v.pointer(&format!("/{}", dotted.replace('.', "/")))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use serde_json::json;

    #[test]
    fn a_loop_key_changes_and_is_named() {
        let c = Config::default();
        let t = apply(&c, &json!({"loop": {"speed_fraction": 0.3}})).unwrap();
        assert_eq!(t.changed, vec!["loop.speed_fraction".to_string()]);
        assert_eq!(t.config.params.speed_fraction, 0.3);
        // Nothing else moved.
        let mut back = t.config.clone();
        back.params.speed_fraction = c.params.speed_fraction;
        assert_eq!(back, c);
    }

    #[test]
    fn the_same_value_changes_nothing() {
        let c = Config::default();
        let t = apply(&c, &json!({"loop": {"speed_fraction": 0.75}})).unwrap();
        assert!(t.changed.is_empty());
        assert_eq!(t.config, c);
    }

    #[test]
    fn refusals_name_the_key() {
        let c = Config::default();
        let refused = |patch: Value| apply(&c, &patch).unwrap_err();
        // Out of range: the config file's own check and message.
        let r = refused(json!({"loop": {"speed_fraction": 2.0}}));
        assert_eq!(r.key, "loop.speed_fraction");
        assert!(
            r.problem.starts_with("loop.speed_fraction = 2: must be in"),
            "{r}"
        );
        // A key that does not exist.
        let r = refused(json!({"loop": {"speed_fractoin": 0.3}}));
        assert!(r.key.starts_with("loop"), "{r}");
        assert!(r.problem.contains("speed_fractoin"), "{r}");
        // The wrong type.
        let r = refused(json!({"loop": {"speed_fraction": "fast"}}));
        assert_eq!(r.key, "loop.speed_fraction");
        // Not live.
        let r = refused(json!({"robot": {"model": "ur5"}}));
        assert_eq!(r.key, "robot.model");
        assert!(r.problem.contains("restart"), "{r}");
        // Not an object, or empty.
        assert_eq!(refused(json!([1, 2])).key, "(body)");
        assert_eq!(refused(json!({})).key, "(body)");
    }

    #[test]
    fn the_camera_pipelines_keys_change_and_are_checked_as_in_the_file() {
        let c = Config::default();
        let t = apply(
            &c,
            &json!({"tracker": {"camera": {"params": {"ir_threshold": 30000, "scan_area": [10, 20, 300, 200]}}}}),
        )
        .unwrap();
        assert_eq!(t.config.tracker.camera.params.ir_threshold, 30000);
        assert_eq!(
            t.config.tracker.camera.params.scan_area,
            Some([10, 20, 300, 200])
        );
        assert_eq!(t.changed.len(), 2);
        let r = apply(
            &c,
            &json!({"tracker": {"camera": {"params": {"depth_min_mm": 3000}}}}),
        )
        .unwrap_err();
        assert_eq!(r.key, "tracker.camera.params.depth_min_mm");
        assert!(r.problem.contains("must be below depth_max_mm"), "{r}");
        // Cleared again (null: the whole image).
        let back = apply(
            &t.config,
            &json!({"tracker": {"camera": {"params": {"scan_area": null}}}}),
        )
        .unwrap();
        assert_eq!(back.config.tracker.camera.params.scan_area, None);
        // The Azure Kinect's pipeline is live as well.
        let t = apply(
            &c,
            &json!({"tracker": {"k4a": {"params": {"ir_threshold": 25000}}}}),
        )
        .unwrap();
        assert_eq!(t.config.tracker.k4a.params.ir_threshold, 25000);
        assert_eq!(
            t.changed,
            vec!["tracker.k4a.params.ir_threshold".to_string()]
        );
        let r = apply(&c, &json!({"tracker": {"k4a": {"fps": 15}}})).unwrap_err();
        assert_eq!(r.key, "tracker.k4a.fps");
        // The camera's other keys are not live.
        let r = apply(&c, &json!({"tracker": {"camera": {"rate_hz": 15.0}}})).unwrap_err();
        assert_eq!(r.key, "tracker.camera.rate_hz");
    }

    #[test]
    fn an_unchanged_key_outside_loop_beside_a_loop_change_is_accepted() {
        // The page may send a whole section it shows; an unchanged value is no change.
        let c = Config::default();
        let t = apply(
            &c,
            &json!({"loop": {"max_tcp_speed_m_s": 0.2}, "robot": {"model": "ur3"}}),
        )
        .unwrap();
        assert_eq!(t.changed, vec!["loop.max_tcp_speed_m_s".to_string()]);
    }
}
