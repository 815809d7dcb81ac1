//! Targeting by dose: the coil's place on the scalp and its turn about its axis that give a
//! brain target the largest field, along a direction (normal to the gyral wall) or as |E|.
//!
//! The coil over the scalp point nearest the target, handle as asked, is where [`place_coil`]
//! puts it: the shortest way in, not the strongest field. A figure-of-eight induces its field
//! under its centre along its wings' common current, so the turn about the axis decides the
//! field along a gyral normal (as the cosine of the angle between them), and on a curved head
//! a place a few millimetres off the nearest point can bring the windings closer to a target
//! under a sulcus' wall. The search looks within `radius_m` of the nearest scalp point.
//!
//! **How.** Every place is the coil set over a scalp point as [`place_coil`] sets it (the face
//! `standoff_m` off, lifted to clear the scalp), turned about its axis; its dose is the field
//! of the coil's dipoles in the sphere fitted to the scalp under it ([`local_sphere`]) at the
//! target. A coarse grid (a quarter of the radius apart, every 30°) finds the best region;
//! a pattern search then halves both steps around its best down to 0.25 mm and 1°. The sphere
//! and the lift depend on the place only, not the turn: each place is fitted once.
//! [`exhaustive`] evaluates a fine grid everywhere, for the test that holds the search to it.

use crate::NavError;
use crate::placement::{Handle, over};
use crate::section::direction;
use mocomp_efield::{DipoleCoil, FIT_RADIUS_M, LocalSphere, PlacedCoil, local_sphere};
use mocomp_geom::nalgebra::{Isometry3, Point3, Unit, UnitQuaternion, Vector3};
use mocomp_head::{CoilSolid, HeadShape};
use std::collections::HashMap;

/// Which part of the field is the dose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DoseAlong {
    /// Along this unit direction (image frame): the field's component, signed.
    Direction(Unit<Vector3<f64>>),
    /// The field's magnitude.
    Magnitude,
}

/// The search's reach and resolution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DoseSearch {
    /// How far from the nearest scalp point the coil's centre may go, m.
    pub radius_m: f64,
    /// The finest step of the place, m.
    pub min_step_m: f64,
    /// The finest step of the turn, rad.
    pub min_turn_rad: f64,
}

impl Default for DoseSearch {
    fn default() -> Self {
        Self {
            radius_m: 0.01,
            min_step_m: 0.00025,
            min_turn_rad: 1f64.to_radians(),
        }
    }
}

/// One place and turn and what it gives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DosePlace {
    /// The coil (image frame).
    pub image_from_coil: Isometry3<f64>,
    /// Its offset from the nearest scalp point in the tangent plane there, m (along the
    /// plane's two axes: the handle's way, and across it).
    pub offset_m: (f64, f64),
    /// Its turn about its axis from the asked handle, rad (counter-clockwise seen from outside).
    pub turn_rad: f64,
    /// The field at the target, V/m (image frame).
    pub field_v_per_m: Vector3<f64>,
    /// The dose, V/m.
    pub dose_v_per_m: f64,
}

/// What a search found.
#[derive(Debug, Clone, PartialEq)]
pub struct DoseMap {
    /// The best place and turn.
    pub best: DosePlace,
    /// The coil as [`place_coil`] puts it (no offset, no turn), for comparison.
    pub plain: DosePlace,
    /// Every place and turn evaluated, in order.
    pub evaluated: Vec<DosePlace>,
}

/// How the coil is set over a scalp point ([`place_coil`]'s way): the scalp, the coil's solid,
/// the face's standoff, the handle.
#[derive(Clone, Copy)]
pub struct CoilOver<'a> {
    /// The scalp (image frame).
    pub scalp: &'a dyn HeadShape,
    /// The coil's solid for the clearance.
    pub solid: &'a CoilSolid,
    /// The face's distance from the scalp, m.
    pub standoff_m: f64,
    /// The handle asked (the turn 0).
    pub handle: Handle,
}

impl std::fmt::Debug for CoilOver<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CoilOver")
            .field("standoff_m", &self.standoff_m)
            .field("handle", &self.handle)
            .finish_non_exhaustive()
    }
}

/// The coil's field at one point, for a coil model at a stimulator's dI/dt.
#[derive(Debug)]
pub struct FieldAt<'a> {
    /// The coil's dipoles.
    pub coil: &'a DipoleCoil,
    /// The stimulator's dI/dt, A/s.
    pub didt_a_per_s: f64,
    /// The target (image frame), m.
    pub target: Point3<f64>,
    /// Which part of the field is the dose.
    pub along: DoseAlong,
}

/// A place's coil (turn 0) and the sphere under it.
type Fitted = (Isometry3<f64>, LocalSphere);

/// The tangent plane at a scalp point: the point, two ways in the plane, the outward normal.
struct Plane {
    origin: Point3<f64>,
    u: Vector3<f64>,
    v: Vector3<f64>,
    normal: Vector3<f64>,
}

/// The places the search knows: each scalp place's coil (turn 0) and its sphere, by its grid
/// offset (in units of the finest step, so that the same place is fitted once).
struct Places<'a> {
    scalp: &'a dyn HeadShape,
    solid: &'a CoilSolid,
    standoff_m: f64,
    handle: Handle,
    field: &'a FieldAt<'a>,
    /// The nearest scalp point and the tangent plane's axes there.
    origin: Point3<f64>,
    u: Vector3<f64>,
    v: Vector3<f64>,
    normal: Vector3<f64>,
    unit_m: f64,
    radius_m: f64,
    fitted: HashMap<(i64, i64), Option<Fitted>>,
    placed: PlacedCoil,
    evaluated: Vec<DosePlace>,
}

impl Places<'_> {
    /// The coil at offset `(i, j)` finest steps, turn 0, and its sphere (`None`: off the scalp,
    /// beyond the radius, or no place for the coil there).
    fn place(&mut self, i: i64, j: i64) -> Option<Fitted> {
        if let Some(p) = self.fitted.get(&(i, j)) {
            return *p;
        }
        let (a, b) = (i as f64 * self.unit_m, j as f64 * self.unit_m);
        let p = if a.hypot(b) > self.radius_m + 1e-12 {
            None
        } else {
            let q = self.origin + self.u * a + self.v * b + self.normal * 0.01;
            let on = self.scalp.nearest(&q).point;
            over(self.scalp, self.solid, &on, self.standoff_m, &self.handle)
                .ok()
                .and_then(|c| {
                    local_sphere(self.scalp, &c.image_from_coil, FIT_RADIUS_M)
                        .ok()
                        .map(|s| (c.image_from_coil, s))
                })
        };
        self.fitted.insert((i, j), p);
        p
    }

    /// The dose at offset `(i, j)` turned by `turn` (`None` where there is no place or field).
    fn dose(&mut self, i: i64, j: i64, turn: f64) -> Option<DosePlace> {
        let (pose0, sphere) = self.place(i, j)?;
        // The handle turned counter-clockwise about the outward normal is the coil turned
        // clockwise about its own axis (+z, into the head).
        let pose = pose0 * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -turn);
        let f = self.field;
        self.placed.place(f.coil, &pose, &sphere.sphere).ok()?;
        let e = self.placed.e_field(&f.target, f.didt_a_per_s).ok()?;
        let dose = match f.along {
            DoseAlong::Direction(d) => e.dot(&d),
            DoseAlong::Magnitude => e.norm(),
        };
        let place = DosePlace {
            image_from_coil: pose,
            offset_m: (i as f64 * self.unit_m, j as f64 * self.unit_m),
            turn_rad: turn,
            field_v_per_m: e,
            dose_v_per_m: dose,
        };
        self.evaluated.push(place);
        Some(place)
    }
}

fn better(a: Option<DosePlace>, b: Option<DosePlace>) -> Option<DosePlace> {
    match (a, b) {
        (Some(a), Some(b)) => Some(if b.dose_v_per_m > a.dose_v_per_m {
            b
        } else {
            a
        }),
        (a, None) => a,
        (None, b) => b,
    }
}

/// The tangent plane at the scalp point nearest `target`: the point, the handle's way and the
/// way across it in the plane, the outward normal.
fn plane(scalp: &dyn HeadShape, target: &Point3<f64>, handle: &Handle) -> Result<Plane, NavError> {
    let near = scalp.nearest(target);
    let n = near.normal.into_inner();
    let along = handle.toward - n * handle.toward.dot(&n);
    let u = direction(&along).ok_or(NavError::HandleAlongNormal)?;
    Ok(Plane {
        origin: near.point,
        u,
        v: n.cross(&u),
        normal: n,
    })
}

/// The search's start: its places, the plain placement's dose, and the radius in finest steps.
fn start<'a>(
    over: &CoilOver<'a>,
    field: &'a FieldAt<'a>,
    params: &DoseSearch,
) -> Result<(Places<'a>, DosePlace, i64), NavError> {
    if !(params.radius_m.is_finite()
        && params.radius_m >= 0.0
        && params.min_step_m > 0.0
        && params.min_turn_rad > 0.0)
    {
        return Err(NavError::BadSearch(format!("{params:?}")));
    }
    let Plane {
        origin,
        u,
        v,
        normal,
    } = plane(over.scalp, &field.target, &over.handle)?;
    let mut p = Places {
        scalp: over.scalp,
        solid: over.solid,
        standoff_m: over.standoff_m,
        handle: over.handle,
        field,
        origin,
        u,
        v,
        normal,
        unit_m: params.min_step_m,
        radius_m: params.radius_m,
        fitted: HashMap::new(),
        placed: PlacedCoil::with_capacity(field.coil.len()),
        evaluated: Vec::new(),
    };
    let plain = p.dose(0, 0, 0.0).ok_or(NavError::NoDose)?;
    let reach = (params.radius_m / params.min_step_m).floor() as i64;
    Ok((p, plain, reach))
}

/// The best place within `params.radius_m` of the scalp point nearest the target, and turn,
/// for the coil's dose at `field`'s target; the coil set as `over` says. Refused where no place gives a field (the target outside every
/// sphere under the coil).
pub fn search(
    over: &CoilOver<'_>,
    field: &FieldAt<'_>,
    params: &DoseSearch,
) -> Result<DoseMap, NavError> {
    let (mut p, plain, reach) = start(over, field, params)?;
    // The coarse grid: a quarter of the radius apart (in whole finest steps), every 30°.
    let coarse = ((params.radius_m / 4.0 / params.min_step_m).round() as i64).max(1);
    let mut best = Some(plain);
    let turns = 12;
    let mut i = -reach / coarse * coarse;
    while i <= reach {
        let mut j = -reach / coarse * coarse;
        while j <= reach {
            for k in 0..turns {
                let turn = std::f64::consts::TAU * f64::from(k) / f64::from(turns);
                best = better(best, p.dose(i, j, turn));
            }
            j += coarse;
        }
        i += coarse;
    }
    // The pattern search around the best: halve the steps until both are the finest.
    let mut at = best.map_or((0, 0, 0.0), |b| {
        (
            (b.offset_m.0 / params.min_step_m).round() as i64,
            (b.offset_m.1 / params.min_step_m).round() as i64,
            b.turn_rad,
        )
    });
    let mut step = (coarse / 2).max(1);
    let mut turn_step = std::f64::consts::TAU / f64::from(turns) / 2.0;
    loop {
        loop {
            let (i, j, t) = at;
            let mut moved = false;
            for (di, dj, dt) in [
                (step, 0, 0.0),
                (-step, 0, 0.0),
                (0, step, 0.0),
                (0, -step, 0.0),
                (0, 0, turn_step),
                (0, 0, -turn_step),
            ] {
                let here = p.dose(i + di, j + dj, t + dt);
                let b = better(best, here);
                if b != best {
                    best = b;
                    at = (i + di, j + dj, t + dt);
                    moved = true;
                }
            }
            if !moved {
                break;
            }
        }
        if step == 1 && turn_step <= params.min_turn_rad {
            break;
        }
        step = (step / 2).max(1);
        turn_step = (turn_step / 2.0).max(params.min_turn_rad);
    }
    Ok(DoseMap {
        best: best.unwrap_or(plain),
        plain,
        evaluated: p.evaluated,
    })
}

/// Every place on a grid of `params.min_step_m` within the radius and every turn
/// `params.min_turn_rad` apart: the search's reference.
pub fn exhaustive(
    over: &CoilOver<'_>,
    field: &FieldAt<'_>,
    params: &DoseSearch,
) -> Result<DoseMap, NavError> {
    let (mut p, plain, reach) = start(over, field, params)?;
    let turns = (std::f64::consts::TAU / params.min_turn_rad).round() as u32;
    let mut best = Some(plain);
    for i in -reach..=reach {
        for j in -reach..=reach {
            for k in 0..turns {
                let turn = std::f64::consts::TAU * f64::from(k) / f64::from(turns);
                best = better(best, p.dose(i, j, turn));
            }
        }
    }
    Ok(DoseMap {
        best: best.unwrap_or(plain),
        plain,
        evaluated: p.evaluated,
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr)] // test code
    use super::*;
    use mocomp_efield::parse_ccd;
    use mocomp_head::Ellipsoid;

    /// SimNIBS's Magstim D70 (its dipoles; the test reads the repository's copy).
    fn d70() -> DipoleCoil {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../mocomp-efield/tests/data/coils/MagStim_D70.ccd");
        parse_ccd("D70", &std::fs::read_to_string(path).unwrap()).unwrap()
    }

    /// A target 20 mm under the adult ellipsoid's scalp off its pole, where the curvature
    /// differs along the two tangent ways.
    fn setup() -> (Ellipsoid, Point3<f64>, CoilSolid) {
        let head = Ellipsoid::adult();
        let way = Vector3::new(0.35, 0.2, 0.9).normalize();
        let on = head.nearest(&(Point3::origin() + way * 0.2));
        let target = on.point - on.normal.into_inner() * 0.02;
        (head, target, CoilSolid::new(0.04, 0.02).unwrap())
    }

    fn over<'a>(head: &'a Ellipsoid, solid: &'a CoilSolid) -> CoilOver<'a> {
        CoilOver {
            scalp: head,
            solid,
            standoff_m: 0.004,
            handle: Handle::default(),
        }
    }

    #[test]
    fn the_search_finds_what_the_exhaustive_grid_finds_for_a_fraction_of_the_work() {
        let (head, target, solid) = setup();
        let coil = d70();
        let near = head.nearest(&target);
        // A gyral normal in the tangent plane, 50° from the handle's default way (posterior):
        // the coil as placed plainly gives it cos 50° of its field; turned, nearly all.
        let n = near.normal.into_inner();
        let back = (-Vector3::y() - n * (-n.y)).normalize();
        let d = UnitQuaternion::from_axis_angle(&Unit::new_normalize(n), 50f64.to_radians())
            * n.cross(&back);
        let field = FieldAt {
            coil: &coil,
            didt_a_per_s: 1e8,
            target,
            along: DoseAlong::Direction(Unit::new_normalize(d)),
        };
        let params = DoseSearch {
            radius_m: 0.008,
            min_step_m: 0.001,
            min_turn_rad: 5f64.to_radians(),
        };
        let over = over(&head, &solid);
        let found = search(&over, &field, &params).unwrap();
        let all = exhaustive(&over, &field, &params).unwrap();
        let (f, a) = (found.best.dose_v_per_m, all.best.dose_v_per_m);
        eprintln!(
            "search {f:.3} V/m in {} evaluations, exhaustive {a:.3} V/m in {}, plain {:.3} V/m; \
             best offset {:.1}, {:.1} mm, turn {:.1}°",
            found.evaluated.len(),
            all.evaluated.len(),
            found.plain.dose_v_per_m,
            found.best.offset_m.0 * 1e3,
            found.best.offset_m.1 * 1e3,
            found.best.turn_rad.to_degrees()
        );
        assert!(f >= a * 0.999, "search {f} V/m, exhaustive {a} V/m");
        assert!(
            f <= a * (1.0 + 1e-9),
            "the search beat its own grid: {f} {a}"
        );
        assert!(
            found.evaluated.len() * 5 < all.evaluated.len(),
            "{} against {}",
            found.evaluated.len(),
            all.evaluated.len()
        );
        // Turned, the field at the target lies along the gyral normal, and the dose is well
        // above the plain placement's.
        let e = found.best.field_v_per_m;
        assert!(e.angle(&d) < 10f64.to_radians(), "{e} against {d}");
        assert!(
            f > found.plain.dose_v_per_m * 1.2,
            "{f} against {}",
            found.plain.dose_v_per_m
        );
        // The best place within the radius, its coil facing into the head.
        let (x, y) = found.best.offset_m;
        assert!(x.hypot(y) <= params.radius_m + 1e-12);
        let z = found.best.image_from_coil.rotation * Vector3::z();
        assert!(z.dot(&n) < -0.9, "{z}");
    }

    #[test]
    fn as_a_magnitude_turning_matters_little_and_a_target_outside_is_refused() {
        let (head, target, solid) = setup();
        let coil = d70();
        let field = FieldAt {
            coil: &coil,
            didt_a_per_s: 1e8,
            target,
            along: DoseAlong::Magnitude,
        };
        let params = DoseSearch::default();
        let over = over(&head, &solid);
        let m = search(&over, &field, &params).unwrap();
        let gain = m.best.dose_v_per_m / m.plain.dose_v_per_m;
        eprintln!(
            "|E|: {:.3} V/m against {:.3} plainly, {} evaluations",
            m.best.dose_v_per_m,
            m.plain.dose_v_per_m,
            m.evaluated.len()
        );
        assert!((1.0..1.15).contains(&gain), "{gain}");
        let outside = FieldAt {
            target: Point3::new(0.0, 0.0, 0.3),
            ..field
        };
        let e = search(&over, &outside, &params).unwrap_err();
        assert!(matches!(e, NavError::NoDose), "{e}");
        let bad = DoseSearch {
            min_step_m: 0.0,
            ..params
        };
        assert!(matches!(
            search(&over, &field, &bad),
            Err(NavError::BadSearch(_))
        ));
    }
}
