//! Shared by the loop's integration tests (and the cycle benchmark).
pub mod mem;
