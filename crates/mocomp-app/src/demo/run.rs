//! `mocomp demo`'s run: the experiment ([`crate::experiment`]) with what watches it wired in
//! (the console's phases and observers, the MCAP recording `record_mcap` names), paced in real
//! time when a person watches, and the recording closed whatever became of the experiment.

use crate::AppError;
use crate::config::Config;
use crate::demo::record::DemoRecording;
use crate::experiment::{
    Controller, ExperimentConfig, ExperimentError, Outcome, Phase, Watch, run_experiment_watched,
};
use crate::frontend::{Both, Controls, Observer, Silent};
use crate::live::logger::RecordOutcome;
use mocomp_control::LoopConfig;
use mocomp_kin::Arm;

/// What shows the demo to a person (the console): the phases between the runs and an observer
/// of each controller's run.
pub trait DemoFront {
    /// Shows a phase that is not a loop's (placing the robots, calibrating).
    fn phase(&self, what: &str);
    /// The observer of one controller's run, the coil robot `arm` placed by the frames the
    /// experiment calibrated (`loop_cfg`).
    fn observer(
        &self,
        controller: &'static str,
        arm: Arm,
        loop_cfg: &LoopConfig,
    ) -> Box<dyn Observer>;
}

/// What a demo run gave.
#[derive(Debug)]
pub struct DemoRun {
    /// The experiment's outcome, or why it failed (the experiment's own error, which the exit
    /// status judges).
    pub outcome: Result<Outcome, ExperimentError>,
    /// The recording, closed: what it holds is kept, whatever became of the experiment.
    pub record: Option<RecordOutcome>,
}

/// Runs the experiment `exp` for each controller of `order`, shown on `front` (then paced in
/// real time, and `controls` hold, resume and stop it) and recorded where `config` says;
/// `progress` hears each phase's name and how far it is (0 to 1). An error only when the
/// recording cannot start.
pub fn run(
    config: &Config,
    exp: &ExperimentConfig,
    order: &[Controller],
    front: Option<&dyn DemoFront>,
    controls: &Controls,
    progress: &mut dyn FnMut(&str, f64),
) -> Result<DemoRun, AppError> {
    if let Some(f) = front {
        f.phase("placing the robots");
    }
    let recording = match &config.record_mcap {
        Some(path) => Some(DemoRecording::create(
            path,
            config.ros2.frames.clone(),
            config.ros2.node_name.clone(),
        )?),
        None => None,
    };
    let arm = Arm::new(exp.coil_robot);
    let mut observer = |c: Controller, loop_cfg: &LoopConfig| {
        let shown: Box<dyn Observer> = match front {
            Some(f) => f.observer(c.name(), arm, loop_cfg),
            None => Box::new(Silent),
        };
        match &recording {
            Some(r) => Box::new(Both(shown, r.observer(c, arm, loop_cfg))) as Box<dyn Observer>,
            None => shown,
        }
    };
    let watched = front.is_some() || recording.is_some();
    let mut watch = Watch {
        controls,
        real_time: front.is_some(),
        observer: &mut observer,
    };
    let outcome = run_experiment_watched(
        exp,
        order,
        &mut |phase, f| {
            let name = phase.to_string();
            if let Some(front) = front
                && !matches!(phase, Phase::Compensating(_))
            {
                front.phase(&name);
            }
            progress(&name, f);
        },
        watched.then_some(&mut watch),
    );
    Ok(DemoRun {
        outcome,
        record: recording.map(DemoRecording::finish),
    })
}
