//! The eight IK solution families of a UR arm: shoulder left or right, elbow up or down, wrist
//! flipped or not. Named here, apart from the solver, so errors and callers can speak of a
//! branch without depending on the solver.

use std::fmt;

/// Which side of the base–wrist line the arm passes, seen from above.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Shoulder {
    /// Looking down from above, from the base axis toward the wrist point, the arm (links 2 and 3)
    /// passes to the left of that line: the wrist point's reach `ρ` along frame 1's x axis is ≥ 0.
    Left,
    /// The arm passes to the right (`ρ < 0`).
    Right,
}

/// Where the elbow is relative to the line from shoulder to wrist 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Elbow {
    /// The elbow lies above the shoulder–wrist line (seen with the arm reaching forward).
    Up,
    /// The elbow lies below it.
    Down,
}

/// Whether the wrist is flipped (`q5` and `−q5`, with `q6 + π` and `q234 + π`, reach the same pose).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Wrist {
    /// `sin q5 ≥ 0`.
    NoFlip,
    /// `sin q5 < 0`.
    Flip,
}

/// The branch of a joint configuration: one of the (up to) eight IK solution families.
///
/// A branch can change only through a singularity (`ρ = 0`, `sin q3 = 0` or `sin q5 = 0`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Branch {
    /// Shoulder left/right.
    pub shoulder: Shoulder,
    /// Elbow up/down.
    pub elbow: Elbow,
    /// Wrist flip/noflip.
    pub wrist: Wrist,
}

impl Shoulder {
    /// `"left"` / `"right"`.
    pub fn as_str(self) -> &'static str {
        match self {
            Shoulder::Left => "left",
            Shoulder::Right => "right",
        }
    }
}

impl Elbow {
    /// `"up"` / `"down"`.
    pub fn as_str(self) -> &'static str {
        match self {
            Elbow::Up => "up",
            Elbow::Down => "down",
        }
    }
}

impl Wrist {
    /// `"noflip"` / `"flip"`.
    pub fn as_str(self) -> &'static str {
        match self {
            Wrist::NoFlip => "noflip",
            Wrist::Flip => "flip",
        }
    }
}

impl fmt::Display for Branch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "shoulder {}, elbow {}, wrist {}",
            self.shoulder.as_str(),
            self.elbow.as_str(),
            self.wrist.as_str()
        )
    }
}
