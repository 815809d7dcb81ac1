//! A tracker whose clock stepped (issue 29), the loop in memory: until the client re-bases its
//! offset, every sample arrives stamped a second in the past. Such a sample says nothing about
//! the head now: it is not taken (judged as motion it would look like a 1 s jump), the newest
//! sample ages, the tracker rules hold the arm, and samples stamped right again bring the loop
//! back by a path.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

mod common;
use common::mem::{PERIOD, World};
use mocomp_control::{Event, Mode, Reason};

#[test]
fn samples_stamped_before_the_newest_are_not_taken_the_arm_holds_and_comes_back() {
    let mut w = World::new();
    let seq = w.robot.seq;
    w.tracker.stamp_offset_s = -1.0;
    let stepped = w.run(500);
    let events: Vec<_> = stepped.iter().filter_map(|(_, e)| *e).collect();
    assert!(
        !events.iter().any(|e| matches!(e, Event::Outlier(..))),
        "{events:?}"
    );
    assert!(
        events
            .iter()
            .any(|e| matches!(e, Event::Hold(Reason::TrackerStale(_)))),
        "{events:?}"
    );
    // Held within the tracker rules' time (stale 75 ms plus 150 ms of coasting) and to the end.
    let held = stepped
        .iter()
        .position(|(m, _)| matches!(m, Mode::Holding(_)))
        .unwrap();
    assert!(held as f64 * PERIOD < 0.3, "held after {held} cycles");
    assert!(
        stepped[held..]
            .iter()
            .all(|(m, _)| matches!(m, Mode::Holding(_))),
        "{stepped:?}"
    );
    assert!(w.robot.seq > seq, "commands kept coming while held");
    // Stamped right again: back, by a path, without the operator.
    w.tracker.stamp_offset_s = 0.0;
    let back = w.run(2000);
    assert!(
        back.iter().any(|(m, _)| *m == Mode::Approaching),
        "back by a path"
    );
    assert_eq!(back.last().unwrap().0, Mode::Tracking);
    assert_eq!(w.comp.latched(), None);
}
