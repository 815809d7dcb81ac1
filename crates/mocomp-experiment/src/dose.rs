//! The dose each tick: the field the true coil gives at the selected target, against the one
//! its goal gives ([`mocomp_efield`]). Planned once per goal before the run (the sphere under
//! the coil there, the target, the planned field), measured each tick allocating nothing.

use mocomp_efield::{Along, DoseMeter, DoseModel, EfieldError, PlannedDose};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_head::HeadShape;

/// A goal whose dose cannot be planned (its target gets no field, or lies outside the head
/// under the coil).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the dose at {what}")]
pub struct DosePlanError {
    /// Which goal.
    pub what: String,
    /// Why.
    #[source]
    pub source: EfieldError,
}

/// The run's dose plans and its meter.
#[derive(Debug, Clone)]
pub(crate) struct DoseWatch {
    meter: DoseMeter,
    /// The run's goal (the target without a session).
    goal: PlannedDose,
    /// The session's targets, in its order.
    targets: Vec<PlannedDose>,
}

impl DoseWatch {
    /// Plans the dose for `goal` and each of `targets` (head_from_coil) on `scalp`: the target
    /// under each, the dose along the field each gives there.
    pub(crate) fn new(
        model: &DoseModel,
        scalp: &dyn HeadShape,
        goal: &Isometry3<f64>,
        targets: &[Isometry3<f64>],
    ) -> Result<Self, DosePlanError> {
        let mut meter = DoseMeter::new(model.clone());
        let mut plan = |what: String, pose: &Isometry3<f64>| {
            PlannedDose::new(&mut meter, scalp, pose, None, Along::Planned)
                .map_err(|source| DosePlanError { what, source })
        };
        let goal = plan("the run's goal".into(), goal)?;
        let targets = targets
            .iter()
            .enumerate()
            .map(|(k, t)| plan(format!("the session's target {}", k + 1), t))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            meter,
            goal,
            targets,
        })
    }

    /// The dose of the coil at `head_from_coil` against target `target`'s plan (`None`: the
    /// goal's), % of the planned; NaN where the field has no answer (the coil inside the
    /// sphere, which the clearance reports).
    pub(crate) fn pct(&mut self, target: Option<usize>, head_from_coil: &Isometry3<f64>) -> f64 {
        let plan = target
            .and_then(|k| self.targets.get(k))
            .unwrap_or(&self.goal);
        self.meter
            .dose_pct(plan, head_from_coil)
            .unwrap_or(f64::NAN)
    }
}
