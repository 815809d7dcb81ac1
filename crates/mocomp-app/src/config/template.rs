//! The configuration as a file with comments (`mocomp config print`): the commented template
//! (`config.toml` beside this module, every key at its default) with the effective values put in.
//! A test holds the template to [`Config::default`], so the defaults stay in one place and the
//! comments cannot drift from them.

use crate::AppError;
use crate::config::Config;
use toml_edit::{DocumentMut, Item, Table};

/// Every key at its default, with comments: the file `mocomp config print` starts from.
pub const TEMPLATE: &str = include_str!("config.toml");

/// `cfg` as a commented file: the template's comments, `cfg`'s values. A value equal to the
/// template's keeps the template's spelling; keys `cfg` leaves unset (optional ones) go; keys the
/// template lacks (a motion of another kind) are added.
pub fn print(cfg: &Config) -> Result<String, AppError> {
    let values =
        toml::to_string(cfg).map_err(|e| AppError::failed("printing the configuration", e))?;
    let values: DocumentMut = values
        .parse()
        .map_err(|e| AppError::failed("printing the configuration", e))?;
    let mut doc: DocumentMut = TEMPLATE
        .parse()
        .map_err(|e| AppError::failed("the configuration template", e))?;
    merge(doc.as_table_mut(), values.as_table());
    Ok(doc.to_string())
}

/// Puts `values` into `into`, table by table.
fn merge(into: &mut Table, values: &Table) {
    let gone: Vec<String> = into
        .iter()
        .filter(|(k, _)| !values.contains_key(k))
        .map(|(k, _)| k.to_string())
        .collect();
    for k in gone {
        into.remove(&k);
    }
    for (k, v) in values.iter() {
        match (into.get_mut(k), v) {
            (Some(Item::Table(t)), Item::Table(vt)) => merge(t, vt),
            (Some(Item::Value(old)), Item::Value(new)) => {
                if !same(old, new) {
                    let decor = old.decor().clone();
                    *old = new.clone();
                    *old.decor_mut() = decor;
                }
            }
            (_, v) => {
                into.insert(k, v.clone());
            }
        }
    }
}

/// Whether two TOML values are equal as values (`0.0` and `0.0e0`, `1` and `1`), whatever
/// their spelling.
fn same(a: &toml_edit::Value, b: &toml_edit::Value) -> bool {
    let parse = |v: &toml_edit::Value| {
        let text = format!("v = {}", v.to_string().trim());
        text.parse::<toml::Table>().ok()
    };
    match (parse(a), parse(b)) {
        (Some(a), Some(b)) => a == b,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    #[test]
    fn the_template_is_every_default_and_prints_unchanged() {
        let parsed = Config::parse("config.toml", TEMPLATE).unwrap();
        assert_eq!(parsed, Config::default());
        // Every key the defaults have is in the template with the same value, and no other.
        assert_eq!(print(&Config::default()).unwrap(), TEMPLATE);
        // Every key at its default: the demo has nothing to note.
        assert!(crate::config::unused_by_experiment(TEMPLATE).is_empty());
    }

    #[test]
    fn a_printed_configuration_reads_back_to_itself() {
        let text = "duration_s = 3.5\n[robot]\nmodel = \"ur5e\"\ninitial_joints_rad = [0.1, -1.2, 1.5, -1.9, -1.6, 0.2]\n\
                    [tracker.simulated.motion]\nkind = \"drift\"\nvelocity_m_s = [0.01, 0.0, 0.0]\n\
                    [experiment]\nseed = 7\n[loop]\nspeed_fraction = 0.4\n";
        let cfg = Config::parse("f.toml", text).unwrap();
        let printed = print(&cfg).unwrap();
        let back = Config::parse("printed.toml", &printed).unwrap();
        assert_eq!(back, cfg, "{printed}");
        // The comments are the template's.
        assert!(printed.contains("# ur3, ur5, ur10"), "{printed}");
        // A motion of another kind: the template's random-motion keys are gone, the drift's are
        // there.
        let key = |k: &str| printed.lines().any(|l| l.starts_with(k));
        assert!(!key("max_speed_m_s ="), "{printed}");
        assert!(key("velocity_m_s ="), "{printed}");
    }
}
