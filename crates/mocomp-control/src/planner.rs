//! Safe paths to a goal near the head: retreat along the coil's axis to a shell around the head,
//! travel on the shell, approach the goal along its axis.
//!
//! The shell is the head's farthest reach from its centre along each direction
//! ([`mocomp_head::HeadShape::radius_along`]) plus a margin, so around a scalp it passes outside
//! the ears and the nose, not through them.
//!
//! A [`ShellPath`] lives in the head frame (`head_from_coil` poses), so it moves with the head:
//! the loop maps it through the newest predicted head pose every cycle, which replans it
//! continuously for head motion. It is parametrised by arc length σ (m; rotation counts as
//! [`ROTATION_LENGTH_M`] metres per radian so that pure turns take time too). Pure geometry: no
//! allocation, no I/O; the loop checks reachability and collisions on it before it starts.

use crate::geometry::HeadModel;
use mocomp_geom::interp::slerp;
use mocomp_geom::nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use mocomp_head::HeadShape;

/// How many metres of path one radian of coil rotation counts as.
pub const ROTATION_LENGTH_M: f64 = 0.1;

/// Samples per shell segment used for its length.
const SHELL_SAMPLES: usize = 16;

/// Why a path cannot be built.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// The goal lies within the shell distance of the head along its own axis in a way that
    /// leaves no room for the approach (the goal's axis points out of the head).
    #[error("the goal's approach axis does not point into the head")]
    AxisOutward,
    /// The coil could not retreat to the shell (m reached).
    #[error("no retreat to the shell within {0:.3} m")]
    NoRetreat(f64),
}

/// Retreat, shell travel and approach, in the head frame, around the head it was planned for
/// (which each pose query is given again: the path holds no copy of a scalp).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShellPath {
    /// The head's centre the shell is built around.
    centre: Point3<f64>,
    start: Isometry3<f64>,
    retreat: Isometry3<f64>,
    pre: Isometry3<f64>,
    goal: Isometry3<f64>,
    /// Radial excess over the head's reach at the retreat point and at the pre-approach point, m.
    excess: (f64, f64),
    /// Segment lengths: retreat, shell, approach (m of path).
    lengths: [f64; 3],
}

/// Spherical interpolation of unit vectors (a perpendicular detour when they are opposite).
fn slerp_dir(a: &Vector3<f64>, b: &Vector3<f64>, t: f64) -> Vector3<f64> {
    let cos = a.dot(b).clamp(-1.0, 1.0);
    let angle = cos.acos();
    if angle < 1e-9 {
        return *a;
    }
    let axis = a.cross(b);
    let axis = if axis.norm() < 1e-9 {
        // Opposite: go over any perpendicular.
        let p = if a.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        a.cross(&p).normalize()
    } else {
        axis.normalize()
    };
    UnitQuaternion::from_scaled_axis(axis * (angle * t)) * a
}

impl ShellPath {
    /// A path from the coil at `start` to `goal` (both `head_from_coil`, +z of the coil points
    /// into the head) for the head model `head`, keeping `shell_m` from the head while
    /// travelling.
    pub fn plan(
        head: &HeadModel,
        start: &Isometry3<f64>,
        goal: &Isometry3<f64>,
        shell_m: f64,
    ) -> Result<Self, PlanError> {
        let axis_of = |p: &Isometry3<f64>| p.rotation * Vector3::z();
        let centre_dist = |p: &Vector3<f64>| head.distance(&Point3::from(*p));
        // Pre-approach: back along the goal's axis until the shell.
        let goal_axis = axis_of(goal);
        let goal_p = goal.translation.vector;
        // The one axis rule (crate::goal), so the planner and the goal check agree on the edge.
        if !crate::goal::axis_points_into_head(head, goal) {
            return Err(PlanError::AxisOutward);
        }
        let mut pre_p = goal_p;
        let mut step = 0.0;
        while centre_dist(&pre_p) < shell_m && step < 0.5 {
            step += 0.002;
            pre_p = goal_p - goal_axis * step;
        }
        let pre = Isometry3::from_parts(Translation3::from(pre_p), goal.rotation);
        // Retreat: along the coil's own axis (backwards) if that leaves the head, else radially.
        let start_p = start.translation.vector;
        let retreat_p = if centre_dist(&start_p) >= shell_m {
            start_p
        } else {
            let back = -axis_of(start);
            let radial_out = {
                let v = start_p - head.shape().centre().coords;
                if v.norm() > 1e-9 {
                    v.normalize()
                } else {
                    Vector3::z()
                }
            };
            let dir = if centre_dist(&(start_p + back * 1e-3)) > centre_dist(&start_p) {
                back
            } else {
                radial_out
            };
            let mut p = start_p;
            let mut s = 0.0;
            while centre_dist(&p) < shell_m {
                s += 0.002;
                if s > 0.3 {
                    return Err(PlanError::NoRetreat(s));
                }
                p = start_p + dir * s;
            }
            p
        };
        let retreat = Isometry3::from_parts(Translation3::from(retreat_p), start.rotation);
        let mut path = Self {
            centre: head.shape().centre(),
            start: *start,
            retreat,
            pre,
            goal: *goal,
            excess: (0.0, 0.0),
            lengths: [0.0; 3],
        };
        path.excess = (
            path.radial_excess(head, &retreat_p),
            path.radial_excess(head, &pre.translation.vector),
        );
        path.lengths[0] = (retreat_p - start_p).norm();
        path.lengths[2] = (goal_p - pre_p).norm();
        let mut shell = 0.0;
        let mut prev = path.shell_at(head, 0.0);
        for k in 1..=SHELL_SAMPLES {
            let next = path.shell_at(head, k as f64 / SHELL_SAMPLES as f64);
            shell += (next.translation.vector - prev.translation.vector).norm();
            prev = next;
        }
        let turn = retreat.rotation.angle_to(&goal.rotation) * ROTATION_LENGTH_M;
        path.lengths[1] = shell.max(turn);
        Ok(path)
    }

    /// Where the path starts (`head_from_coil`).
    pub fn start(&self) -> &Isometry3<f64> {
        &self.start
    }

    /// The path's length, m.
    pub fn length(&self) -> f64 {
        self.lengths.iter().sum()
    }

    /// Where the retreat ends (on the shell), `head_from_coil`.
    pub fn retreat_end(&self) -> Isometry3<f64> {
        self.retreat
    }

    /// Where the approach starts (on the goal's axis, at the shell), `head_from_coil`.
    pub fn approach_start(&self) -> Isometry3<f64> {
        self.pre
    }

    fn radial_excess(&self, head: &HeadModel, p_head: &Vector3<f64>) -> f64 {
        let p = p_head - self.centre.coords;
        let n = p.norm();
        if n < 1e-12 {
            return 0.0;
        }
        n - head.shape().radius_along(&(p / n))
    }

    /// The shell segment at u ∈ [0, 1]: the direction from the head's centre turns on a great
    /// circle, the radial excess over the head's reach goes linearly from the retreat point's to
    /// the pre-approach point's, the orientation slerps.
    fn shell_at(&self, head: &HeadModel, u: f64) -> Isometry3<f64> {
        let c = self.centre.coords;
        let a = self.retreat.translation.vector - c;
        let b = self.pre.translation.vector - c;
        let (na, nb) = (a.norm().max(1e-12), b.norm().max(1e-12));
        let d = slerp_dir(&(a / na), &(b / nb), u);
        let excess = self.excess.0 + (self.excess.1 - self.excess.0) * u;
        let p = c + d * (head.shape().radius_along(&d) + excess);
        Isometry3::from_parts(
            Translation3::from(p),
            slerp(&self.retreat.rotation, &self.goal.rotation, u),
        )
    }

    /// The pose at arc length `sigma` (clamped to the path), `head_from_coil`, around `head`
    /// (the one it was planned for).
    pub fn pose_at(&self, head: &HeadModel, sigma: f64) -> Isometry3<f64> {
        let [l0, l1, l2] = self.lengths;
        let s = sigma.clamp(0.0, self.length());
        let lerp = |a: &Isometry3<f64>, b: &Isometry3<f64>, u: f64| {
            Isometry3::from_parts(
                Translation3::from(a.translation.vector.lerp(&b.translation.vector, u)),
                a.rotation,
            )
        };
        if s < l0 {
            lerp(&self.start, &self.retreat, s / l0)
        } else if s < l0 + l1 {
            self.shell_at(head, (s - l0) / l1)
        } else if l2 > 0.0 {
            lerp(&self.pre, &self.goal, ((s - l0 - l1) / l2).min(1.0))
        } else {
            self.goal
        }
    }

    /// Which segment σ is on: 0 retreat, 1 shell, 2 approach.
    pub fn segment(&self, sigma: f64) -> usize {
        let [l0, l1, _] = self.lengths;
        if sigma < l0 {
            0
        } else if sigma < l0 + l1 {
            1
        } else {
            2
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn head() -> HeadModel {
        HeadModel::adult()
    }

    /// A coil pose at `p` (head frame) with its +z pointing at the head's centre.
    fn facing(p: Vector3<f64>) -> Isometry3<f64> {
        let z = -p.normalize();
        let rot = UnitQuaternion::rotation_between(&Vector3::z(), &z).unwrap_or_else(|| {
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        });
        Isometry3::from_parts(Translation3::from(p), rot)
    }

    #[test]
    fn a_path_retreats_travels_on_the_shell_and_approaches_on_the_axis() {
        let h = head();
        // From the left side, 3 mm off the scalp, to the top, 3 mm off.
        let start = facing(Vector3::new(0.078, 0.0, 0.0));
        let goal = facing(Vector3::new(0.0, 0.0, 0.113));
        let p = ShellPath::plan(&h, &start, &goal, 0.05).unwrap();
        assert!((p.pose_at(&h, 0.0).translation.vector - start.translation.vector).norm() < 1e-12);
        let end = p.pose_at(&h, p.length());
        assert!((end.translation.vector - goal.translation.vector).norm() < 1e-12);
        assert!(end.rotation.angle_to(&goal.rotation) < 1e-9);
        // The retreat is along the start's axis, the approach along the goal's.
        let r = p.retreat_end().translation.vector - start.translation.vector;
        assert!(r.normalize().dot(&-(start.rotation * Vector3::z())) > 0.999_999);
        let a = goal.translation.vector - p.approach_start().translation.vector;
        assert!(a.normalize().dot(&(goal.rotation * Vector3::z())) > 0.999_999);
        // Everywhere: outside the head; on the shell segment: at least near the shell.
        let n = 400;
        let mut prev = p.pose_at(&h, 0.0);
        for k in 0..=n {
            let s = p.length() * k as f64 / n as f64;
            let q = p.pose_at(&h, s);
            let d = h.distance(&Point3::from(q.translation.vector));
            assert!(d > 0.002, "σ {s}: {d}");
            if p.segment(s) == 1 {
                assert!(d > 0.04, "σ {s}: {d}");
            }
            // Continuous: no jumps between neighbouring samples.
            let step = (q.translation.vector - prev.translation.vector).norm();
            assert!(step < 3.0 * p.length() / n as f64, "σ {s}: {step}");
            prev = q;
        }
    }

    #[test]
    fn a_start_outside_the_shell_does_not_retreat_and_opposite_sides_are_joined() {
        let h = head();
        let start = facing(Vector3::new(-0.3, 0.0, 0.0));
        let goal = facing(Vector3::new(0.078, 0.0, 0.0));
        let p = ShellPath::plan(&h, &start, &goal, 0.05).unwrap();
        assert_eq!(p.retreat_end(), start);
        for k in 0..=200 {
            let s = p.length() * f64::from(k) / 200.0;
            let q = p.pose_at(&h, s).translation.vector;
            assert!(h.distance(&Point3::from(q)) > 0.002);
        }
    }

    #[test]
    fn a_goal_whose_axis_points_away_is_refused() {
        let h = head();
        let mut goal = facing(Vector3::new(0.0, 0.0, 0.113));
        goal.rotation = UnitQuaternion::identity(); // +z up, out of the head
        let start = facing(Vector3::new(0.0, 0.2, 0.1));
        assert_eq!(
            ShellPath::plan(&h, &start, &goal, 0.05),
            Err(PlanError::AxisOutward)
        );
    }
}
