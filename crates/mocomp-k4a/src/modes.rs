//! The depth camera's modes and frame rates, as configuration names them and the SDK numbers
//! them.

use serde::{Deserialize, Serialize};

/// The depth camera's mode (`k4a_depth_mode_t`): field of view, binning, size.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DepthMode {
    /// Narrow field of view, 2×2 binned: 320×288.
    NfovBinned,
    /// Narrow field of view, unbinned: 640×576 (the head at 0.5–3.9 m).
    #[default]
    NfovUnbinned,
    /// Wide field of view, 2×2 binned: 512×512.
    WfovBinned,
    /// Wide field of view, unbinned: 1024×1024, at most 15 frames a second.
    WfovUnbinned,
    /// Passive IR only (no depth): 1024×1024.
    PassiveIr,
}

impl DepthMode {
    /// Every mode.
    pub const ALL: [Self; 5] = [
        Self::NfovBinned,
        Self::NfovUnbinned,
        Self::WfovBinned,
        Self::WfovUnbinned,
        Self::PassiveIr,
    ];

    /// The SDK's number.
    pub fn raw(self) -> i32 {
        match self {
            Self::NfovBinned => 1,
            Self::NfovUnbinned => 2,
            Self::WfovBinned => 3,
            Self::WfovUnbinned => 4,
            Self::PassiveIr => 5,
        }
    }

    /// The mode of the SDK's number (`None`: off or unknown).
    pub fn from_raw(raw: i32) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.raw() == raw)
    }

    /// Its image size, pixels.
    pub fn size(self) -> (u32, u32) {
        match self {
            Self::NfovBinned => (320, 288),
            Self::NfovUnbinned => (640, 576),
            Self::WfovBinned => (512, 512),
            Self::WfovUnbinned | Self::PassiveIr => (1024, 1024),
        }
    }

    /// Whether it measures depth (passive IR does not: the pipeline needs depth).
    pub fn has_depth(self) -> bool {
        self != Self::PassiveIr
    }

    /// Its highest frame rate.
    pub fn max_fps(self) -> u32 {
        match self {
            Self::WfovUnbinned => 15,
            _ => 30,
        }
    }
}

/// The SDK's number of a frame rate (`k4a_fps_t`): 5, 15 or 30 a second.
pub fn fps_raw(fps: u32) -> Option<i32> {
    match fps {
        5 => Some(0),
        15 => Some(1),
        30 => Some(2),
        _ => None,
    }
}

/// The frame rate of the SDK's number.
pub fn fps_from_raw(raw: i32) -> Option<u32> {
    [5, 15, 30].into_iter().find(|&f| fps_raw(f) == Some(raw))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn modes_and_rates_round_trip_through_the_sdks_numbers() {
        for m in DepthMode::ALL {
            assert_eq!(DepthMode::from_raw(m.raw()), Some(m));
        }
        assert_eq!(DepthMode::from_raw(0), None);
        for f in [5, 15, 30] {
            assert_eq!(fps_from_raw(fps_raw(f).unwrap_or(-1)), Some(f));
        }
        assert_eq!(fps_raw(60), None);
    }
}
