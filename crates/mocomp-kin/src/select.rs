//! Choosing one IK solution: the `±2π` variant of each joint nearest the current joints, ranked by
//! a weighted joint distance, optionally kept on a branch, within joint-limit margins.

use crate::arm::Arm;
use crate::branch::Branch;
use crate::error::KinError;
use crate::ik::{BranchCoordinates, Solutions};
use mocomp_geom::nalgebra::Isometry3;

/// How the distance from the current joints to a candidate is measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Metric {
    /// `max_j |Δq_j| / v_max_j`: the time the slowest joint needs at full speed (ties broken by
    /// the sum of those times). Suits tracking.
    TimeToReach,
    /// `Σ_j w_j |Δq_j|`; weights of 1 give the seed paper's "minimal angle sum".
    WeightedSum([f64; 6]),
}

/// Which branches a choice may use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BranchPolicy {
    /// Any branch.
    Any,
    /// Only the given branch.
    Only(Branch),
    /// Only the branch the current joints are on: never jump branches while tracking. A branch
    /// coordinate within [`SINGULAR_LABEL_EPS`] of zero (the current joints at a singularity) does
    /// not restrict that label.
    KeepCurrent,
}

/// A branch coordinate this close to zero (metres for the shoulder, sine for elbow and wrist) is
/// at a singularity, where the branch label on that axis is not defined.
pub const SINGULAR_LABEL_EPS: f64 = 1e-9;

/// Options for [`Arm::choose`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Selection {
    /// Distance measure.
    pub metric: Metric,
    /// Branch restriction.
    pub branch: BranchPolicy,
    /// Keep this far (radians) inside every joint limit.
    pub limit_margin: f64,
}

impl Default for Selection {
    /// Time to reach, any branch, no margin.
    fn default() -> Self {
        Self {
            metric: Metric::TimeToReach,
            branch: BranchPolicy::Any,
            limit_margin: 0.0,
        }
    }
}

impl Selection {
    /// The tracking preset: time to reach, keep the current branch, with a limit margin.
    pub fn tracking(limit_margin: f64) -> Self {
        Self {
            metric: Metric::TimeToReach,
            branch: BranchPolicy::KeepCurrent,
            limit_margin,
        }
    }
}

/// The chosen configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Choice {
    /// Joint angles to command (the `±2π` variant nearest the current joints).
    pub joints: [f64; 6],
    /// Its branch.
    pub branch: Branch,
    /// Index of the solution in the [`Solutions`] it was chosen from.
    pub index: usize,
    /// Its cost under the metric.
    pub cost: f64,
}

impl Arm {
    /// Chooses among `solutions` the one to move to from `current`.
    ///
    /// Per joint, the variant `q + 2πk` nearest the current value within the limits (minus the
    /// margin) is taken; that is optimal for any per-joint distance. Fails with
    /// [`KinError::BranchUnavailable`] when the branch policy excludes every solution, and
    /// [`KinError::OutsideJointLimits`] when the margins exclude them.
    pub fn choose(
        &self,
        solutions: &Solutions,
        current: &[f64; 6],
        selection: &Selection,
    ) -> Result<Choice, KinError> {
        let wanted = match selection.branch {
            BranchPolicy::Any => None,
            BranchPolicy::Only(b) => Some((b, [false; 3])),
            BranchPolicy::KeepCurrent => {
                let c = BranchCoordinates::of(self.geometry(), current);
                let free = [
                    c.rho_m.abs() < SINGULAR_LABEL_EPS,
                    c.sin_q3.abs() < SINGULAR_LABEL_EPS,
                    c.sin_q5.abs() < SINGULAR_LABEL_EPS,
                ];
                Some((c.branch(), free))
            }
        };
        let limits = self.limits();
        let speed = &self.spec().max_speed;
        let mut best: Option<(Choice, f64)> = None;
        let mut on_branch = 0usize;
        for (index, s) in solutions.iter().enumerate() {
            if let Some((b, free)) = wanted {
                let matches = (free[0] || s.branch.shoulder == b.shoulder)
                    && (free[1] || s.branch.elbow == b.elbow)
                    && (free[2] || s.branch.wrist == b.wrist);
                if !matches {
                    continue;
                }
            }
            on_branch += 1;
            let mut joints = [0.0; 6];
            let mut feasible = true;
            for j in 0..6 {
                match limits.nearest_variant(j, s.joints[j], current[j], selection.limit_margin) {
                    Some(v) => joints[j] = v,
                    None => {
                        feasible = false;
                        break;
                    }
                }
            }
            if !feasible {
                continue;
            }
            let (cost, tie) = match selection.metric {
                Metric::TimeToReach => {
                    let mut max = 0.0f64;
                    let mut sum = 0.0;
                    for j in 0..6 {
                        let t = (joints[j] - current[j]).abs() / speed[j];
                        max = max.max(t);
                        sum += t;
                    }
                    (max, sum)
                }
                Metric::WeightedSum(w) => {
                    let sum: f64 = (0..6).map(|j| w[j] * (joints[j] - current[j]).abs()).sum();
                    (sum, 0.0)
                }
            };
            let better = best
                .as_ref()
                .is_none_or(|(b, btie)| cost < b.cost || (cost == b.cost && tie < *btie));
            if better {
                best = Some((
                    Choice {
                        joints,
                        branch: s.branch,
                        index,
                        cost,
                    },
                    tie,
                ));
            }
        }
        match best {
            Some((c, _)) => Ok(c),
            None if on_branch == 0 => match wanted {
                Some((branch, _)) => Err(KinError::BranchUnavailable { branch }),
                None => Err(KinError::OutsideJointLimits { solutions: 0 }),
            },
            None => Err(KinError::OutsideJointLimits {
                solutions: solutions.len(),
            }),
        }
    }

    /// IK and choice in one call: the solution for `base_from_tool` to move to from `current`
    /// (whose `q6` also decides a wrist singularity).
    pub fn ik_closest(
        &self,
        base_from_tool: &Isometry3<f64>,
        current: &[f64; 6],
        selection: &Selection,
    ) -> Result<Choice, KinError> {
        let sols = self.ik(base_from_tool, current[5])?;
        self.choose(&sols, current, selection)
    }
}
