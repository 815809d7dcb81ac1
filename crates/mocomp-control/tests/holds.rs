//! A hold never locks itself in: a command that does not move is never refused by the collision
//! check, wherever the arm is (the coil deep in the head model included), so the loop can always
//! stay where it is. The check compares the command with the previous one; both must come from
//! the same computation to the last bit.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

mod common;
use common::mem::{World, coil_on_head_joints};
use mocomp_kin::{Arm, Model};
use mocomp_testkit::SplitMix64;
use mocomp_testkit::scene::head_rest;

#[test]
fn standing_still_is_never_a_collision() {
    let w = World::new();
    let q0 = coil_on_head_joints(&Arm::new(Model::Ur3e));
    let head = head_rest();
    let mut rng = SplitMix64(15);
    for _ in 0..3000 {
        // Around the coil on the head: up to ±0.3 rad per joint puts the coil and the links into
        // the head model as often as not.
        let q: [f64; 6] = std::array::from_fn(|j| q0[j] + 0.6 * (rng.next_f64() - 0.5));
        assert_eq!(w.comp.collision(&q, &q, &head, &head), None, "{q:?}");
    }
}
