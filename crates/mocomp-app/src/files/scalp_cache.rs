//! Scalps segmented from a T1, kept (see [`crate::files::cache`]) so that each command on the same
//! image does not segment it again (seconds for a 1 mm head): the mended surface and where the
//! scan ends inside the head, bit for bit as segmented, under a key made of the image's bytes
//! and everything that shapes its scalp (the unit it is read in, the threshold, the triangle
//! budget, the smoothing, and [`mocomp_mri::SCALP_REVISION`] for the code itself). The counts are
//! checked against the content's length before anything is allocated for them.

use crate::files::cache::{Kind, Reader, Refused, refused};
use mocomp_geom::LengthUnit;
use mocomp_geom::nalgebra::{Point3, Unit, Vector3};
use mocomp_head::{Mesh, ScanCut};
use mocomp_mri::SegmentOptions;
use sha2::{Digest, Sha256};
use std::path::Path;

/// Kept scalps: a few megabytes each.
pub const KIND: Kind = Kind {
    folder: "scalps",
    ext: "scalp",
    magic: b"mocomp scalp  1\n",
    keep: 16,
    max_bytes: 12 + MAX_COUNT * 36 + 6 * CUT as u64 + crate::files::cache::HEADER as u64 + 32,
};
/// The most vertices or triangles a kept scalp may claim (a segmented scalp has 100 k
/// triangles unless asked for more; ten million is far beyond what a head needs).
const MAX_COUNT: u64 = 10_000_000;
/// The sides a scan's cut can face, in the order their byte counts them.
const SIDES: [&str; 6] = [
    "left",
    "right",
    "posterior",
    "anterior",
    "inferior",
    "superior",
];
/// Bytes of a cut: its side, then centre, outward and along (3 f64 each) and its half sides.
const CUT: usize = 1 + 11 * 8;

/// A scalp as kept: the mended surface (the image's frame, metres) and where the scan cut it.
#[derive(Debug, Clone, PartialEq)]
pub struct Scalp {
    /// The mended surface.
    pub mesh: Mesh,
    /// Where the scan ends inside the head (image frame).
    pub cuts: Vec<ScanCut>,
}

/// The key for the scalp of the image `bytes` read in `unit` and segmented as `options` say.
pub fn key(bytes: &[u8], unit: Option<LengthUnit>, options: &SegmentOptions) -> [u8; 32] {
    let mut h = Sha256::new();
    h.update(KIND.magic);
    h.update(mocomp_mri::SCALP_REVISION.to_le_bytes());
    h.update([match unit {
        None => 0u8,
        Some(LengthUnit::Metre) => 1,
        Some(LengthUnit::Millimetre) => 2,
    }]);
    match options.threshold {
        None => h.update([0u8]),
        Some(t) => {
            h.update([1u8]);
            h.update(t.to_bits().to_le_bytes());
        }
    }
    h.update((options.max_triangles as u64).to_le_bytes());
    h.update((options.smoothing_passes as u64).to_le_bytes());
    h.update((bytes.len() as u64).to_le_bytes());
    h.update(bytes);
    h.finalize().into()
}

/// The scalp kept under `key` under the cache's `root`, if one is there whole.
pub fn load(root: &Path, key: &[u8; 32]) -> Option<Scalp> {
    decode(&crate::files::cache::load(&KIND, root, key)?).ok()
}

/// Keeps `scalp` under `key` under the cache's `root`.
pub fn store(root: &Path, key: &[u8; 32], scalp: &Scalp) -> Result<(), crate::AppError> {
    crate::files::cache::store(&KIND, root, key, &encode(scalp))
}

fn f64s(out: &mut Vec<u8>, xs: &[f64]) {
    for x in xs {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

/// The content `scalp` is kept as.
pub fn encode(scalp: &Scalp) -> Vec<u8> {
    let (v, t) = (&scalp.mesh.vertices, &scalp.mesh.triangles);
    let mut out = Vec::with_capacity(12 + v.len() * 24 + t.len() * 12 + scalp.cuts.len() * CUT);
    for n in [v.len(), t.len(), scalp.cuts.len()] {
        out.extend_from_slice(&u32::try_from(n).unwrap_or(u32::MAX).to_le_bytes());
    }
    for p in v {
        f64s(&mut out, &[p.x, p.y, p.z]);
    }
    for tri in t {
        for i in tri {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
    for c in &scalp.cuts {
        out.push(SIDES.iter().position(|s| *s == c.side).unwrap_or(0) as u8);
        f64s(&mut out, c.centre.coords.as_slice());
        f64s(&mut out, c.outward.as_slice());
        f64s(&mut out, c.along.as_slice());
        f64s(&mut out, &c.half_m);
    }
    out
}

fn vector(r: &mut Reader<'_>, what: &str) -> Result<Vector3<f64>, Refused> {
    Ok(Vector3::new(r.f64(what)?, r.f64(what)?, r.f64(what)?))
}

fn unit(r: &mut Reader<'_>, what: &str) -> Result<Unit<Vector3<f64>>, Refused> {
    let at = r.offset();
    let v = vector(r, what)?;
    if (v.norm() - 1.0).abs() > 1e-9 {
        return Err(refused(at, format!("{what} is not a unit vector")));
    }
    Ok(Unit::new_unchecked(v))
}

/// The scalp in `content` (an envelope's), refused by the offset of what is wrong.
pub fn decode(content: &[u8]) -> Result<Scalp, Refused> {
    let mut r = Reader::new(content);
    let counts_at = r.offset();
    let [nv, nt, nc] = [r.u32()?, r.u32()?, r.u32()?].map(u64::from);
    if nv > MAX_COUNT || nt > MAX_COUNT || nc > SIDES.len() as u64 {
        return Err(refused(
            counts_at,
            format!("{nv} vertices, {nt} triangles, {nc} cuts: more than a scalp has"),
        ));
    }
    // Counts of at most ten million: the products fit.
    let expected = 12 + nv * 24 + nt * 12 + nc * CUT as u64;
    if expected != content.len() as u64 {
        return Err(refused(
            counts_at,
            format!(
                "its counts make {expected} bytes, the content is {}",
                content.len()
            ),
        ));
    }
    let (nv, nt, nc) = (nv as usize, nt as usize, nc as usize);
    let mut vertices = Vec::with_capacity(nv);
    for _ in 0..nv {
        vertices.push(Point3::from(vector(&mut r, "a vertex")?));
    }
    let mut triangles = Vec::with_capacity(nt);
    for _ in 0..nt {
        let at = r.offset();
        let tri = [r.u32()?, r.u32()?, r.u32()?];
        if tri.iter().any(|&i| i as usize >= nv) {
            return Err(refused(
                at,
                format!("triangle {tri:?} names a vertex past {nv}"),
            ));
        }
        triangles.push(tri);
    }
    let mut cuts = Vec::with_capacity(nc);
    for _ in 0..nc {
        let at = r.offset();
        let side = r.take(1)?[0];
        let side = *SIDES
            .get(usize::from(side))
            .ok_or_else(|| refused(at, format!("side {side} is none of the scan's six")))?;
        cuts.push(ScanCut {
            side,
            centre: Point3::from(vector(&mut r, "a cut's centre")?),
            outward: unit(&mut r, "a cut's outward normal")?,
            along: unit(&mut r, "a cut's axis")?,
            half_m: [r.f64("a cut's side")?, r.f64("a cut's side")?],
        });
    }
    Ok(Scalp {
        mesh: Mesh {
            vertices,
            triangles,
        },
        cuts,
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use crate::files::cache::HEADER;

    fn scalp() -> Scalp {
        Scalp {
            mesh: Mesh {
                vertices: vec![
                    Point3::new(0.1, 0.0, 0.0),
                    Point3::new(0.0, 0.1, 0.0),
                    Point3::new(0.0, 0.0, 0.1),
                    Point3::new(-0.1, -0.1, -0.1 / 3.0),
                ],
                triangles: vec![[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]],
            },
            cuts: vec![ScanCut {
                side: "anterior",
                centre: Point3::new(0.0, 0.09, 0.01),
                outward: Vector3::y_axis(),
                along: Vector3::x_axis(),
                half_m: [0.03, 0.02],
            }],
        }
    }

    fn options() -> SegmentOptions {
        SegmentOptions::new(None, 100_000).unwrap()
    }

    #[test]
    fn a_kept_scalp_reads_back_bit_for_bit() {
        let s = scalp();
        assert_eq!(decode(&encode(&s)).unwrap(), s);
        let dir = mocomp_testkit::TempDir::new("scalp-cache");
        let root = std::path::PathBuf::from(dir.path(""));
        let k = key(b"image", None, &options());
        store(&root, &k, &s).unwrap();
        assert_eq!(load(&root, &k), Some(s));
        assert_eq!(load(&root, &key(b"other", None, &options())), None);
    }

    #[test]
    fn the_key_changes_with_the_image_and_everything_that_shapes_its_scalp() {
        let base = key(b"image", None, &options());
        let others = [
            key(b"imagf", None, &options()),
            key(b"image", Some(LengthUnit::Millimetre), &options()),
            key(
                b"image",
                None,
                &SegmentOptions::new(Some(120.0), 100_000).unwrap(),
            ),
            key(b"image", None, &SegmentOptions::new(None, 50_000).unwrap()),
            key(
                b"image",
                None,
                &SegmentOptions {
                    smoothing_passes: 3,
                    ..options()
                },
            ),
        ];
        for (i, k) in others.iter().enumerate() {
            assert_ne!(*k, base, "option {i} left the key as it was");
        }
    }

    /// Content whose counts are forged (in a file whose checksum anyone can make right):
    /// refused for its counts before anything is allocated for them, and every truncation
    /// refused, never a panic.
    #[test]
    fn forged_counts_and_cut_content_are_refused_before_allocating() {
        let good = encode(&scalp());
        for (field, value) in [(0, u32::MAX), (1, 10_000_001), (2, 7), (0, 5), (1, 3)] {
            let mut bad = good.clone();
            bad[4 * field..4 * field + 4].copy_from_slice(&value.to_le_bytes());
            let e = decode(&bad).unwrap_err();
            assert_eq!(e.offset, HEADER, "{e}");
        }
        // A triangle naming a vertex that is not there.
        let mut bad = good.clone();
        let at = 12 + 4 * 24;
        bad[at..at + 4].copy_from_slice(&9u32.to_le_bytes());
        let e = decode(&bad).unwrap_err();
        assert_eq!(e.offset, HEADER + at, "{e}");
        assert!(e.what.contains("names a vertex"), "{e}");
        for n in 0..good.len() {
            assert!(decode(&good[..n]).is_err(), "{n} bytes read");
        }
        // A cut's side past the six, and a normal that is not a unit vector.
        let cut = 12 + 4 * 24 + 4 * 12;
        let mut bad = good.clone();
        bad[cut] = 6;
        assert!(
            decode(&bad)
                .unwrap_err()
                .what
                .contains("none of the scan's six")
        );
        let mut bad = good;
        bad[cut + 1 + 24..cut + 1 + 32].copy_from_slice(&2.0f64.to_le_bytes());
        assert!(decode(&bad).unwrap_err().what.contains("not a unit vector"));
    }
}
