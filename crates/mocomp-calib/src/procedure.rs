//! The calibration procedure, one for the live command (`calibrate collect`, on the wall clock)
//! and the experiment (in lockstep): at each planned pose, move there and wait until the
//! controller reports the move done with the arm still and on target ([`move_state`]), settle,
//! measure the marker, and keep the pair; then return to where the run started. How a move is
//! commanded, how time passes and how a marker is measured belong to the [`Station`]; what counts
//! as arrived, and the order of it all, are here.

use crate::Pair;
use crate::plan::PlannedPose;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_kin::Arm;
use mocomp_robot::RobotState;

/// A joint closer than this to its target (rad) is there.
pub const ARRIVED_RAD: f64 = 2e-3;
/// A joint slower than this (rad/s) is still.
pub const STILL_RAD_S: f64 = 2e-3;

/// Where a joint move stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MoveState {
    /// Not done yet, or the arm still moves.
    Moving,
    /// Done, still, and every joint within [`ARRIVED_RAD`] of the target.
    Arrived,
    /// Done and still, but away from the target (the move was cut short).
    Away,
}

/// How the move numbered `seq` to `target` stands in state `s`: done is the controller's word
/// (its program's completed-move counter), still and on target are checked on the joints.
pub fn move_state(s: &RobotState, target: &[f64; 6], seq: i32) -> MoveState {
    let done = s.move_done_seq.wrapping_sub(seq) >= 0;
    let still = s.actual_qd.iter().all(|v| v.abs() < STILL_RAD_S);
    if !(done && still) {
        return MoveState::Moving;
    }
    let there = s
        .actual_q
        .iter()
        .zip(target)
        .all(|(a, b)| (a - b).abs() < ARRIVED_RAD);
    if there {
        MoveState::Arrived
    } else {
        MoveState::Away
    }
}

/// One pose's measurement: the robot's joints and tracker_from_marker.
pub type Measurement = ([f64; 6], Isometry3<f64>);

/// A robot with a tracker watching its marker, as the procedure uses it.
pub trait Station {
    /// What goes wrong.
    type Error;
    /// Moves to `q` and returns once [`move_state`] says arrived.
    fn move_to(&mut self, q: &[f64; 6]) -> Result<(), Self::Error>;
    /// Lets `seconds` pass with the arm still (the controller's watchdog fed).
    fn settle(&mut self, seconds: f64) -> Result<(), Self::Error>;
    /// Averages `samples` marker samples acquired from now on, with the joints over the same
    /// time; `None` when the marker is not seen within the station's patience.
    fn measure(&mut self, samples: usize) -> Result<Option<Measurement>, Self::Error>;
}

/// What a collection measured.
#[derive(Debug, Clone, Default)]
pub struct Collection {
    /// One pair per pose where the marker was seen.
    pub pairs: Vec<Pair>,
    /// Poses (1-based) where it was not.
    pub missed: Vec<usize>,
}

/// Runs `poses` on `station` (kinematics `arm`), settling `settle_s` and averaging `samples` at
/// each, then returns to `home`. `progress` is told each pose done (0-based) and whether the
/// marker was seen there.
pub fn collect<S: Station>(
    station: &mut S,
    arm: &Arm,
    poses: &[PlannedPose],
    home: &[f64; 6],
    settle_s: f64,
    samples: usize,
    progress: &mut dyn FnMut(usize, bool),
) -> Result<Collection, S::Error> {
    let mut c = Collection::default();
    for (i, p) in poses.iter().enumerate() {
        station.move_to(&p.joints)?;
        station.settle(settle_s)?;
        let seen = match station.measure(samples)? {
            Some((q, tracker_from_marker)) => {
                let mut pair = Pair::new(arm.fk_flange(&q), tracker_from_marker);
                pair.joints = Some(q);
                c.pairs.push(pair);
                true
            }
            None => {
                c.missed.push(i + 1);
                false
            }
        };
        progress(i, seen);
    }
    station.move_to(home)?;
    Ok(c)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use mocomp_robot::Robot;
    use mocomp_testkit::mem::MemRobot;

    fn state(q: [f64; 6], qd: [f64; 6], done: i32) -> RobotState {
        let mut r = MemRobot::at(q, Isometry3::identity(), 0.008);
        r.tick(0.0);
        let mut s = r.state().unwrap();
        s.actual_qd = qd;
        s.move_done_seq = done;
        s
    }

    #[test]
    fn a_move_has_arrived_only_when_done_still_and_on_target() {
        let target = [0.1, -1.2, 1.4, -1.8, -1.6, 0.3];
        let mut near = target;
        near[2] += 0.5 * ARRIVED_RAD;
        let mut off = target;
        off[4] -= 3.0 * ARRIVED_RAD;
        let slow = [0.5 * STILL_RAD_S; 6];
        let mut moving = [0.0; 6];
        moving[0] = 2.0 * STILL_RAD_S;
        assert_eq!(
            move_state(&state(near, slow, 7), &target, 7),
            MoveState::Arrived
        );
        // Not done by the controller's count, even on target and still.
        assert_eq!(
            move_state(&state(target, [0.0; 6], 6), &target, 7),
            MoveState::Moving
        );
        // Done, but still moving.
        assert_eq!(
            move_state(&state(target, moving, 7), &target, 7),
            MoveState::Moving
        );
        // Done and still away from the target: cut short.
        assert_eq!(
            move_state(&state(off, [0.0; 6], 8), &target, 7),
            MoveState::Away
        );
        // The counter wraps.
        assert_eq!(
            move_state(&state(target, [0.0; 6], i32::MIN), &target, i32::MAX),
            MoveState::Arrived
        );
    }

    /// A station whose marker is seen everywhere but at the poses listed.
    struct Fake {
        arm: Arm,
        q: [f64; 6],
        blind_at: Vec<usize>,
        moves: Vec<[f64; 6]>,
        settled: f64,
    }

    impl Station for Fake {
        type Error = String;
        fn move_to(&mut self, q: &[f64; 6]) -> Result<(), String> {
            self.q = *q;
            self.moves.push(*q);
            Ok(())
        }
        fn settle(&mut self, s: f64) -> Result<(), String> {
            self.settled += s;
            Ok(())
        }
        fn measure(&mut self, _: usize) -> Result<Option<Measurement>, String> {
            if self.blind_at.contains(&self.moves.len()) {
                return Ok(None);
            }
            Ok(Some((self.q, self.arm.fk_flange(&self.q))))
        }
    }

    #[test]
    fn each_pose_is_moved_to_settled_and_measured_then_the_arm_goes_home() {
        let arm = Arm::new(mocomp_kin::Model::Ur3);
        let home = [0.0, -1.3, 1.6, -1.87, -1.57, 0.0];
        let poses: Vec<PlannedPose> = (0..4)
            .map(|k| {
                let mut q = home;
                q[5] += 0.1 * f64::from(k);
                PlannedPose {
                    joints: q,
                    base_from_flange: arm.fk_flange(&q),
                    rotation_rad: 0.1 * f64::from(k),
                }
            })
            .collect();
        let mut s = Fake {
            arm,
            q: home,
            blind_at: vec![3],
            moves: Vec::new(),
            settled: 0.0,
        };
        let mut told = Vec::new();
        let c = collect(&mut s, &arm, &poses, &home, 0.3, 5, &mut |i, seen| {
            told.push((i, seen));
        })
        .unwrap();
        assert_eq!(c.missed, vec![3]);
        assert_eq!(c.pairs.len(), 3);
        // The pair is the flange at the measured joints, with the joints kept.
        assert_eq!(c.pairs[1].joints, Some(poses[1].joints));
        assert_eq!(told, vec![(0, true), (1, true), (2, false), (3, true)]);
        assert_eq!(s.moves.len(), 5);
        assert_eq!(s.moves[4], home);
        assert!((s.settled - 1.2).abs() < 1e-12);
    }
}
