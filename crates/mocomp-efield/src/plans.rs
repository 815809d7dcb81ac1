//! A run's dose plans: one per coil goal it may hold (the configuration's goal, each session
//! target), made once before the run, and the meter that measures a coil pose against them.
//!
//! The loop's cycle asks for the dose against the goal it holds *now*, found by its pose: a
//! target selected, a goal taught or sent by a front end, all are recognised by what the loop
//! is given, never by what was last asked for. A goal no plan was made for has no dose (NaN),
//! which a gate that requires a dose treats as off target.

use crate::dose::{Along, DoseMeter, DoseModel, PlannedDose};
use crate::error::EfieldError;
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

/// A dose measured: the field along the plan's direction (or its magnitude) and that as a
/// percentage of the planned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dose {
    /// V/m.
    pub v_per_m: f64,
    /// % of the planned dose.
    pub pct: f64,
}

impl Dose {
    /// No dose (NaN in both).
    pub const NONE: Self = Self {
        v_per_m: f64::NAN,
        pct: f64::NAN,
    };
}

/// Two goals closer than this are the same goal (m; and this many radians): a goal handed to
/// the loop is the planned pose itself, so only rounding separates them.
const SAME_GOAL: f64 = 1e-6;

/// The plans of a run's goals and the meter.
#[derive(Debug, Clone)]
pub struct DosePlans {
    meter: DoseMeter,
    /// The run's own goal (the target without a session), when it has one.
    goal: Option<PlannedDose>,
    /// The session's targets, in its order.
    targets: Vec<PlannedDose>,
}

impl DosePlans {
    /// Plans the dose for `goal` and each of `targets` (`head_from_coil`) on `scalp`: the target
    /// [`DoseModel::depth_m`] under the scalp on each coil's axis, the dose along the field each
    /// gives there. Errors name the goal (`the run's goal`, `the session's target 3`).
    pub fn new(
        model: &DoseModel,
        scalp: &dyn HeadShape,
        goal: Option<&Isometry3<f64>>,
        targets: &[Isometry3<f64>],
    ) -> Result<Self, DosePlanError> {
        let mut meter = DoseMeter::new(model.clone());
        let mut plan = |what: String, pose: &Isometry3<f64>| {
            PlannedDose::new(&mut meter, scalp, pose, None, Along::Planned)
                .map_err(|source| DosePlanError { what, source })
        };
        let goal = goal.map(|g| plan("the run's goal".into(), g)).transpose()?;
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

    /// The plan of target `target` (`None`: the run's goal).
    pub fn plan(&self, target: Option<usize>) -> Option<&PlannedDose> {
        match target {
            Some(k) => self.targets.get(k),
            None => self.goal.as_ref(),
        }
    }

    /// The dose of the coil at `head_from_coil` against target `target`'s plan (`None`: the
    /// run's goal); [`Dose::NONE`] where there is no such plan or the field has no answer (the
    /// coil inside the sphere, which the clearance reports).
    pub fn dose(&mut self, target: Option<usize>, head_from_coil: &Isometry3<f64>) -> Dose {
        let plan = match target {
            Some(k) => self.targets.get(k),
            None => self.goal.as_ref(),
        };
        Self::measure(&mut self.meter, plan, head_from_coil)
    }

    /// The dose of the coil at `head_from_coil` against the plan made for the goal
    /// `head_from_coil_goal` (the one the loop holds), [`Dose::NONE`] when no plan was made
    /// for it.
    pub fn dose_at_goal(
        &mut self,
        head_from_coil_goal: &Isometry3<f64>,
        head_from_coil: &Isometry3<f64>,
    ) -> Dose {
        let same = |p: &&PlannedDose| {
            let d = p.head_from_coil.inv_mul(head_from_coil_goal);
            d.translation.vector.norm() < SAME_GOAL && d.rotation.angle() < SAME_GOAL
        };
        let plan = self.goal.iter().chain(self.targets.iter()).find(same);
        Self::measure(&mut self.meter, plan, head_from_coil)
    }

    fn measure(
        meter: &mut DoseMeter,
        plan: Option<&PlannedDose>,
        head_from_coil: &Isometry3<f64>,
    ) -> Dose {
        let Some(plan) = plan else {
            return Dose::NONE;
        };
        match meter.dose(plan, head_from_coil) {
            Ok(v) => Dose {
                v_per_m: v,
                pct: 100.0 * v / plan.dose_v_per_m,
            },
            Err(_) => Dose::NONE,
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use crate::test_coil::eight;
    use mocomp_geom::nalgebra::{Translation3, UnitQuaternion, Vector3};
    use mocomp_head::Ellipsoid;
    use std::sync::Arc;

    fn on_top(x: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(x, 0.0, 0.093),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        )
    }

    fn plans() -> DosePlans {
        let head = Ellipsoid::new(Isometry3::identity(), Vector3::new(0.1, 0.08, 0.09)).unwrap();
        let model = DoseModel {
            coil: Arc::new(eight()),
            didt_a_per_s: 1e8,
            depth_m: 0.015,
        };
        DosePlans::new(
            &model,
            &head,
            Some(&on_top(0.0)),
            &[on_top(0.02), on_top(-0.02)],
        )
        .unwrap()
    }

    #[test]
    fn each_goal_is_measured_against_its_own_plan_and_an_unplanned_one_has_none() {
        let mut p = plans();
        for (k, goal) in [
            (None, on_top(0.0)),
            (Some(0), on_top(0.02)),
            (Some(1), on_top(-0.02)),
        ] {
            // At its goal, a coil gives its plan's dose, however found.
            let by_index = p.dose(k, &goal);
            let by_pose = p.dose_at_goal(&goal, &goal);
            assert!((by_index.pct - 100.0).abs() < 1e-9, "{k:?} {by_index:?}");
            assert_eq!(by_index, by_pose);
            assert!(
                (by_index.v_per_m - p.plan(k).unwrap().dose_v_per_m).abs() < 1e-9,
                "{by_index:?}"
            );
        }
        // The coil lifted 2 mm off target 1 is measured against target 1's plan, not the
        // goal's: less than 100 %, and not the goal's (which it is 20 mm away from) figure.
        let lifted = Isometry3::translation(0.0, 0.0, 0.002) * on_top(0.02);
        let against_own = p.dose_at_goal(&on_top(0.02), &lifted);
        assert!(
            against_own.pct < 97.0 && against_own.pct > 80.0,
            "{against_own:?}"
        );
        assert_eq!(against_own, p.dose(Some(0), &lifted));
        // A goal a millimetre off every plan, a target index past the end: no dose.
        assert!(p.dose_at_goal(&on_top(0.001), &lifted).pct.is_nan());
        assert!(p.dose(Some(2), &lifted).pct.is_nan());
        // A coil inside the sphere: the field has no answer, nor does the dose.
        let inside = Isometry3::translation(0.0, 0.0, -0.05) * on_top(0.0);
        assert!(p.dose(None, &inside).v_per_m.is_nan());
    }

    #[test]
    fn a_goal_that_gives_no_field_at_its_target_is_named() {
        let head = Ellipsoid::new(Isometry3::identity(), Vector3::new(0.1, 0.08, 0.09)).unwrap();
        let model = DoseModel {
            coil: Arc::new(eight()),
            didt_a_per_s: 1e8,
            depth_m: 0.015,
        };
        // A goal with the coil half inside the head: the sphere model has no field for it.
        let sunk = Isometry3::translation(0.0, 0.0, -0.05) * on_top(0.0);
        let e = DosePlans::new(&model, &head, None, &[on_top(0.0), sunk]).unwrap_err();
        assert!(e.to_string().contains("the session's target 2"), "{e}");
        assert!(
            matches!(e.source, EfieldError::Outside { .. }),
            "{:?}",
            e.source
        );
    }
}
