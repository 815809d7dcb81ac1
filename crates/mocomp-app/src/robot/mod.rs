//! Procedures on the live robot apart from the loop: the calibration collection, teaching
//! the goal, the servo streaming check.

pub mod collect;
pub mod servo_check;
pub mod teach;
