//! What the loop's coil-clearance queries remember from one cycle to the next: each call site
//! asks about its own pose, a cycle after its last, and on a scalp the memory spares the
//! samples that cannot be the nearest (`mocomp_head::sampled::ClearanceMemory`; the answers
//! are the same). Held in a `RefCell` because the collision check that asks is a `&self`
//! query the planner also uses; nothing here allocates or blocks.

use mocomp_head::sampled::ClearanceMemory;
use std::cell::RefCell;

/// The call sites that ask every cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Site {
    /// The safety filter's clearance of the command it limits.
    Filter,
    /// The goal's own clearance, for the standoff a larger requirement asks.
    Goal,
    /// The collision check of the command.
    Collision,
    /// The commanded coil's clearance, recorded.
    Recorded,
    /// The servo setpoint's, when it leads the command.
    Setpoint,
}

/// One memory per [`Site`].
#[derive(Debug, Clone, Default)]
pub(super) struct Memories(RefCell<[ClearanceMemory; 5]>);

impl Memories {
    /// Runs `f` with `site`'s memory; with a fresh one should the memories be in use already
    /// (a query asked from inside another: never in the loop, and the same answer).
    pub(super) fn at<R>(&self, site: Site, f: impl FnOnce(&mut ClearanceMemory) -> R) -> R {
        match self.0.try_borrow_mut() {
            Ok(mut all) => f(&mut all[site as usize]),
            Err(_) => f(&mut ClearanceMemory::new()),
        }
    }
}
