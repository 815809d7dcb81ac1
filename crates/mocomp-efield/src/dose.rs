//! The dose: the field a pulse gives at a brain target, against the one planned.
//!
//! A plan ([`PlannedDose`]) is made once per coil goal: the sphere fitted to the scalp under the
//! coil there ([`crate::local_sphere`]), the target (a point in the brain, or the point
//! [`DoseModel::depth_m`] under the scalp on the coil's axis), the direction the dose is taken
//! along (given, the planned field's own, or none for |E|) and the field there. A
//! [`DoseMeter`] then measures any coil pose against a plan allocating nothing: the loop's
//! cycle and every pulse can afford it. The sphere stays the plan's while the coil moves about
//! its goal: the head does not change shape when the coil slides a few millimetres.

use crate::ccd::DipoleCoil;
use crate::error::EfieldError;
use crate::local::{FIT_RADIUS_M, LocalSphere, local_sphere};
use crate::sphere::PlacedCoil;
use mocomp_geom::nalgebra::{Isometry3, Point3, Unit, Vector3};
use mocomp_head::HeadShape;
use std::sync::Arc;

/// A coil model driven at a given rate, and where its targets lie by default.
#[derive(Debug, Clone, PartialEq)]
pub struct DoseModel {
    /// The coil's dipoles.
    pub coil: Arc<DipoleCoil>,
    /// The stimulator's dI/dt, A/s.
    pub didt_a_per_s: f64,
    /// A target not given as a point: this far under the scalp on the goal coil's axis, m.
    pub depth_m: f64,
}

/// Which part of the field is the dose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Along {
    /// Along the field the planned pose gives at the target (its direction kept fixed in the
    /// head): turning the coil lowers the dose as the cosine of the turn.
    Planned,
    /// Along a given direction (head frame), e.g. normal to the gyral wall.
    Direction(Unit<Vector3<f64>>),
    /// The field's magnitude, whatever its direction.
    Magnitude,
}

/// What a coil goal is to give.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedDose {
    /// The goal, head frame.
    pub head_from_coil: Isometry3<f64>,
    /// The sphere fitted under the coil at its goal.
    pub sphere: LocalSphere,
    /// The target, head frame, m.
    pub target: Point3<f64>,
    /// The unit direction the dose is taken along (`None`: |E|).
    pub direction: Option<Unit<Vector3<f64>>>,
    /// The planned field at the target, V/m (head frame).
    pub field_v_per_m: Vector3<f64>,
    /// The planned dose, V/m.
    pub dose_v_per_m: f64,
}

impl PlannedDose {
    /// The plan for the coil at `head_from_coil` over `scalp`: the target `target` (head frame)
    /// or, without one, [`DoseModel::depth_m`] under the scalp on the coil's axis.
    pub fn new(
        meter: &mut DoseMeter,
        scalp: &dyn HeadShape,
        head_from_coil: &Isometry3<f64>,
        target: Option<Point3<f64>>,
        along: Along,
    ) -> Result<Self, EfieldError> {
        let sphere = local_sphere(scalp, head_from_coil, FIT_RADIUS_M)?;
        let axis = head_from_coil.rotation * Vector3::z();
        let target = target.unwrap_or(sphere.under_coil + axis * meter.model.depth_m);
        let field = meter.field(&sphere, head_from_coil, &target)?;
        let direction = match along {
            Along::Planned => Some(Unit::try_new(field, 1e-12).ok_or_else(|| {
                EfieldError::NoField {
                    what: "the planned pose gives no field at the target to take a direction from"
                        .into(),
                }
            })?),
            Along::Direction(d) => Some(d),
            Along::Magnitude => None,
        };
        let dose = along_direction(&field, direction.as_ref());
        // A direction across the field (radial, say) has nothing to measure a change against.
        if dose.abs() <= 1e-6 * field.norm() || field.norm() == 0.0 || !dose.is_finite() {
            return Err(EfieldError::NoField {
                what: format!(
                    "the planned pose gives {dose} V/m at the target along its direction"
                ),
            });
        }
        Ok(Self {
            head_from_coil: *head_from_coil,
            sphere,
            target,
            direction,
            field_v_per_m: field,
            dose_v_per_m: dose,
        })
    }
}

fn along_direction(field: &Vector3<f64>, direction: Option<&Unit<Vector3<f64>>>) -> f64 {
    direction.map_or_else(|| field.norm(), |d| field.dot(d))
}

/// Measures coil poses against plans, allocating nothing once made.
#[derive(Debug, Clone)]
pub struct DoseMeter {
    model: DoseModel,
    placed: PlacedCoil,
}

impl DoseMeter {
    /// A meter for `model`.
    pub fn new(model: DoseModel) -> Self {
        let placed = PlacedCoil::with_capacity(model.coil.len());
        Self { model, placed }
    }

    /// Its model.
    pub fn model(&self) -> &DoseModel {
        &self.model
    }

    fn field(
        &mut self,
        sphere: &LocalSphere,
        head_from_coil: &Isometry3<f64>,
        at: &Point3<f64>,
    ) -> Result<Vector3<f64>, EfieldError> {
        self.placed
            .place(&self.model.coil, head_from_coil, &sphere.sphere)?;
        self.placed.e_field(at, self.model.didt_a_per_s)
    }

    /// The dose the coil at `head_from_coil` gives at `plan`'s target, V/m.
    pub fn dose(
        &mut self,
        plan: &PlannedDose,
        head_from_coil: &Isometry3<f64>,
    ) -> Result<f64, EfieldError> {
        let field = self.field(&plan.sphere, head_from_coil, &plan.target)?;
        Ok(along_direction(&field, plan.direction.as_ref()))
    }

    /// [`Self::dose`] as a percentage of the plan's.
    pub fn dose_pct(
        &mut self,
        plan: &PlannedDose,
        head_from_coil: &Isometry3<f64>,
    ) -> Result<f64, EfieldError> {
        Ok(100.0 * self.dose(plan, head_from_coil)? / plan.dose_v_per_m)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use crate::test_coil::eight;
    use mocomp_geom::nalgebra::{Translation3, UnitQuaternion};
    use mocomp_head::Ellipsoid;

    fn setup() -> (DoseMeter, Ellipsoid, Isometry3<f64>) {
        let head = Ellipsoid::new(Isometry3::identity(), Vector3::new(0.1, 0.08, 0.09)).unwrap();
        let goal = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 0.093),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        );
        let meter = DoseMeter::new(DoseModel {
            coil: Arc::new(eight()),
            didt_a_per_s: 1e8,
            depth_m: 0.015,
        });
        (meter, head, goal)
    }

    #[test]
    fn the_goal_gives_its_planned_dose_and_moving_off_it_less() {
        let (mut meter, head, goal) = setup();
        let plan = PlannedDose::new(&mut meter, &head, &goal, None, Along::Planned).unwrap();
        // The target: 15 mm under the scalp point under the coil, on its axis.
        assert!(
            (plan.target - Point3::new(0.0, 0.0, 0.09 - 0.015)).norm() < 1e-9,
            "{plan:?}"
        );
        assert!((meter.dose_pct(&plan, &goal).unwrap() - 100.0).abs() < 1e-9);
        let lifted = Isometry3::translation(0.0, 0.0, 0.002) * goal;
        let turned = goal * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.3);
        let lift = meter.dose_pct(&plan, &lifted).unwrap();
        let turn = meter.dose_pct(&plan, &turned).unwrap();
        assert!(lift < 95.0 && lift > 80.0, "{lift}");
        // Along the planned direction a turn costs about the cosine; as |E| much less.
        assert!((turn - 100.0 * 0.3f64.cos()).abs() < 2.0, "{turn}");
        let magnitude = PlannedDose::new(&mut meter, &head, &goal, None, Along::Magnitude).unwrap();
        let turn_m = meter.dose_pct(&magnitude, &turned).unwrap();
        assert!(turn_m > turn + 2.0, "{turn_m} {turn}");
    }

    #[test]
    fn a_target_or_direction_that_gives_nothing_is_refused_by_name() {
        let (mut meter, head, goal) = setup();
        // Along the axis (radial in the sphere): no field.
        let radial = Along::Direction(Vector3::z_axis());
        let e = PlannedDose::new(&mut meter, &head, &goal, None, radial).unwrap_err();
        assert!(e.to_string().contains("along its direction"), "{e}");
        // A target outside the head.
        let e = PlannedDose::new(
            &mut meter,
            &head,
            &goal,
            Some(Point3::new(0.0, 0.0, 0.2)),
            Along::Planned,
        )
        .unwrap_err();
        assert!(e.to_string().contains("beyond its radius"), "{e}");
    }

    #[test]
    fn measuring_allocates_nothing() {
        let (mut meter, head, goal) = setup();
        let plan = PlannedDose::new(&mut meter, &head, &goal, None, Along::Planned).unwrap();
        let before = meter.placed.clone();
        for k in 0..20 {
            let p = Isometry3::translation(0.0001 * k as f64, 0.0, 0.0) * goal;
            meter.dose(&plan, &p).unwrap();
        }
        assert_eq!(meter.placed.len(), before.len());
    }
}
