//! Where the head must sit for the arm to reach a session's targets: each target checked at a
//! placement as the loop would plan it ([`mocomp_control::compensator::reach`]), and a search over
//! the head's place relative to the robot's base (a box around the configured place, and turns
//! about the vertical) for the one that reaches every target with the most margin.
//!
//! The placement is the head's pose in the robot's base frame at rest. In the built-in world it
//! is `tracker.simulated.base_from_head`; in a clinic, it is where the chair stands relative to
//! the robot (the same transform, read the other way).

use crate::AppError;
use crate::config::Setup;
use mocomp_control::Compensator;
use mocomp_control::compensator::reach::Reach;
use mocomp_geom::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// One target at one placement.
#[derive(Debug, Clone)]
pub struct TargetReach {
    /// The target's name.
    pub name: String,
    /// Whether and how.
    pub reach: Reach,
    /// The rule that keeps the loop from it, if any.
    pub refusal: Option<mocomp_control::Reason>,
}

/// The targets at the configured placement ([`Targets::at_configured`]).
#[derive(Debug, Clone)]
pub struct Configured {
    /// The placement, base_from_head.
    pub place: Isometry3<f64>,
    /// The arm's rest there, rad.
    pub rest: [f64; 6],
    /// Each target.
    pub reaches: Vec<TargetReach>,
}

/// The loops that would track each target: one per goal, made once and planned on copies.
#[derive(Debug)]
pub struct Targets {
    loops: Vec<(String, Compensator)>,
    slow: f64,
}

impl Targets {
    /// A loop for each `(name, head_from_coil)` under `setup`.
    pub fn new(setup: &Setup, goals: &[(String, Isometry3<f64>)]) -> Result<Self, AppError> {
        let cfg = setup.loop_config()?;
        let slow = cfg.params.singularity_slow;
        let loops = goals
            .iter()
            .map(|(name, goal)| {
                let mut c = cfg.clone();
                c.head_from_coil_goal = *goal;
                (name.clone(), Compensator::new(c, setup.arm, setup.period()))
            })
            .collect();
        Ok(Self { loops, slow })
    }

    /// Each target with the head at `base_from_head` and the arm resting at `rest`.
    pub fn check(&self, base_from_head: &Isometry3<f64>, rest: &[f64; 6]) -> Vec<TargetReach> {
        (0..self.loops.len())
            .map(|k| self.check_one(k, base_from_head, rest))
            .collect()
    }

    /// Target `k` with the head at `base_from_head` and the arm resting at `rest`.
    fn check_one(&self, k: usize, base_from_head: &Isometry3<f64>, rest: &[f64; 6]) -> TargetReach {
        let (name, c) = &self.loops[k];
        let reach = c.reach(rest, base_from_head);
        TargetReach {
            name: name.clone(),
            refusal: reach.refusal(self.slow),
            reach,
        }
    }

    /// Whether target `k` is surely refused with the head at `base_from_head`: no joint
    /// solution at it on any branch (one IK solve; `check` would plan a way first).
    fn surely_refused(&self, k: usize, base_from_head: &Isometry3<f64>) -> bool {
        !self.loops[k].1.goal_has_solution(base_from_head)
    }

    /// The targets at a placement as [`Self::check`] gives them when every one is reached;
    /// `None` as soon as one is refused. Targets are tried in `order`, and the one refused is
    /// moved to its front: neighbouring placements tend to fail on the same target, so most
    /// are turned down by one check, and first by its IK alone where that suffices.
    fn all_reached(
        &self,
        order: &mut [usize],
        base_from_head: &Isometry3<f64>,
        rest: &[f64; 6],
    ) -> Option<Vec<TargetReach>> {
        let mut reaches: Vec<Option<TargetReach>> = vec![None; self.loops.len()];
        for i in 0..order.len() {
            let k = order[i];
            let refused = self.surely_refused(k, base_from_head) || {
                let r = self.check_one(k, base_from_head, rest);
                let refused = r.reach.score(self.slow) <= 0.0;
                reaches[k] = Some(r);
                refused
            };
            if refused {
                order[..=i].rotate_right(1);
                return None;
            }
        }
        reaches.into_iter().collect()
    }

    /// Each target at the configured placement (`tracker.simulated.base_from_head`), the arm
    /// at its rest there: the placement, the rest and the reaches. What `placement check` and
    /// `targets add` report.
    pub fn at_configured(&self, setup: &Setup) -> Result<Configured, AppError> {
        let place = setup.file.tracker.simulated.base_from_head.iso();
        let rest = setup.initial_joints_at(&place)?;
        let reaches = self.check(&place, &rest);
        Ok(Configured {
            place,
            rest,
            reaches,
        })
    }

    /// The placement's figure: the least of its targets' (0: one is refused).
    pub fn score(&self, reaches: &[TargetReach]) -> f64 {
        reaches
            .iter()
            .map(|r| r.reach.score(self.slow))
            .fold(f64::INFINITY, f64::min)
    }
}

/// The places tried: a box about the configured place (in the base frame, m) on a grid, each
/// turned about the vertical through the head's origin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Region {
    /// Half the box's size along the base's x, y and z, m.
    pub half_m: [f64; 3],
    /// The grid's step, m.
    pub step_m: f64,
    /// Turns tried about the vertical, each way, rad.
    pub yaw_half_rad: f64,
    /// Their step, rad.
    pub yaw_step_rad: f64,
}

impl Default for Region {
    /// ±20 cm across, ±10 cm up and down, in 5 cm; ±90° in 15°: where a chair and its
    /// headrest go.
    fn default() -> Self {
        Self {
            half_m: [0.2, 0.2, 0.1],
            step_m: 0.05,
            yaw_half_rad: std::f64::consts::FRAC_PI_2,
            yaw_step_rad: 15f64.to_radians(),
        }
    }
}

impl Region {
    /// Checks the numbers (the field named).
    pub fn check(&self) -> Result<(), AppError> {
        let bad = |what: &str, v: f64| {
            AppError::Config(format!("{what} {v}: must be a finite number, 0 or more"))
        };
        for (i, h) in self.half_m.iter().enumerate() {
            if !(h.is_finite() && *h >= 0.0) {
                return Err(bad(["region x", "region y", "region z"][i], *h));
            }
        }
        if !(self.yaw_half_rad.is_finite() && self.yaw_half_rad >= 0.0) {
            return Err(bad("yaw", self.yaw_half_rad.to_degrees()));
        }
        if !(self.step_m.is_finite() && self.step_m > 0.0) {
            return Err(bad("step", self.step_m));
        }
        if !(self.yaw_step_rad.is_finite() && self.yaw_step_rad > 0.0) {
            return Err(bad("yaw step", self.yaw_step_rad.to_degrees()));
        }
        let n = self.candidates_count();
        if n > MAX_CANDIDATES {
            return Err(AppError::Config(format!(
                "the region holds {n} placements, more than {MAX_CANDIDATES}: a larger step"
            )));
        }
        Ok(())
    }

    fn steps(half: f64, step: f64) -> Vec<f64> {
        let n = (half / step + 1e-9).floor() as i64;
        (-n..=n).map(|k| k as f64 * step).collect()
    }

    fn candidates_count(&self) -> usize {
        let n = |h: f64, s: f64| 2 * (h / s + 1e-9).floor() as usize + 1;
        n(self.half_m[0], self.step_m)
            * n(self.half_m[1], self.step_m)
            * n(self.half_m[2], self.step_m)
            * n(self.yaw_half_rad, self.yaw_step_rad)
    }

    /// The placements about `centre`, nearest it first (so that among equals the least move
    /// wins).
    pub fn candidates(&self, centre: &Isometry3<f64>) -> Vec<Isometry3<f64>> {
        let mut out = Vec::with_capacity(self.candidates_count());
        for dx in Self::steps(self.half_m[0], self.step_m) {
            for dy in Self::steps(self.half_m[1], self.step_m) {
                for dz in Self::steps(self.half_m[2], self.step_m) {
                    for yaw in Self::steps(self.yaw_half_rad, self.yaw_step_rad) {
                        out.push(moved(centre, Vector3::new(dx, dy, dz), yaw));
                    }
                }
            }
        }
        out.sort_by(|a, b| {
            let d = |p: &Isometry3<f64>| {
                (p.translation.vector - centre.translation.vector).norm()
                    + 0.1 * p.rotation.angle_to(&centre.rotation)
            };
            d(a).total_cmp(&d(b))
        });
        out
    }
}

/// The most placements a search tries.
pub const MAX_CANDIDATES: usize = 50_000;

/// `centre` moved by `shift` (base frame) and turned by `yaw` about the base's vertical through
/// the head's origin.
pub fn moved(centre: &Isometry3<f64>, shift: Vector3<f64>, yaw: f64) -> Isometry3<f64> {
    let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
    Isometry3::from_parts(
        Translation3::from(centre.translation.vector + shift),
        turn * centre.rotation,
    )
}

/// A search's outcome.
#[derive(Debug, Clone)]
pub struct Found {
    /// The best placement (`None`: none reaches every target).
    pub best: Option<(Isometry3<f64>, f64, Vec<TargetReach>)>,
    /// Placements tried.
    pub tried: usize,
    /// Of them, those that reach every target.
    pub reaching: usize,
}

/// The placement in `region` about `centre` that reaches every target with the most margin,
/// each tried with the arm resting where `rest` puts it for that placement.
pub fn search(
    targets: &Targets,
    centre: &Isometry3<f64>,
    region: &Region,
    rest: impl Fn(&Isometry3<f64>) -> Option<[f64; 6]>,
) -> Found {
    let mut found = Found {
        best: None,
        tried: 0,
        reaching: 0,
    };
    let mut order: Vec<usize> = (0..targets.loops.len()).collect();
    for place in region.candidates(centre) {
        found.tried += 1;
        let Some(q) = rest(&place) else { continue };
        // A placement with a target refused scores 0 ([`Targets::score`]): it is not one that
        // reaches, whichever target it fails first.
        let Some(reaches) = targets.all_reached(&mut order, &place, &q) else {
            continue;
        };
        let score = targets.score(&reaches);
        if score <= 0.0 {
            continue;
        }
        found.reaching += 1;
        // Strictly better only: nearer the configured place wins a tie.
        if found.best.as_ref().is_none_or(|b| score > b.1 + 1e-9) {
            found.best = Some((place, score, reaches));
        }
    }
    found
}

/// A placement as the configuration writes a pose: `[x, y, z, rx, ry, rz]` (m, rotation vector).
pub fn pose_vector(p: &Isometry3<f64>) -> [f64; 6] {
    let t = p.translation.vector;
    let r = p.rotation.scaled_axis();
    [t.x, t.y, t.z, r.x, r.y, r.z]
}

/// The goals to check: the targets file's (`file`, else `[session] targets`), those named in
/// `only` if any, else the configuration's `[goal]` alone (named `goal`).
pub fn goals(
    setup: &Setup,
    file: Option<&std::path::Path>,
    only: &[String],
) -> Result<Vec<(String, Isometry3<f64>)>, AppError> {
    let path = file.map(std::path::Path::to_path_buf).or_else(|| {
        setup
            .file
            .session
            .targets
            .as_ref()
            .map(|f| setup.dir.join(f))
    });
    let Some(path) = path else {
        if let Some(name) = only.first() {
            return Err(AppError::Config(format!(
                "--target {name}: no targets file (--targets FILE, or [session] targets)"
            )));
        }
        return Ok(vec![("goal".into(), setup.file.head_from_coil()?)]);
    };
    let targets = crate::navigation::targets::load(&path)?;
    let mut out = Vec::new();
    for t in &targets.targets {
        if only.is_empty() || only.contains(&t.name) {
            out.push((
                t.name.clone(),
                crate::navigation::targets::head_from_coil(setup, t),
            ));
        }
    }
    for name in only {
        if !out.iter().any(|(n, _)| n == name) {
            return Err(AppError::Config(format!(
                "--target {name}: not in {}",
                path.display()
            )));
        }
    }
    if out.is_empty() {
        return Err(AppError::Config(format!(
            "{}: no targets in it",
            path.display()
        )));
    }
    Ok(out)
}

impl std::fmt::Display for TargetReach {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use mocomp_control::compensator::reach::{HEADROOM_M, HEADROOM_MOVES, HEADROOM_RAD, Way};
        match &self.refusal {
            Some(r) => write!(f, "{}: NOT REACHABLE: {r}", self.name)?,
            None => write!(f, "{}: reachable", self.name)?,
        }
        match self.reach.way {
            Ok(Way::Shell) => write!(f, "; the way: along the shell around the head")?,
            Ok(Way::Transit(q)) => write!(
                f,
                "; the way: a joint move ({:.0}° at most) to its axis, then the shell",
                q.to_degrees()
            )?,
            Err(_) => {}
        }
        if let Some(g) = &self.reach.at_goal {
            write!(
                f,
                "; at it: arm {}, {:.0}° from a joint limit, singularity margin {:.2}; the head \
                 may turn {:.0}° or move {:.0} mm each way: {} of {} followed (least margin {:.2})",
                g.branch,
                g.joint_margin_rad.to_degrees(),
                g.singularity_margin,
                HEADROOM_RAD.to_degrees(),
                HEADROOM_M * 1e3,
                g.headroom_ok,
                HEADROOM_MOVES,
                g.headroom_singularity_margin
            )?;
        }
        if let Some(a) = self
            .refusal
            .as_ref()
            .and_then(mocomp_control::Reason::advice)
        {
            write!(f, "; {a}")?;
        }
        Ok(())
    }
}

/// The placements drawn ([`mocomp_report::placement`]): the head's outline from `setup`'s head
/// model, `goals` at the `configured` placement and, after a search, at the `found` one, each
/// marked by its reach there.
pub fn view(
    setup: &Setup,
    goals: &[(String, Isometry3<f64>)],
    configured: (&Isometry3<f64>, &[TargetReach]),
    found: Option<(&Isometry3<f64>, &[TargetReach])>,
) -> Result<mocomp_report::placement::PlacementView, AppError> {
    use mocomp_report::placement::{Place, PlacementView};
    let head = setup.file.head_model()?;
    let place = |(at, reaches): (&Isometry3<f64>, &[TargetReach])| Place {
        base_from_head: *at,
        targets: goals
            .iter()
            .map(|(name, goal)| {
                let reached = reaches
                    .iter()
                    .any(|r| &r.name == name && r.refusal.is_none());
                (name.clone(), *goal, reached)
            })
            .collect(),
    };
    let g = setup.arm.geometry();
    Ok(PlacementView {
        robot: setup.model.to_string(),
        reach_m: g.a2.abs() + g.a3.abs(),
        outline: outline(&head),
        face: setup.file.head.head_from_image.iso().rotation * Vector3::y(),
        configured: place(configured),
        found: found.map(place),
    })
}

/// The head seen from above: for each of 72 directions about its centre, its farthest point
/// that way (the scalp's vertices, or the ellipsoid's equator), in the head's frame.
fn outline(head: &mocomp_control::HeadModel) -> Vec<mocomp_geom::nalgebra::Point3<f64>> {
    use mocomp_geom::nalgebra::Point3;
    let points: Vec<Point3<f64>> = match (head.shape().scalp(), head.as_ellipsoid()) {
        (Some(m), _) => m.vertices().to_vec(),
        (None, Some(e)) => {
            let r = e.radii();
            (0..144)
                .map(|k| {
                    let a = std::f64::consts::TAU * f64::from(k) / 144.0;
                    e.head_from_ellipsoid() * Point3::new(r.x * a.cos(), r.y * a.sin(), 0.0)
                })
                .collect()
        }
        (None, None) => Vec::new(),
    };
    if points.is_empty() {
        return points;
    }
    let centre = points.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / points.len() as f64;
    (0..72)
        .filter_map(|k| {
            let a = std::f64::consts::TAU * f64::from(k) / 72.0;
            let d = Vector3::new(a.cos(), a.sin(), 0.0);
            points
                .iter()
                .max_by(|p, q| {
                    (p.coords - centre)
                        .dot(&d)
                        .total_cmp(&(q.coords - centre).dot(&d))
                })
                .copied()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use crate::config::Config;

    /// The built-in world with the head at `place` (a UR pose vector).
    fn setup(place: &str) -> Setup {
        let text = format!("[tracker.simulated]\nbase_from_head = {place}\n");
        let file = Config::parse("t.toml", &text).unwrap();
        Setup::new(file, None, std::path::PathBuf::new()).unwrap()
    }

    fn goal_targets(s: &Setup) -> Targets {
        Targets::new(s, &[("goal".into(), s.file.head_from_coil().unwrap())]).unwrap()
    }

    #[test]
    fn the_default_world_reaches_its_goal_and_a_head_far_off_does_not() {
        let s = setup("[0.30, -0.12, -0.02, 0.0, 0.0, 0.3]");
        let t = goal_targets(&s);
        let place = s.file.tracker.simulated.base_from_head.iso();
        let r = t.check(&place, &s.initial_joints_at(&place).unwrap());
        assert!(r[0].refusal.is_none(), "{}", r[0]);
        assert!(t.score(&r) > 0.0);
        // 45 cm further out along x, a UR3e's reach is short of it: refused, in words.
        let far = moved(&place, Vector3::new(0.45, 0.0, 0.0), 0.0);
        let rest = s.initial_joints_at(&place).unwrap();
        let r = t.check(&far, &rest);
        assert!(r[0].refusal.is_some_and(|x| x.is_placement()), "{}", r[0]);
        assert_eq!(t.score(&r), 0.0);
        assert!(r[0].to_string().contains("NOT REACHABLE"), "{}", r[0]);
    }

    #[test]
    fn a_search_about_an_unreachable_place_finds_one_that_reaches() {
        let s = setup("[0.62, -0.12, -0.02, 0.0, 0.0, 0.3]");
        let t = goal_targets(&s);
        let centre = s.file.tracker.simulated.base_from_head.iso();
        let rest = [0.0, -1.3, 1.6, -1.87, -1.57, 0.0];
        assert!(t.check(&centre, &rest)[0].refusal.is_some());
        let region = Region {
            half_m: [0.3, 0.1, 0.0],
            step_m: 0.1,
            yaw_half_rad: 0.0,
            yaw_step_rad: 0.1,
        };
        region.check().unwrap();
        let found = search(&t, &centre, &region, |_| Some(rest));
        assert_eq!(found.tried, 7 * 3);
        let (best, score, reaches) = found.best.expect("a placement that reaches");
        assert!(score > 0.0 && reaches[0].refusal.is_none());
        // Nearer the base than the configured place, and checked again there alike.
        assert!(best.translation.x < centre.translation.x - 0.05, "{best}");
        assert!(t.check(&best, &rest)[0].refusal.is_none());
        assert!(found.reaching >= 1 && found.reaching < found.tried);
    }

    /// The search turns placements down on their first refused target (by IK alone where it
    /// can): it finds what checking every target at every placement finds, the same best
    /// placement, score and count.
    #[test]
    fn the_search_finds_what_checking_everything_finds() {
        let s = setup("[0.62, -0.12, -0.02, 0.0, 0.0, 0.3]");
        let goals = vec![
            ("top".to_string(), s.file.head_from_coil().unwrap()),
            // Turned about its own axis: the same spot, another wrist.
            (
                "turned".to_string(),
                s.file.head_from_coil().unwrap() * Isometry3::rotation(Vector3::new(0.0, 0.0, 1.2)),
            ),
        ];
        let t = Targets::new(&s, &goals).unwrap();
        let centre = s.file.tracker.simulated.base_from_head.iso();
        let rest = [0.0, -1.3, 1.6, -1.87, -1.57, 0.0];
        let region = Region {
            half_m: [0.3, 0.2, 0.1],
            step_m: 0.1,
            yaw_half_rad: 0.6,
            yaw_step_rad: 0.3,
        };
        let found = search(&t, &centre, &region, |_| Some(rest));
        let (mut best, mut reaching) = (None::<(Isometry3<f64>, f64)>, 0);
        for place in region.candidates(&centre) {
            let score = t.score(&t.check(&place, &rest));
            if score > 0.0 {
                reaching += 1;
                if best.is_none_or(|b| score > b.1 + 1e-9) {
                    best = Some((place, score));
                }
            }
        }
        assert_eq!(found.reaching, reaching);
        assert!(
            reaching > 0 && reaching < found.tried,
            "{reaching} of {}",
            found.tried
        );
        let (place, score, reaches) = found.best.unwrap();
        assert_eq!(Some((place, score)), best);
        assert_eq!(reaches.len(), 2);
        assert_eq!(
            (reaches[0].name.as_str(), reaches[1].name.as_str()),
            ("top", "turned")
        );
    }

    #[test]
    fn a_region_too_large_or_not_a_number_is_refused_by_its_field() {
        let huge = Region {
            step_m: 0.001,
            ..Region::default()
        };
        assert!(
            huge.check()
                .unwrap_err()
                .to_string()
                .contains("larger step")
        );
        let nan = Region {
            half_m: [f64::NAN, 0.1, 0.1],
            ..Region::default()
        };
        assert!(nan.check().unwrap_err().to_string().contains("region x"));
        assert_eq!(Region::default().candidates_count(), 9 * 9 * 5 * 13);
        let c = Region::default().candidates(&Isometry3::identity());
        assert_eq!(c.len(), 9 * 9 * 5 * 13);
        // The configured place first.
        assert_eq!(c[0], Isometry3::identity());
    }
}
