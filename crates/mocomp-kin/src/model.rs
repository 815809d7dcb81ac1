//! The Universal Robots model table: published DH parameters, joint limits and maximum joint
//! speeds, in one place.
//!
//! Sources: Universal Robots' published DH table (the same values as
//! `Universal_Robots_ROS2_Description/config/<model>/default_kinematics.yaml`), and the models'
//! `joint_limits.yaml` in that description (citing the UR manuals) for speeds.

use crate::error::KinError;
use std::f64::consts::TAU;
use std::fmt;
use std::str::FromStr;

/// A Universal Robots arm model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Model {
    /// UR3 (CB3).
    Ur3,
    /// UR5 (CB3).
    Ur5,
    /// UR10 (CB3).
    Ur10,
    /// UR3e.
    Ur3e,
    /// UR5e.
    Ur5e,
    /// UR10e.
    Ur10e,
    /// UR16e.
    Ur16e,
    /// UR20.
    Ur20,
    /// UR30.
    Ur30,
}

/// The controller generation, which fixes the control period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Series {
    /// CB3 controllers: 125 Hz (8 ms).
    Cb3,
    /// e-Series controllers (and UR20/UR30): 500 Hz (2 ms).
    ESeries,
}

impl Series {
    /// The controller's control period, seconds.
    pub fn period_s(self) -> f64 {
        match self {
            Series::Cb3 => 0.008,
            Series::ESeries => 0.002,
        }
    }
}

/// The six non-zero DH parameters of the UR family's nominal geometry (standard DH, metres):
/// `α = [π/2, 0, 0, π/2, −π/2, 0]`, `a1 = a4 = a5 = a6 = 0`, `d2 = d3 = 0`, all joint offsets 0.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct UrGeometry {
    /// Base height (shoulder axis above the base frame).
    pub d1: f64,
    /// Upper arm length (negative in UR's convention).
    pub a2: f64,
    /// Forearm length (negative in UR's convention).
    pub a3: f64,
    /// Net shoulder/elbow offset along the parallel axes 2–4.
    pub d4: f64,
    /// Wrist 1 to wrist 2 offset.
    pub d5: f64,
    /// Wrist 2 to flange offset.
    pub d6: f64,
}

/// Everything the table knows about one model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelSpec {
    /// The model.
    pub model: Model,
    /// Lower-case name, as used on the command line and in configs (`"ur5e"`).
    pub name: &'static str,
    /// Nominal DH geometry.
    pub geometry: UrGeometry,
    /// Lower joint position limits, radians (`-inf` for a joint without limit).
    pub lower_limits: [f64; 6],
    /// Upper joint position limits, radians (`inf` for a joint without limit).
    pub upper_limits: [f64; 6],
    /// Maximum joint speeds, rad/s.
    pub max_speed: [f64; 6],
    /// Controller generation.
    pub series: Series,
}

const fn deg(d: f64) -> f64 {
    d * (std::f64::consts::PI / 180.0)
}

const FULL: [f64; 6] = [TAU; 6];
const NEG_FULL: [f64; 6] = [-TAU; 6];
/// UR3 / UR3e: wrist 3 turns without limit.
const UR3_UPPER: [f64; 6] = [TAU, TAU, TAU, TAU, TAU, f64::INFINITY];
const UR3_LOWER: [f64; 6] = [-TAU, -TAU, -TAU, -TAU, -TAU, f64::NEG_INFINITY];

const SPEED_UR3: [f64; 6] = [
    deg(180.0),
    deg(180.0),
    deg(180.0),
    deg(360.0),
    deg(360.0),
    deg(360.0),
];
const SPEED_UR5: [f64; 6] = [deg(180.0); 6];
const SPEED_UR10: [f64; 6] = [
    deg(120.0),
    deg(120.0),
    deg(180.0),
    deg(180.0),
    deg(180.0),
    deg(180.0),
];
const SPEED_UR20: [f64; 6] = [
    deg(120.0),
    deg(120.0),
    deg(150.0),
    deg(210.0),
    deg(210.0),
    deg(210.0),
];

const fn geo(d1: f64, a2: f64, a3: f64, d4: f64, d5: f64, d6: f64) -> UrGeometry {
    UrGeometry {
        d1,
        a2,
        a3,
        d4,
        d5,
        d6,
    }
}

/// The table: one row per model.
pub const MODELS: [ModelSpec; 9] = [
    ModelSpec {
        model: Model::Ur3,
        name: "ur3",
        geometry: geo(0.1519, -0.24365, -0.21325, 0.11235, 0.08535, 0.0819),
        lower_limits: UR3_LOWER,
        upper_limits: UR3_UPPER,
        max_speed: SPEED_UR3,
        series: Series::Cb3,
    },
    ModelSpec {
        model: Model::Ur5,
        name: "ur5",
        geometry: geo(0.089159, -0.425, -0.39225, 0.10915, 0.09465, 0.0823),
        lower_limits: NEG_FULL,
        upper_limits: FULL,
        max_speed: SPEED_UR5,
        series: Series::Cb3,
    },
    ModelSpec {
        model: Model::Ur10,
        name: "ur10",
        geometry: geo(0.1273, -0.612, -0.5723, 0.163941, 0.1157, 0.0922),
        lower_limits: NEG_FULL,
        upper_limits: FULL,
        max_speed: SPEED_UR10,
        series: Series::Cb3,
    },
    ModelSpec {
        model: Model::Ur3e,
        name: "ur3e",
        geometry: geo(0.15185, -0.24355, -0.2132, 0.13105, 0.08535, 0.0921),
        lower_limits: UR3_LOWER,
        upper_limits: UR3_UPPER,
        max_speed: SPEED_UR3,
        series: Series::ESeries,
    },
    ModelSpec {
        model: Model::Ur5e,
        name: "ur5e",
        geometry: geo(0.1625, -0.425, -0.3922, 0.1333, 0.0997, 0.0996),
        lower_limits: NEG_FULL,
        upper_limits: FULL,
        max_speed: SPEED_UR5,
        series: Series::ESeries,
    },
    ModelSpec {
        model: Model::Ur10e,
        name: "ur10e",
        geometry: geo(0.1807, -0.6127, -0.57155, 0.17415, 0.11985, 0.11655),
        lower_limits: NEG_FULL,
        upper_limits: FULL,
        max_speed: SPEED_UR10,
        series: Series::ESeries,
    },
    ModelSpec {
        model: Model::Ur16e,
        name: "ur16e",
        geometry: geo(0.1807, -0.4784, -0.36, 0.17415, 0.11985, 0.11655),
        lower_limits: NEG_FULL,
        upper_limits: FULL,
        max_speed: SPEED_UR10,
        series: Series::ESeries,
    },
    ModelSpec {
        model: Model::Ur20,
        name: "ur20",
        geometry: geo(0.2363, -0.862, -0.7287, 0.201, 0.1593, 0.1543),
        lower_limits: NEG_FULL,
        upper_limits: FULL,
        max_speed: SPEED_UR20,
        series: Series::ESeries,
    },
    ModelSpec {
        model: Model::Ur30,
        name: "ur30",
        geometry: geo(0.2363, -0.637, -0.5037, 0.201, 0.1593, 0.1543),
        lower_limits: NEG_FULL,
        upper_limits: FULL,
        max_speed: SPEED_UR20,
        series: Series::ESeries,
    },
];

impl Model {
    /// Every model, in table order.
    pub const ALL: [Model; 9] = [
        Model::Ur3,
        Model::Ur5,
        Model::Ur10,
        Model::Ur3e,
        Model::Ur5e,
        Model::Ur10e,
        Model::Ur16e,
        Model::Ur20,
        Model::Ur30,
    ];

    /// The model's row of the table.
    pub fn spec(self) -> &'static ModelSpec {
        // The table is in enum order; the test `table_is_in_enum_order` keeps it so.
        &MODELS[self as usize]
    }

    /// Lower-case name (`"ur5e"`).
    pub fn name(self) -> &'static str {
        self.spec().name
    }
}

impl fmt::Display for Model {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Model {
    type Err = KinError;

    /// Parses `ur5e`, `UR5e` or `UR5E`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.trim().to_ascii_lowercase();
        MODELS
            .iter()
            .find(|m| m.name == lower)
            .map(|m| m.model)
            .ok_or_else(|| KinError::UnknownModel {
                name: s.to_string(),
                known: model_names(),
            })
    }
}

/// From its name in a configuration file (`"ur5e"`, case-insensitive); an unknown name is refused
/// with every known one.
impl<'de> serde::Deserialize<'de> for Model {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = <std::borrow::Cow<'de, str>>::deserialize(d)?;
        name.parse().map_err(|_| {
            serde::de::Error::custom(format!(
                "unknown robot model {name:?} (known: {})",
                model_names()
            ))
        })
    }
}

/// As its name (`"ur5e"`), the form [`Model`]'s `Deserialize` reads.
impl serde::Serialize for Model {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

/// The names of every model, comma-separated, for error messages and help texts.
pub fn model_names() -> String {
    MODELS.iter().map(|m| m.name).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_is_in_enum_order() {
        for (i, m) in Model::ALL.iter().enumerate() {
            assert_eq!(MODELS[i].model, *m);
            assert_eq!(m.spec().model, *m);
        }
    }

    #[test]
    fn names_parse_back() {
        for m in Model::ALL {
            assert_eq!(m.name().parse::<Model>().unwrap(), m);
            assert_eq!(m.name().to_uppercase().parse::<Model>().unwrap(), m);
        }
        let err = "ur4".parse::<Model>().unwrap_err();
        assert!(err.to_string().contains("ur4"), "{err}");
    }

    #[test]
    fn speeds_and_series() {
        assert!((Model::Ur3.spec().max_speed[5] - TAU).abs() < 1e-15);
        assert!((Model::Ur10e.spec().max_speed[0] - TAU / 3.0).abs() < 1e-15);
        assert_eq!(Model::Ur5.spec().series.period_s(), 0.008);
        assert_eq!(Model::Ur30.spec().series.period_s(), 0.002);
        assert!(Model::Ur3e.spec().upper_limits[5].is_infinite());
        assert_eq!(Model::Ur5e.spec().upper_limits[5], TAU);
    }
}
