//! Registering the patient's head to the image: the tracked pointer, the live registration
//! and its check, where its poses come from (a tracker or the rehearsal), its report
//! and the gate that weighs it where it matters.

pub mod gate;
pub mod open;
pub mod pointer;
pub mod register;
pub mod rehearsal;
pub mod report;
