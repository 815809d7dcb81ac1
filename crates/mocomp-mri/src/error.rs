//! What can be wrong with a T1 volume as a head: its file, its header, its contents. Each error
//! names the file (as the caller named it) and the header field or byte offset where there is one.

use mocomp_head::HeadError;

/// Why no scalp could be segmented from a volume.
#[derive(Debug, thiserror::Error)]
pub enum MriError {
    /// The bytes are not a NIfTI-1 file the reader can decode.
    #[error("{file}: {what}")]
    Nifti {
        /// The file.
        file: String,
        /// What the reader found.
        what: String,
        /// The reader's error.
        #[source]
        source: nifti::NiftiError,
    },
    /// A header field holds something mocomp cannot use.
    #[error("{file}: header field {field} = {value}: {why}")]
    Header {
        /// The file.
        file: String,
        /// The field, as the NIfTI-1 standard names it.
        field: &'static str,
        /// What it holds.
        value: String,
        /// Why that will not do.
        why: String,
    },
    /// The volume declares more voxels than mocomp reads (checked before anything is allocated).
    #[error("{file}: {voxels} voxels ({dims:?}), more than the {limit} a head volume may have")]
    TooLarge {
        /// The file.
        file: String,
        /// Its dimensions.
        dims: [usize; 3],
        /// Their product.
        voxels: u64,
        /// The limit.
        limit: u64,
    },
    /// The header does not state the spatial unit and none was given.
    #[error(
        "{file}: its header does not state a spatial unit (xyzt_units = {code}): give it (--units \
         mm or m; [head] units); its voxels are {voxel:.4} units across, which is {hint}"
    )]
    UnitsNeeded {
        /// The file.
        file: String,
        /// `xyzt_units` as read.
        code: u8,
        /// The largest voxel edge, in the file's units.
        voxel: f64,
        /// Which unit that makes an MRI voxel.
        hint: &'static str,
    },
    /// Nothing in the volume is a head.
    #[error("{file}: no head in the volume: {why}")]
    NoHead {
        /// The file.
        file: String,
        /// What was found instead.
        why: String,
    },
    /// The segmented surface is not a head model (its size, its shape).
    #[error(transparent)]
    Head(#[from] HeadError),
}
