//! Planning the robot poses of a calibration run.
//!
//! Candidates rotate the flange about the marker's centre (so the marker stays where the tracker
//! sees it) by 15°–40° about axes spread over the sphere, with small shifts. A candidate is kept
//! when IK reaches it from the current joints on their branch, inside the joint limits, away from
//! singularities, and (when the tracker's rough pose is given) with the marker inside the tracker's
//! field of view and range and facing it. From the kept ones, a set spread over rotation space is
//! chosen and ordered to keep the moves short.

use crate::error::CalibError;
use mocomp_geom::nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use mocomp_kin::{Arm, BranchPolicy, Metric, Selection};
use std::f64::consts::PI;

/// A rough model of the tracker for visibility.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerView {
    /// Rough `base_from_tracker` (the tracker looks along its +z axis).
    pub base_from_tracker: Isometry3<f64>,
    /// Half-angle of the viewing cone about +z, radians.
    pub fov_half_angle_rad: f64,
    /// Working distance range, metres.
    pub range_m: (f64, f64),
    /// Largest angle between the marker's +z (its face normal) and the direction to the tracker.
    pub max_marker_tilt_rad: f64,
}

impl TrackerView {
    /// A tracker at `base_from_tracker` with a typical optical tracker's volume: ±30° cone, 0.5–2.4 m,
    /// marker tilt up to 60°.
    pub fn typical(base_from_tracker: Isometry3<f64>) -> Self {
        Self {
            base_from_tracker,
            fov_half_angle_rad: 30f64.to_radians(),
            range_m: (0.5, 2.4),
            max_marker_tilt_rad: 60f64.to_radians(),
        }
    }

    /// Whether a marker at `base_from_marker` is seen.
    pub fn sees(&self, base_from_marker: &Isometry3<f64>) -> bool {
        let p = base_from_marker.translation.vector;
        let in_tracker = self.base_from_tracker.inverse() * Point3::from(p);
        let d = in_tracker.coords.norm();
        if d < self.range_m.0 || d > self.range_m.1 {
            return false;
        }
        let off_axis = (in_tracker.z / d).clamp(-1.0, 1.0).acos();
        if off_axis > self.fov_half_angle_rad {
            return false;
        }
        let to_tracker = (self.base_from_tracker.translation.vector - p).normalize();
        let normal = base_from_marker.rotation * Vector3::z();
        normal.dot(&to_tracker).clamp(-1.0, 1.0).acos() <= self.max_marker_tilt_rad
    }
}

/// Options of [`plan`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanOptions {
    /// Number of poses.
    pub count: usize,
    /// Centre flange pose (`base_from_flange`).
    pub center: Isometry3<f64>,
    /// Current joints: IK stays on their branch, and the run starts here.
    pub current: [f64; 6],
    /// Rough `flange_from_marker` (rotations are about the marker's centre).
    pub flange_from_marker: Isometry3<f64>,
    /// Rotation from the centre, radians (min, max).
    pub rotation_range_rad: (f64, f64),
    /// Shifts from the centre, per axis within ±this, metres.
    pub translation_spread_m: f64,
    /// The tracker, for visibility; `None` skips the check.
    pub tracker: Option<TrackerView>,
    /// Keep this singularity margin (see `mocomp_kin::Singularity::margin`).
    pub singularity_margin: f64,
    /// Keep this far inside the joint limits, radians.
    pub limit_margin: f64,
}

impl PlanOptions {
    /// Defaults around a centre pose: 15°–40°, ±10 cm shifts (marker positions spread over the
    /// volume determine Y's rotation better than orientations alone), no tracker model, margins
    /// 0.05 and 0.1 rad.
    pub fn new(count: usize, center: Isometry3<f64>, current: [f64; 6]) -> Self {
        Self {
            count,
            center,
            current,
            flange_from_marker: Isometry3::identity(),
            rotation_range_rad: (15f64.to_radians(), 40f64.to_radians()),
            translation_spread_m: 0.10,
            tracker: None,
            singularity_margin: 0.05,
            limit_margin: 0.1,
        }
    }
}

/// The joints a plan starts from when the caller has none: the flange at `center` (the arm's
/// tool aside), on the branch nearest all-zero joints, as a robot first taught there would be.
/// Refused when the centre itself is out of reach.
pub fn start_at_center(arm: &Arm, center: &Isometry3<f64>) -> Result<[f64; 6], CalibError> {
    arm.with_tool(Isometry3::identity())
        .ik_closest(center, &[0.0; 6], &Selection::default())
        .map(|c| c.joints)
        .map_err(|e| {
            CalibError::InvalidOption(format!("the centre pose itself is not reachable: {e}"))
        })
}

/// One planned pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedPose {
    /// Flange pose to move to.
    pub base_from_flange: Isometry3<f64>,
    /// Joints to move to (on the current branch, continuous from the previous pose).
    pub joints: [f64; 6],
    /// Rotation from the centre pose, radians.
    pub rotation_rad: f64,
}

/// Golden-ratio based low-discrepancy numbers in [0, 1).
fn r1(i: usize, g: f64) -> f64 {
    (0.5 + g * i as f64).fract()
}

/// Plans `options.count` calibration poses. Fails with counts of why candidates were rejected when
/// not enough remain.
pub fn plan(arm: &Arm, options: &PlanOptions) -> Result<Vec<PlannedPose>, CalibError> {
    let (lo, hi) = options.rotation_range_rad;
    if options.count < 3 {
        return Err(CalibError::InvalidOption(format!(
            "plan at least 3 poses (asked for {})",
            options.count
        )));
    }
    if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi >= lo && hi < PI) {
        return Err(CalibError::InvalidOption(format!(
            "rotation range [{lo}, {hi}] rad must satisfy 0 < min ≤ max < π"
        )));
    }
    let flange_arm = arm.with_tool(Isometry3::identity());
    let selection = Selection {
        metric: Metric::TimeToReach,
        branch: BranchPolicy::KeepCurrent,
        limit_margin: options.limit_margin,
    };
    let x = options.flange_from_marker;
    let candidates = 12 * options.count + 24;
    let golden = (5f64.sqrt() - 1.0) / 2.0;
    let (mut unreachable, mut near_singular, mut not_visible) = (0, 0, 0);
    let mut valid: Vec<PlannedPose> = Vec::new();
    for i in 0..candidates {
        // Fibonacci sphere axis, golden-ratio angle and shifts.
        let zc = 1.0 - 2.0 * (i as f64 + 0.5) / candidates as f64;
        let ring = (1.0 - zc * zc).sqrt();
        let phi = 2.0 * PI * r1(i, golden);
        let axis = Unit::new_normalize(Vector3::new(ring * phi.cos(), ring * phi.sin(), zc));
        let angle = lo + (hi - lo) * r1(i, 0.754_877_666_246_692_7);
        let s = options.translation_spread_m;
        let shift = Vector3::new(
            s * (2.0 * r1(i, 0.569_840_290_998_053_3) - 1.0),
            s * (2.0 * r1(i, 0.438_579_939_474_401) - 1.0),
            s * (2.0 * r1(i, 0.337_003_175_575_389_4) - 1.0),
        );
        let turn = Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&axis, angle),
        );
        let mut pose = options.center * x * turn * x.inverse();
        pose.translation.vector += shift;
        if let Some(view) = &options.tracker
            && !view.sees(&(pose * x))
        {
            not_visible += 1;
            continue;
        }
        let Ok(choice) = flange_arm.ik_closest(&pose, &options.current, &selection) else {
            unreachable += 1;
            continue;
        };
        if flange_arm
            .singularity(&choice.joints)
            .margin(flange_arm.geometry())
            < options.singularity_margin
        {
            near_singular += 1;
            continue;
        }
        valid.push(PlannedPose {
            base_from_flange: pose,
            joints: choice.joints,
            rotation_rad: angle,
        });
    }
    if valid.len() < options.count {
        return Err(CalibError::PlanShort {
            found: valid.len(),
            wanted: options.count,
            unreachable,
            near_singular,
            not_visible,
        });
    }
    // Spread: farthest-point selection in rotation space, starting from the largest rotation.
    let mut chosen: Vec<usize> = Vec::with_capacity(options.count);
    let first = (0..valid.len())
        .max_by(|&a, &b| valid[a].rotation_rad.total_cmp(&valid[b].rotation_rad))
        .unwrap_or(0);
    chosen.push(first);
    let mut nearest = vec![f64::INFINITY; valid.len()];
    while chosen.len() < options.count {
        let last = &valid[chosen[chosen.len() - 1]].base_from_flange;
        let mut best = None;
        let mut best_d = -1.0;
        for (k, v) in valid.iter().enumerate() {
            let d = v.base_from_flange.rotation.angle_to(&last.rotation);
            nearest[k] = nearest[k].min(d);
            if !chosen.contains(&k) && nearest[k] > best_d {
                best_d = nearest[k];
                best = Some(k);
            }
        }
        match best {
            Some(k) => chosen.push(k),
            None => break,
        }
    }
    let mut poses: Vec<PlannedPose> = chosen.iter().map(|&k| valid[k]).collect();
    order_short(arm, &mut poses, &options.current);
    // Joints continuous along the tour.
    let mut from = options.current;
    for p in &mut poses {
        if let Ok(c) = flange_arm.ik_closest(&p.base_from_flange, &from, &selection) {
            p.joints = c.joints;
        }
        from = p.joints;
    }
    Ok(poses)
}

/// Time for the slowest joint to move from `a` to `b` at full speed.
fn move_time(arm: &Arm, a: &[f64; 6], b: &[f64; 6]) -> f64 {
    let v = &arm.spec().max_speed;
    (0..6)
        .map(|j| (a[j] - b[j]).abs() / v[j])
        .fold(0.0, f64::max)
}

/// Total time of the tour from `start` through `poses`.
pub fn tour_time(arm: &Arm, start: &[f64; 6], poses: &[PlannedPose]) -> f64 {
    let mut t = 0.0;
    let mut from = start;
    for p in poses {
        t += move_time(arm, from, &p.joints);
        from = &p.joints;
    }
    t
}

/// Nearest neighbour from `start`, then 2-opt passes while they shorten the tour.
fn order_short(arm: &Arm, poses: &mut [PlannedPose], start: &[f64; 6]) {
    let n = poses.len();
    let mut from = *start;
    for i in 0..n {
        let k = (i..n)
            .min_by(|&a, &b| {
                move_time(arm, &from, &poses[a].joints).total_cmp(&move_time(
                    arm,
                    &from,
                    &poses[b].joints,
                ))
            })
            .unwrap_or(i);
        poses.swap(i, k);
        from = poses[i].joints;
    }
    // 2-opt: reverse a segment when that shortens the open tour.
    for _ in 0..20 {
        let mut improved = false;
        for i in 0..n.saturating_sub(1) {
            for j in i + 1..n {
                let before = if i == 0 { *start } else { poses[i - 1].joints };
                let old = move_time(arm, &before, &poses[i].joints)
                    + if j + 1 < n {
                        move_time(arm, &poses[j].joints, &poses[j + 1].joints)
                    } else {
                        0.0
                    };
                let new = move_time(arm, &before, &poses[j].joints)
                    + if j + 1 < n {
                        move_time(arm, &poses[i].joints, &poses[j + 1].joints)
                    } else {
                        0.0
                    };
                if new + 1e-12 < old {
                    poses[i..=j].reverse();
                    improved = true;
                }
            }
        }
        if !improved {
            break;
        }
    }
}
