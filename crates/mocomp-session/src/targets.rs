//! A session's named targets: each a coil pose in the head marker's frame (`head_from_coil`), with
//! a note and the time it was taught, kept in a TOML file so they survive a restart.
//!
//! ```toml
//! [[target]]
//! name = "hotspot"
//! head_from_coil = [0.0, 0.0, 0.113, 3.141592653589793, 0.0, 0.0]  # m; rotation vector, rad
//! note = "APB hotspot, 62 % RMT"
//! taught_at = "2026-12-02T09:14:03Z"
//! ```
//!
//! Parsing and printing only: the caller reads and writes the file.

use crate::grid::{GridError, GridParams, grid_around};
use mocomp_control::HeadModel;
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use serde::{Deserialize, Serialize};

/// One target.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Target {
    /// Its name (unique in the session).
    pub name: String,
    /// The coil in the head marker's frame: x, y, z (m) and a rotation vector (rad).
    pub head_from_coil: [f64; 6],
    /// Free text.
    #[serde(default)]
    pub note: String,
    /// When it was taught (RFC 3339, UTC), as the caller gave it.
    #[serde(default)]
    pub taught_at: String,
    /// Where it came from when it was placed on the image rather than taught (`eeg F3 (10-20)`,
    /// `image (-38.0, 42.0, 30.0) mm`, `mni (…) mm through FILE`).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub source: String,
    /// The coil in the image's frame (RAS; m, rotation vector), for a target placed on the
    /// image: kept so it can be placed again under a new registration.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image_from_coil: Option<[f64; 6]>,
}

impl Target {
    /// One line for a person: name, position (mm) and approach axis in the head marker's
    /// frame, when taught, note.
    pub fn line(&self) -> String {
        let p = self.pose();
        let mm = p.translation.vector * 1e3;
        let axis = p.rotation * Vector3::z();
        format!(
            "{:<20} [{:8.2} {:8.2} {:8.2}] mm  axis [{:6.3} {:6.3} {:6.3}]  {}  {}{}",
            self.name,
            mm.x,
            mm.y,
            mm.z,
            axis.x,
            axis.y,
            axis.z,
            self.taught_at,
            self.note,
            if self.source.is_empty() {
                String::new()
            } else {
                format!("  (from {})", self.source)
            }
        )
    }

    /// One JSON object: `name`, `position_mm`, `axis`, `head_from_coil`, `taught_at`, `note`.
    pub fn json(&self) -> String {
        #[derive(Serialize)]
        struct Line<'a> {
            name: &'a str,
            position_mm: [f64; 3],
            axis: [f64; 3],
            head_from_coil: [f64; 6],
            taught_at: &'a str,
            note: &'a str,
            #[serde(skip_serializing_if = "str::is_empty")]
            source: &'a str,
        }
        let p = self.pose();
        let mm = p.translation.vector * 1e3;
        let axis = p.rotation * Vector3::z();
        let line = Line {
            name: &self.name,
            position_mm: [mm.x, mm.y, mm.z],
            axis: [axis.x, axis.y, axis.z],
            head_from_coil: self.head_from_coil,
            taught_at: &self.taught_at,
            note: &self.note,
            source: &self.source,
        };
        serde_json::to_string(&line).unwrap_or_default()
    }

    /// A target from a pose.
    pub fn new(name: &str, head_from_coil: &Isometry3<f64>, note: &str, taught_at: &str) -> Self {
        Self {
            name: name.to_string(),
            head_from_coil: six(head_from_coil),
            note: note.to_string(),
            taught_at: taught_at.to_string(),
            source: String::new(),
            image_from_coil: None,
        }
    }

    /// This target, placed on the image at `image_from_coil` from `source`.
    pub fn placed_on_image(mut self, image_from_coil: &Isometry3<f64>, source: &str) -> Self {
        self.image_from_coil = Some(six(image_from_coil));
        self.source = source.to_string();
        self
    }

    /// Its pose.
    pub fn pose(&self) -> Isometry3<f64> {
        let p = &self.head_from_coil;
        Isometry3::new(
            Vector3::new(p[0], p[1], p[2]),
            Vector3::new(p[3], p[4], p[5]),
        )
    }
}

/// A pose as x, y, z and a rotation vector.
fn six(p: &Isometry3<f64>) -> [f64; 6] {
    let (t, r) = (p.translation.vector, p.rotation.scaled_axis());
    [t.x, t.y, t.z, r.x, r.y, r.z]
}

/// What is wrong with a targets file or a change to it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TargetsError {
    /// Not TOML of the expected shape (the parser's message names the line and key).
    #[error("{file}: {detail}")]
    Parse {
        /// The file.
        file: String,
        /// The parser's message.
        detail: String,
    },
    /// A value that is not a number, by target and field.
    #[error("{file}: target {name:?}: {field} is not finite")]
    NotFinite {
        /// The file.
        file: String,
        /// The target.
        name: String,
        /// The field.
        field: &'static str,
    },
    /// Two targets of one name, or an empty name.
    #[error("target name {0:?}: names must be unique and not empty")]
    Name(String),
    /// A grid that cannot be laid.
    #[error("the grid around {name:?}: {source}")]
    Grid {
        /// The target it is around.
        name: String,
        /// Why.
        #[source]
        source: GridError,
    },
    /// No target of this name.
    #[error("no target {name:?} (the session has: {known})")]
    Unknown {
        /// The name asked for.
        name: String,
        /// The names there are.
        known: String,
    },
}

/// The session's targets, in the order taught.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Targets {
    /// The targets.
    #[serde(default, rename = "target")]
    pub targets: Vec<Target>,
}

impl Targets {
    /// Parses a targets file's text (`file` names it in errors).
    pub fn parse(file: &str, text: &str) -> Result<Self, TargetsError> {
        let t: Targets = toml::from_str(text).map_err(|e| TargetsError::Parse {
            file: file.to_string(),
            detail: e.to_string(),
        })?;
        let mut seen = std::collections::HashSet::new();
        for target in &t.targets {
            if target.name.trim().is_empty() || !seen.insert(target.name.as_str()) {
                return Err(TargetsError::Name(target.name.clone()));
            }
            if !target.head_from_coil.iter().all(|x| x.is_finite()) {
                return Err(TargetsError::NotFinite {
                    file: file.to_string(),
                    name: target.name.clone(),
                    field: "head_from_coil",
                });
            }
        }
        Ok(t)
    }

    /// The file's text.
    pub fn to_toml(&self) -> String {
        // Plain data: serialising cannot fail.
        toml::to_string(self).unwrap_or_default()
    }

    /// Adds a target, or replaces the one of its name (re-teaching).
    pub fn teach(&mut self, target: Target) -> Result<(), TargetsError> {
        if target.name.trim().is_empty() {
            return Err(TargetsError::Name(target.name));
        }
        match self.targets.iter_mut().find(|t| t.name == target.name) {
            Some(t) => *t = target,
            None => self.targets.push(target),
        }
        Ok(())
    }

    /// The target called `name`.
    pub fn get(&self, name: &str) -> Result<&Target, TargetsError> {
        self.targets
            .iter()
            .find(|t| t.name == name)
            .ok_or_else(|| self.unknown(name))
    }

    /// Deletes the target called `name`.
    pub fn delete(&mut self, name: &str) -> Result<Target, TargetsError> {
        let i = self
            .targets
            .iter()
            .position(|t| t.name == name)
            .ok_or_else(|| self.unknown(name))?;
        Ok(self.targets.remove(i))
    }

    /// Adds a grid around the target `name` on `head` ([`crate::grid`]): targets named
    /// `{name}-r{row}c{col}` (re-teaching any of those names), noted as the grid's. Returns
    /// their names, row by row.
    pub fn add_grid(
        &mut self,
        head: &HeadModel,
        name: &str,
        p: &GridParams,
        taught_at: &str,
    ) -> Result<Vec<String>, TargetsError> {
        let centre = self.get(name)?.pose();
        let points = grid_around(head, &centre, p).map_err(|source| TargetsError::Grid {
            name: name.to_string(),
            source,
        })?;
        let note = format!(
            "grid around {name}: {} × {}, {} mm apart",
            p.rows,
            p.cols,
            p.spacing_m * 1e3
        );
        let mut names = Vec::with_capacity(points.len());
        for g in points {
            let n = format!("{name}-r{}c{}", g.row, g.col);
            self.teach(Target::new(&n, &g.head_from_coil, &note, taught_at))?;
            names.push(n);
        }
        Ok(names)
    }

    fn unknown(&self, name: &str) -> TargetsError {
        TargetsError::Unknown {
            name: name.to_string(),
            known: self
                .targets
                .iter()
                .map(|t| t.name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    fn pose(z: f64) -> Isometry3<f64> {
        Isometry3::new(Vector3::new(0.01, -0.02, z), Vector3::new(3.0, 0.1, -0.2))
    }

    #[test]
    fn targets_survive_a_round_trip_through_their_file() {
        let mut t = Targets::default();
        t.teach(Target::new(
            "hotspot",
            &pose(0.113),
            "APB",
            "2026-12-02T09:14:03Z",
        ))
        .unwrap();
        t.teach(Target::new(
            "hotspot-r0c0",
            &pose(0.12),
            "",
            "2026-12-02T09:20:00Z",
        ))
        .unwrap();
        let back = Targets::parse("session.toml", &t.to_toml()).unwrap();
        assert_eq!(back, t);
        let p = back.get("hotspot").unwrap().pose();
        assert!((p.translation.vector - pose(0.113).translation.vector).norm() < 1e-15);
        assert!(p.rotation.angle_to(&pose(0.113).rotation) < 1e-12);
        // Re-teaching replaces; deleting removes; an unknown name lists the known ones.
        t.teach(Target::new("hotspot", &pose(0.2), "moved", "later"))
            .unwrap();
        assert_eq!(t.targets.len(), 2);
        assert_eq!(t.get("hotspot").unwrap().note, "moved");
        t.delete("hotspot-r0c0").unwrap();
        let e = t.get("hotspot-r0c0").unwrap_err();
        assert_eq!(
            e.to_string(),
            "no target \"hotspot-r0c0\" (the session has: hotspot)"
        );
    }

    #[test]
    fn a_grid_is_added_as_named_targets_around_one() {
        let head = HeadModel::adult();
        let mut t = Targets::default();
        let top = Isometry3::from_parts(
            mocomp_geom::nalgebra::Translation3::new(0.0, 0.0, 0.113),
            mocomp_geom::nalgebra::UnitQuaternion::from_axis_angle(
                &Vector3::x_axis(),
                std::f64::consts::PI,
            ),
        );
        t.teach(Target::new("hotspot", &top, "", "then")).unwrap();
        let names = t
            .add_grid(&head, "hotspot", &GridParams::default(), "now")
            .unwrap();
        assert_eq!(names.len(), 9);
        assert_eq!(names[0], "hotspot-r0c0");
        assert_eq!(t.targets.len(), 10);
        assert!(t.get("hotspot-r1c1").unwrap().note.contains("3 × 3, 10 mm"));
        // Again: the same names, re-taught, not doubled.
        t.add_grid(&head, "hotspot", &GridParams::default(), "later")
            .unwrap();
        assert_eq!(t.targets.len(), 10);
        assert!(matches!(
            t.add_grid(&head, "nothing", &GridParams::default(), ""),
            Err(TargetsError::Unknown { .. })
        ));
        let e = t
            .add_grid(
                &head,
                "hotspot",
                &GridParams {
                    rows: 0,
                    ..GridParams::default()
                },
                "",
            )
            .unwrap_err();
        assert!(e.to_string().contains("rows = 0"), "{e}");
    }

    #[test]
    fn a_bad_file_is_refused_naming_what_is_wrong() {
        let e = Targets::parse(
            "s.toml",
            "[[target]]\nname = \"a\"\nhead_from_coil = [1, 2]\n",
        )
        .unwrap_err();
        assert!(
            e.to_string().starts_with("s.toml: ") && e.to_string().contains("head_from_coil"),
            "{e}"
        );
        let e = Targets::parse(
            "s.toml",
            "[[target]]\nname = \"a\"\nhead_from_coil = [0, 0, 0, 0, 0, 0]\ncolour = 1\n",
        )
        .unwrap_err();
        assert!(e.to_string().contains("colour"), "{e}");
        let two = "[[target]]\nname = \"a\"\nhead_from_coil = [0, 0, 0, 0, 0, 0]\n\
                   [[target]]\nname = \"a\"\nhead_from_coil = [0, 0, 0, 0, 0, 0]\n";
        assert_eq!(
            Targets::parse("s.toml", two).unwrap_err(),
            TargetsError::Name("a".into())
        );
        let nan = "[[target]]\nname = \"a\"\nhead_from_coil = [0, 0, nan, 0, 0, 0]\n";
        assert!(matches!(
            Targets::parse("s.toml", nan).unwrap_err(),
            TargetsError::NotFinite {
                field: "head_from_coil",
                ..
            }
        ));
        assert!(
            Targets::default()
                .teach(Target::new(" ", &pose(0.1), "", ""))
                .is_err()
        );
    }
}
