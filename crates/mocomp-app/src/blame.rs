//! Whose fault an error is: the input's (an argument, a file, a configuration value: the user
//! can fix it) or the run's (a robot that faults or cannot be reached, a timeout, a full disk).
//! The CLI turns it into exit code 2 or 1; the console into HTTP 400 or 500.
//!
//! Each error in a cause chain is asked in turn; the first that knows says. An error nobody
//! classifies is the run's: calling a broken robot or a full disk "bad input" would send the
//! user to check arguments that are fine.

use mocomp_kin::KinError;

/// Whose fault an error is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Blame {
    /// Bad input.
    Input,
    /// A failure at run time.
    Run,
}

/// Whose fault `e` is, asking it and then each of its sources.
pub fn blame(e: &(dyn std::error::Error + 'static)) -> Blame {
    std::iter::successors(Some(e), |e| e.source())
        .find_map(classify)
        .unwrap_or(Blame::Run)
}

/// Whose fault one error is (its sources aside); `None`: not known here.
pub fn classify(e: &(dyn std::error::Error + 'static)) -> Option<Blame> {
    use crate::experiment::ExperimentError;
    if let Some(e) = e.downcast_ref::<crate::AppError>() {
        // A failure's cause decides (a file not found is input; a lost robot is not).
        return match e {
            crate::AppError::Config(_) => Some(Blame::Input),
            crate::AppError::Refused(_) => Some(Blame::Run),
            crate::AppError::Failed { .. } => None,
        };
    }
    if e.is::<mocomp_vision::VisionError>()
        || e.is::<mocomp_control::ParamError>()
        || e.is::<mocomp_geom::GeomError>()
        || e.is::<mocomp_igtl::name::NameError>()
        || e.is::<mocomp_control::GoalError>()
        || e.is::<mocomp_sim::MotionError>()
        || e.is::<mocomp_sim::trace::TraceError>()
        || e.is::<mocomp_head::HeadError>()
        || e.is::<mocomp_mri::MriError>()
        || e.is::<toml::de::Error>()
        || e.is::<serde_json::Error>()
    {
        return Some(Blame::Input);
    }
    // A camera: the SDK missing, a recording or a mode that will not do are the user's to fix;
    // a camera that is not there or stops is the run's.
    if let Some(e) = e.downcast_ref::<mocomp_k4a::K4aError>() {
        use mocomp_k4a::K4aError as K;
        return Some(match e {
            K::SdkMissing { .. }
            | K::Recording { .. }
            | K::Damaged { .. }
            | K::BadImage { .. }
            | K::Calibration(_)
            | K::Mode(_)
            | K::BadArgument(_) => Blame::Input,
            K::Call { .. } | K::NoDevice(_) | K::DeviceLost => Blame::Run,
        });
    }
    if e.is::<mocomp_ursim::SimError>() {
        return Some(Blame::Run);
    }
    // The robot as the loop sees it: a command out of range is input, a refusal by a fault an
    // outcome; a link's failure is its implementation's error, asked next (its source).
    if let Some(e) = e.downcast_ref::<mocomp_robot::RobotError>() {
        return match e {
            mocomp_robot::RobotError::OutOfRange { .. } => Some(Blame::Input),
            mocomp_robot::RobotError::Fault(_) => Some(Blame::Run),
            mocomp_robot::RobotError::Link(_) => None,
        };
    }
    // A robot that is unreachable, refuses or faults is an outcome; a bad argument is not.
    if let Some(e) = e.downcast_ref::<mocomp_ur::UrError>() {
        return Some(match e {
            mocomp_ur::UrError::Robot(mocomp_robot::RobotError::OutOfRange { .. }) => Blame::Input,
            _ => Blame::Run,
        });
    }
    // The experiment: its configuration is input; simulators, timeouts and calibration runs
    // are outcomes.
    if let Some(e) = e.downcast_ref::<ExperimentError>() {
        return Some(match e {
            // A goal whose target gets no field: the configuration's coil, target or head.
            ExperimentError::Config(_)
            | ExperimentError::Goal(_)
            | ExperimentError::Scene(_)
            | ExperimentError::Dose(_) => Blame::Input,
            ExperimentError::Io { .. }
            | ExperimentError::Timeout { .. }
            | ExperimentError::Calibration { .. } => Blame::Run,
        });
    }
    // Calibration: bad or degenerate input is exit 2; a plan that cannot be met is exit 1.
    if let Some(e) = e.downcast_ref::<mocomp_calib::CalibError>() {
        return Some(match e {
            mocomp_calib::CalibError::PlanShort { .. } => Blame::Run,
            _ => Blame::Input,
        });
    }
    // A pose that cannot be reached is an outcome; a malformed one is input.
    if let Some(e) = e.downcast_ref::<KinError>() {
        return Some(match e {
            KinError::Unreachable(_)
            | KinError::OutsideJointLimits { .. }
            | KinError::BranchUnavailable { .. }
            | KinError::NotConverged { .. } => Blame::Run,
            _ => Blame::Input,
        });
    }
    // A file given that is not there or not readable as asked is input; any other I/O failure
    // (a full disk, a lost connection) happened at run time.
    if let Some(e) = e.downcast_ref::<std::io::Error>() {
        use std::io::ErrorKind;
        return Some(match e.kind() {
            ErrorKind::NotFound | ErrorKind::InvalidInput | ErrorKind::InvalidData => Blame::Input,
            _ => Blame::Run,
        });
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::ExperimentError;

    #[test]
    fn a_robot_command_out_of_range_is_input_a_fault_the_runs_and_a_link_its_cause() {
        use mocomp_robot::{RobotError, RobotFault};
        let range = RobotError::OutOfRange {
            field: "servo gain",
            value: 5.0,
            min: 100.0,
            max: 2000.0,
        };
        assert_eq!(blame(&range), Blame::Input);
        assert_eq!(
            blame(&RobotError::Fault(RobotFault::ProtectiveStop)),
            Blame::Run
        );
        // A link's failure is its cause's: a lost socket is the run's, a file not found input.
        let lost = std::io::Error::from(std::io::ErrorKind::ConnectionReset);
        assert_eq!(blame(&RobotError::Link(Box::new(lost))), Blame::Run);
        let missing = std::io::Error::from(std::io::ErrorKind::NotFound);
        assert_eq!(blame(&RobotError::Link(Box::new(missing))), Blame::Input);
        // Wrapped by the application, the robot's word still decides.
        assert_eq!(
            blame(&crate::AppError::failed("servoj", range)),
            Blame::Input
        );
    }

    #[test]
    fn bad_input_is_the_inputs_and_everything_failing_at_run_time_the_runs() {
        let cfg = crate::AppError::Config("f.toml: servo.gain = 50: must be in [100, 2000]".into());
        assert_eq!(blame(&cfg), Blame::Input);
        // Wrapped, the cause decides.
        let missing = std::io::Error::from(std::io::ErrorKind::NotFound);
        let wrapped = crate::AppError::failed("--config f.toml", missing);
        assert_eq!(blame(&wrapped), Blame::Input);
        let full = std::io::Error::from(std::io::ErrorKind::StorageFull);
        assert_eq!(blame(&crate::AppError::failed("log_csv", full)), Blame::Run);
        // A simulator that timed out, a refusal, an error nobody classified: the run's.
        assert_eq!(
            blame(&ExperimentError::Timeout {
                what: "the robots' states",
                seen: None
            }),
            Blame::Run
        );
        assert_eq!(
            blame(&crate::AppError::Refused("no state".into())),
            Blame::Run
        );
        let odd = std::fmt::Error;
        assert_eq!(blame(&odd), Blame::Run);
        assert_eq!(
            blame(&ExperimentError::Config("seconds = -1".into())),
            Blame::Input
        );
        let unreachable = KinError::Unreachable(mocomp_kin::Unreachable::TooFar {
            distance_m: 1.0,
            reach_m: 0.5,
        });
        assert_eq!(blame(&unreachable), Blame::Run);
    }
}
