//! Files the application reads and keeps: read whole under a size limit, written whole
//! through a rename, the caches that keep a head's work between commands, an affine, a head file.

pub mod affine;
pub mod cache;
pub mod capped;
pub mod field_cache;
pub mod head;
pub mod scalp_cache;
pub mod whole;
