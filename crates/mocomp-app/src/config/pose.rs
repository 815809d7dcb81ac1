//! Poses as a configuration writes them: UR pose vectors, checked when read.

use super::*;

/// A pose as a UR pose vector `[x, y, z, rx, ry, rz]` (metres, rotation vector in radians),
/// checked when read. It keeps the six numbers as written, so a printed file reads them back
/// exactly.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "[f64; 6]", into = "[f64; 6]")]
pub struct Pose {
    raw: [f64; 6],
    iso: Isometry3<f64>,
}

impl Pose {
    /// The rigid transform.
    pub fn iso(&self) -> Isometry3<f64> {
        self.iso
    }

    /// The six numbers.
    pub fn raw(&self) -> [f64; 6] {
        self.raw
    }
}

impl TryFrom<[f64; 6]> for Pose {
    type Error = mocomp_geom::GeomError;
    fn try_from(raw: [f64; 6]) -> Result<Self, Self::Error> {
        Ok(Self {
            raw,
            iso: iso_from_ur_pose(&raw)?,
        })
    }
}

impl From<Pose> for [f64; 6] {
    fn from(p: Pose) -> Self {
        p.raw
    }
}

/// A pose from constant numbers (the defaults below): finite numbers always convert.
pub(super) fn pose_const(raw: [f64; 6]) -> Pose {
    Pose {
        raw,
        iso: iso_from_ur_pose(&raw).unwrap_or_else(|_| Isometry3::identity()),
    }
}
