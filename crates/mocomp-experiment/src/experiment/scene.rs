//! The scene: where the two robots, the tracker and the head stand, placed from the paper's goal.

use super::*;
use mocomp_geom::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use mocomp_kin::{Arm, Model, Selection};

/// Where everything is (world = the head robot's base).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scene {
    /// The coil robot's base.
    pub world_from_base1: Isometry3<f64>,
    /// The tracker.
    pub world_from_tracker: Isometry3<f64>,
    /// The phantom's marker on U2's flange (true).
    pub e2_from_head: Isometry3<f64>,
    /// The coil (and its marker) on U1's flange (true).
    pub e1_from_coil: Isometry3<f64>,
    /// U1's joints at the goal, at the start.
    pub q1_start: [f64; 6],
    /// U2's joints at the head's rest pose.
    pub q2_start: [f64; 6],
    /// The head at rest, world_from_head.
    pub world_from_head_rest: Isometry3<f64>,
}

/// The head model's goal: the coil on top of the head (semi-axis 0.11 m), 3 mm off, +z into it.
pub fn head_from_coil_design() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 0.113),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    )
}

/// The paper's goal moved along the coil's axis until the coil touches the scalp (the head
/// model's surface, where the contact law starts to push).
pub(super) fn touching_goal(cfg: &ExperimentConfig, scene: &Scene) -> Isometry3<f64> {
    let along = |s: f64| {
        cfg.goal_e2_from_e1
            * scene.e1_from_coil
            * Translation3::new(0.0, 0.0, s)
            * scene.e1_from_coil.inverse()
    };
    let head_from_coil =
        |goal: &Isometry3<f64>| scene.e2_from_head.inverse() * goal * scene.e1_from_coil;
    // The distance is exact along the normal and a lower bound elsewhere: a few steps close it.
    let mut s = 0.0;
    for _ in 0..8 {
        s += cfg.coil.distance(&cfg.head, &head_from_coil(&along(s)));
    }
    along(s)
}

/// An upright frame at `p` turned by `yaw` about the vertical.
pub(super) fn upright(p: Vector3<f64>, yaw: f64) -> Isometry3<f64> {
    Isometry3::new(p, Vector3::z() * yaw)
}

/// A frame at `from` looking at `to` along +z.
pub(super) fn look_at(from: Vector3<f64>, to: Vector3<f64>) -> Isometry3<f64> {
    let z = (to - from).normalize();
    let x = Vector3::z().cross(&z);
    let x = if x.norm() < 1e-6 {
        Vector3::x()
    } else {
        x.normalize()
    };
    let y = z.cross(&x);
    let r = mocomp_geom::nalgebra::Rotation3::from_basis_unchecked(&[x, y, z]);
    Isometry3::from_parts(
        Translation3::from(from),
        UnitQuaternion::from_rotation_matrix(&r),
    )
}

/// Of candidate placements (a frame, and the flange pose it asks of `arm`), the one whose IK
/// solution is farthest from a singularity (the first of equals): its margin, frame and joints.
pub(super) fn best_placement(
    arm: &Arm,
    seed: &[f64; 6],
    select: &Selection,
    candidates: impl Iterator<Item = (Isometry3<f64>, Isometry3<f64>)>,
) -> Option<(f64, Isometry3<f64>, [f64; 6])> {
    let mut best: Option<(f64, Isometry3<f64>, [f64; 6])> = None;
    for (frame, flange) in candidates {
        if let Ok(c) = arm.ik_closest(&flange, seed, select) {
            let margin = arm.singularity(&c.joints).margin(arm.geometry());
            if best.as_ref().is_none_or(|b| margin > b.0) {
                best = Some((margin, frame, c.joints));
            }
        }
    }
    best
}

/// The least singularity margin ([`mocomp_kin::Singularity::margin`]) a placement may have.
pub(super) const MIN_MARGIN: f64 = 0.05;

/// The least singularity margin of `arm` following `flanges` on the branch of `q`
/// (`-inf` where it cannot reach one).
pub(super) fn margin_along(
    arm: &Arm,
    q: &[f64; 6],
    flanges: impl Iterator<Item = Isometry3<f64>>,
) -> f64 {
    let mut q = *q;
    let mut least = arm.singularity(&q).margin(arm.geometry());
    for f in flanges {
        match arm.ik_closest(&f, &q, &Selection::tracking(0.05)) {
            Ok(c) => {
                q = c.joints;
                least = least.min(arm.singularity(&q).margin(arm.geometry()));
            }
            Err(_) => return f64::NEG_INFINITY,
        }
    }
    least
}

/// The chosen placement, or why there is none (`task`: what the robot must do).
pub(super) fn placed(
    best: Option<(f64, Isometry3<f64>, [f64; 6])>,
    robot: Model,
    task: &str,
) -> Result<(Isometry3<f64>, [f64; 6]), ExperimentError> {
    match best {
        None => Err(ExperimentError::Scene(format!(
            "the {robot} cannot {task} from anywhere tried"
        ))),
        Some((margin, _, _)) if margin < MIN_MARGIN => Err(ExperimentError::Scene(format!(
            "the {robot} can {task} only near a singularity"
        ))),
        Some((_, frame, q)) => Ok((frame, q)),
    }
}

/// Where a robot's calibration poses are centred, from its start flange: 10 cm back along the
/// flange axis (the coil away from the head).
pub(super) fn calibration_backoff() -> Isometry3<f64> {
    Isometry3::translation(0.0, 0.0, -0.1)
}

/// Head poses along the motion at which a candidate placement of the coil robot is checked.
pub(super) const MOTION_SAMPLES: u32 = 300;

/// Chooses the phantom's mounting from the paper's goal and the coil's design pose, then places
/// the head and both robots so that the start is well inside both arms' workspaces.
pub fn build_scene(cfg: &ExperimentConfig) -> Result<Scene, ExperimentError> {
    // The coil 8 cm out along U1's flange axis; the phantom mounted so that the paper's goal puts
    // the coil on top of the head.
    let e1_from_coil = Isometry3::translation(0.0, 0.0, 0.08);
    let e2_from_head = cfg.goal_e2_from_e1 * e1_from_coil * cfg.coil_design.inverse();
    let (world_from_head_rest, q2_start) = place_head(cfg, &e2_from_head)?;
    let (world_from_base1, q1_start) = place_coil_robot(cfg, &world_from_head_rest, &e2_from_head)?;
    // The tracker 1.3 m from the head, above and in front, looking at it.
    let h = world_from_head_rest.translation.vector;
    let world_from_tracker = look_at(h + Vector3::new(0.9, 0.5, 0.8), h);
    Ok(Scene {
        world_from_base1,
        world_from_tracker,
        e2_from_head,
        e1_from_coil,
        q1_start,
        q2_start,
        world_from_head_rest,
    })
}

/// Both robots' starts are searched from this pose, a joint limit at least this far away.
const START_SEED: [f64; 6] = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0];

fn start_selection() -> Selection {
    Selection {
        limit_margin: 0.3,
        ..Selection::default()
    }
}

/// The yaws a placement tries, 15° apart.
fn yaws() -> impl Iterator<Item = f64> + Clone {
    (0..24).map(|k| f64::from(k) * std::f64::consts::TAU / 24.0)
}

/// The head robot U2 and the phantom on it: the head at rest in the world and U2's start.
fn place_head(
    cfg: &ExperimentConfig,
    e2_from_head: &Isometry3<f64>,
) -> Result<(Isometry3<f64>, [f64; 6]), ExperimentError> {
    let arm2 = Arm::new(cfg.head_robot);
    let e2_from_head = *e2_from_head;
    let (seed, select) = (START_SEED, start_selection());
    // The head upright in front of U2: search its yaw and place for U2's best start.
    let heads = yaws().flat_map(|yaw| {
        [
            (0.35, 0.55),
            (0.45, 0.45),
            (0.3, 0.7),
            (0.5, 0.6),
            (0.25, 0.85),
        ]
        .map(|(x, z)| {
            let head = upright(Vector3::new(x, 0.0, z), yaw);
            (head, head * e2_from_head.inverse())
        })
    });
    // Placed for its start; but a motion that leads the head robot out of reach or near a
    // singularity from there (a wandering recorded head) places it for the whole motion.
    let trajectory = cfg.motion.trajectory();
    let path = &trajectory;
    let flanges = move |head: &Isometry3<f64>| {
        let head = *head;
        (0..=MOTION_SAMPLES).map(move |k| {
            let t = cfg.duration_s * f64::from(k) / f64::from(MOTION_SAMPLES);
            head * path.rest_from_head(t) * e2_from_head.inverse()
        })
    };
    let best = best_placement(&arm2, &seed, &select, heads.clone())
        .filter(|(_, head, q)| margin_along(&arm2, q, flanges(head)) >= MIN_MARGIN)
        .or_else(|| {
            heads
                .filter_map(|(head, flange)| {
                    let q = arm2.ik_closest(&flange, &seed, &select).ok()?.joints;
                    // Its calibration goes round a centre backed off from the start.
                    let centre = arm2.fk_flange(&q) * calibration_backoff();
                    arm2.ik_closest(&centre, &q, &Selection::tracking(0.1))
                        .ok()?;
                    Some((margin_along(&arm2, &q, flanges(&head)), head, q))
                })
                .max_by(|a, b| a.0.total_cmp(&b.0))
        });
    placed(best, cfg.head_robot, "hold the phantom")
}

/// The coil robot U1 beside the head: its base in the world and its start.
fn place_coil_robot(
    cfg: &ExperimentConfig,
    world_from_head_rest: &Isometry3<f64>,
    e2_from_head: &Isometry3<f64>,
) -> Result<(Isometry3<f64>, [f64; 6]), ExperimentError> {
    let arm1 = Arm::new(cfg.coil_robot);
    let (world_from_head_rest, e2_from_head) = (*world_from_head_rest, *e2_from_head);
    let (seed, select) = (START_SEED, start_selection());
    // U1 upright, beside the head: search its yaw, distance and height, for the start pose
    // farthest from a singularity over the whole head motion, its links clear of the head all
    // the way (the coil follows the head through all of it: a start chosen alone can put the
    // arm at its reach, where the elbow races, or a link beside the head).
    let world_from_e1 = world_from_head_rest * e2_from_head.inverse() * cfg.goal_e2_from_e1;
    let target = world_from_e1.translation.vector;
    let g = arm1.geometry();
    let reach = g.a2.abs() + g.a3.abs();
    let trajectory = cfg.motion.trajectory();
    // Along the motion: the head, and the coil robot's flange at the goal on it.
    let along_motion: Vec<(Isometry3<f64>, Isometry3<f64>)> = (0..=MOTION_SAMPLES)
        .map(|k| {
            let t = cfg.duration_s * f64::from(k) / f64::from(MOTION_SAMPLES);
            let head = world_from_head_rest * trajectory.rest_from_head(t);
            (head, head * e2_from_head.inverse() * cfg.goal_e2_from_e1)
        })
        .collect();
    // The loop's collision model: a placement whose arm would pass its links closer to the head
    // than the loop allows would make the loop hold, not follow.
    let (head_model, link_radius, clearance) = (
        &cfg.head,
        cfg.loop_params.link_radius_m,
        cfg.loop_params.link_clearance_m,
    );
    // Only whether each point clears: the exact distance (a descent through a 100 k-triangle
    // scalp's hierarchy) only where a bound cannot say so (most points are far from the head).
    let cutoff = link_radius + clearance + 1e-3;
    let links_clear = |base: &Isometry3<f64>, q: &[f64; 6], world_from_head: &Isometry3<f64>| {
        let head_from_base = world_from_head.inverse() * base;
        let f = arm1.link_frames(q);
        (1..6).all(|i| {
            (0..=4).all(|k| {
                let a = f[i - 1].translation.vector;
                let b = f[i].translation.vector;
                let p = mocomp_geom::nalgebra::Point3::from(a + (b - a) * (f64::from(k) / 4.0));
                head_model.distance_below(&(head_from_base * p), cutoff) - link_radius > clearance
            })
        })
    };
    let mut best: Option<(f64, Isometry3<f64>, [f64; 6])> = None;
    for yaw in yaws() {
        for r in [0.45, 0.6, 0.75] {
            for h in [-0.3, -0.15, 0.0, 0.15] {
                let offset = Vector3::new(yaw.cos(), yaw.sin(), 0.0) * r * reach;
                let base = upright(target - offset + Vector3::z() * h, yaw);
                let Ok(start) = arm1.ik_closest(&(base.inverse() * world_from_e1), &seed, &select)
                else {
                    continue;
                };
                // Its calibration goes round a centre backed off from the start: reachable on
                // the start's branch, or no calibration (a goal beside the ear turns the arm).
                let centre = arm1.fk_flange(&start.joints) * calibration_backoff();
                if arm1
                    .ik_closest(&centre, &start.joints, &Selection::tracking(0.1))
                    .is_err()
                {
                    continue;
                }
                // Follow the motion on the start's branch; the least margin on the way counts.
                let mut q = start.joints;
                let mut margin = arm1.singularity(&q).margin(arm1.geometry());
                for (head, e1) in &along_motion {
                    match arm1.ik_closest(&(base.inverse() * e1), &q, &Selection::tracking(0.05)) {
                        Ok(c) if links_clear(&base, &c.joints, head) => {
                            q = c.joints;
                            margin = margin.min(arm1.singularity(&q).margin(arm1.geometry()));
                        }
                        _ => margin = f64::NEG_INFINITY,
                    }
                }
                if best.as_ref().is_none_or(|b| margin > b.0) {
                    best = Some((margin, base, start.joints));
                }
            }
        }
    }
    placed(best, cfg.coil_robot, "reach the goal")
}
