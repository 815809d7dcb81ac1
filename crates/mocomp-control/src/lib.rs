//! The compensation loop (the seed paper's section V, at the robot's rate), with what the paper
//! left out: prediction that hides latency, a supervisor whose rules each name their reaction, a safety
//! filter on every command, and a collision model of the
//! head, the coil and the arm. Beside it, behind the same [`Controller`] trait, the paper's own
//! pipeline ([`baseline`]), the reference the experiment scores it against.
//!
//! It talks to the robot and the tracker only through [`mocomp_robot::Robot`] and
//! [`mocomp_geom::PoseSource`], and takes the time as an argument, so the simulator steps it
//! deterministically and the live binary drives it from the monotonic clock.
//!
//! **Limits.** No I/O, no thread, no clock, no allocation or lock in the cycle: the robot and the
//! tracker only through traits, the time only as an argument.

pub mod baseline;
pub mod compensator;
pub mod config;
pub mod controller;
pub mod drive;
pub mod force;
pub mod geometry;
pub mod goal;
pub mod learned;
pub mod planner;
pub mod predict;
pub mod safety;
pub mod supervisor;
pub mod transit;
pub mod words;

pub use compensator::{Compensator, CycleRecord, Event, HeadOracle, Mode, Plan, Reason};
pub use config::{LoopConfig, LoopParams, ParamError};
pub use controller::Controller;
pub use drive::{Pace, Requests, drive};
pub use force::{ForceInputs, ForceMonitor, force_rules};
pub use geometry::{CoilModel, HeadModel};
pub use goal::{GoalError, check_goal};
pub use planner::{PlanError, ShellPath};
pub use predict::{MotionModel, PosePredictor, PredictorConfig};
pub use supervisor::{Decision, Reaction, RuleInputs, TransitRefusal, decide, reaction};
pub use transit::JointPath;
