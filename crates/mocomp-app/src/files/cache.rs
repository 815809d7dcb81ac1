//! Files kept between commands so that work done once for a head is not done again (a T1's
//! segmented scalp, a scalp's distance field): where they are kept, how many, and the envelope
//! each is written in — a magic line naming what it holds and its layout's version, the key it
//! was kept under, the content, and a SHA-256 of everything before it.
//!
//! A kept file is a cache: one that cannot be read or written is passed by (the work is done as
//! without it); one that is damaged, truncated, of another layout or kept under another key is
//! refused whole. Where: `MOCOMP_CACHE_DIR` (empty: nothing kept), else
//! `$XDG_CACHE_HOME/mocomp`, else `~/.cache/mocomp`.

use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// One kind of kept file.
#[derive(Debug, Clone, Copy)]
pub struct Kind {
    /// Its folder under the cache's root.
    pub folder: &'static str,
    /// Its files' extension.
    pub ext: &'static str,
    /// Its first 16 bytes: what it holds and its layout's version.
    pub magic: &'static [u8; 16],
    /// How many of its files are kept (the most recently stored).
    pub keep: usize,
    /// The largest file of it that is read, bytes.
    pub max_bytes: u64,
}

/// Bytes before the content: the magic and the key.
pub const HEADER: usize = 16 + 32;

/// Why a kept file was refused: where in it, and what was wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("byte {offset}: {what}")]
pub struct Refused {
    /// Where in the file.
    pub offset: usize,
    /// What was wrong there.
    pub what: String,
}

/// A [`Refused`] at `offset`.
pub fn refused(offset: usize, what: impl Into<String>) -> Refused {
    Refused {
        offset,
        what: what.into(),
    }
}

/// The cache's root folder, from the environment (see the module); `None`: nothing is kept.
pub fn root() -> Option<PathBuf> {
    match std::env::var_os("MOCOMP_CACHE_DIR") {
        Some(d) if d.is_empty() => None,
        Some(d) => Some(PathBuf::from(d)),
        None => match std::env::var_os("XDG_CACHE_HOME") {
            Some(d) if !d.is_empty() => Some(PathBuf::from(d).join("mocomp")),
            _ => Some(PathBuf::from(std::env::var_os("HOME")?).join(".cache/mocomp")),
        },
    }
}

/// Where `kind`'s file for `key` is under `root`.
pub fn file(kind: &Kind, root: &Path, key: &[u8; 32]) -> PathBuf {
    let hex: String = key.iter().map(|b| format!("{b:02x}")).collect();
    root.join(kind.folder).join(format!("{hex}.{}", kind.ext))
}

/// The content of `kind`'s file for `key` under `root`, if one is there whole.
pub fn load(kind: &Kind, root: &Path, key: &[u8; 32]) -> Option<Vec<u8>> {
    let f = std::fs::File::open(file(kind, root, key)).ok()?;
    if f.metadata().ok()?.len() > kind.max_bytes {
        return None;
    }
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(&mut std::io::Read::take(f, kind.max_bytes), &mut bytes).ok()?;
    let content = unwrap(kind, &bytes, key).ok()?.len();
    bytes.truncate(HEADER + content);
    bytes.drain(..HEADER);
    Some(bytes)
}

/// Keeps `content` as `kind`'s file for `key` under `root` (whole, or not at all), then
/// forgets all but the kind's most recently stored.
pub fn store(
    kind: &Kind,
    root: &Path,
    key: &[u8; 32],
    content: &[u8],
) -> Result<(), crate::AppError> {
    let path = file(kind, root, key);
    crate::files::whole::write_whole_making_folder(
        &path,
        &wrap(kind, key, content),
        "a kept file",
    )?;
    prune(kind, &root.join(kind.folder));
    Ok(())
}

/// `content` in its envelope.
pub fn wrap(kind: &Kind, key: &[u8; 32], content: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER + content.len() + 32);
    out.extend_from_slice(kind.magic);
    out.extend_from_slice(key);
    out.extend_from_slice(content);
    let sum: [u8; 32] = Sha256::digest(&out).into();
    out.extend_from_slice(&sum);
    out
}

/// The content in the envelope `bytes`, refused unless it is whole, of `kind` and kept under
/// `key`. The checksum first: nothing in a damaged file is believed.
pub fn unwrap<'a>(kind: &Kind, bytes: &'a [u8], key: &[u8; 32]) -> Result<&'a [u8], Refused> {
    let Some(body_len) = bytes.len().checked_sub(32).filter(|&n| n >= HEADER) else {
        return Err(refused(
            0,
            format!("{} bytes, shorter than an empty one", bytes.len()),
        ));
    };
    let (body, sum) = bytes.split_at(body_len);
    if Sha256::digest(body).as_slice() != sum {
        return Err(refused(body_len, "the checksum does not match the content"));
    }
    if &body[..16] != kind.magic {
        return Err(refused(0, "not a file of this kind and version"));
    }
    if &body[16..HEADER] != key {
        return Err(refused(16, "kept under another key"));
    }
    Ok(&body[HEADER..])
}

/// Removes all but the `kind.keep` newest files in `folder` (what cannot be removed stays).
fn prune(kind: &Kind, folder: &Path) {
    let Ok(entries) = std::fs::read_dir(folder) else {
        return;
    };
    let mut kept: Vec<(std::time::SystemTime, PathBuf)> = entries
        .filter_map(Result::ok)
        .filter(|e| e.path().extension().is_some_and(|x| x == kind.ext))
        .filter_map(|e| Some((e.metadata().ok()?.modified().ok()?, e.path())))
        .collect();
    kept.sort_by_key(|k| std::cmp::Reverse(k.0));
    for (_, old) in kept.iter().skip(kind.keep) {
        std::fs::remove_file(old).ok();
    }
}

/// Reads a kept file's content, never past its end, naming the offset in the file of what it
/// could not read.
#[derive(Debug)]
pub struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    /// A reader of `content` (the envelope's, which begins [`HEADER`] bytes into the file).
    pub fn new(content: &'a [u8]) -> Self {
        Self {
            bytes: content,
            at: 0,
        }
    }

    /// Where it is, as an offset in the file.
    pub fn offset(&self) -> usize {
        HEADER + self.at
    }

    /// Bytes left.
    pub fn left(&self) -> usize {
        self.bytes.len() - self.at
    }

    /// The next `n` bytes.
    pub fn take(&mut self, n: usize) -> Result<&'a [u8], Refused> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(refused(self.offset(), format!("{n} bytes past the end")));
        };
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    /// The next little-endian u32.
    pub fn u32(&mut self) -> Result<u32, Refused> {
        let mut b = [0u8; 4];
        b.copy_from_slice(self.take(4)?);
        Ok(u32::from_le_bytes(b))
    }

    /// The next little-endian u64.
    pub fn u64(&mut self) -> Result<u64, Refused> {
        let mut b = [0u8; 8];
        b.copy_from_slice(self.take(8)?);
        Ok(u64::from_le_bytes(b))
    }

    /// The next little-endian f64, refused unless finite (`what` names it).
    pub fn f64(&mut self, what: &str) -> Result<f64, Refused> {
        let at = self.offset();
        let mut b = [0u8; 8];
        b.copy_from_slice(self.take(8)?);
        let x = f64::from_le_bytes(b);
        if x.is_finite() {
            Ok(x)
        } else {
            Err(refused(at, format!("{what} is {x}")))
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    const KIND: Kind = Kind {
        folder: "things",
        ext: "thing",
        magic: b"mocomp thing  1\n",
        keep: 3,
        max_bytes: 1 << 20,
    };

    /// Every byte flipped and every truncation: refused, never a panic, never other content.
    #[test]
    fn a_damaged_truncated_or_foreign_envelope_is_refused() {
        let key = [7u8; 32];
        let good = wrap(&KIND, &key, b"content");
        assert_eq!(unwrap(&KIND, &good, &key).unwrap(), b"content");
        for i in 0..good.len() {
            let mut bad = good.clone();
            bad[i] ^= 0x20;
            assert!(unwrap(&KIND, &bad, &key).is_err(), "byte {i}");
        }
        for n in 0..good.len() {
            assert!(unwrap(&KIND, &good[..n], &key).is_err(), "{n} bytes");
        }
        assert_eq!(unwrap(&KIND, &good, &[8u8; 32]).unwrap_err().offset, 16);
        let other = Kind {
            magic: b"mocomp thing  2\n",
            ..KIND
        };
        assert_eq!(unwrap(&other, &good, &key).unwrap_err().offset, 0);
    }

    #[test]
    fn stored_files_are_found_under_their_key_and_the_oldest_forgotten() {
        let dir = mocomp_testkit::TempDir::new("cache-files");
        let root = PathBuf::from(dir.path(""));
        let keys: Vec<[u8; 32]> = (0..5u8).map(|i| [i; 32]).collect();
        for (i, k) in keys.iter().enumerate() {
            store(&KIND, &root, k, &[i as u8; 10]).unwrap();
            // Stored a second apart, whatever the machine's speed and the filesystem's clock.
            let t = std::time::UNIX_EPOCH + std::time::Duration::from_secs(1_000_000 + i as u64);
            let f = std::fs::File::options()
                .write(true)
                .open(file(&KIND, &root, k))
                .unwrap();
            f.set_modified(t).unwrap();
        }
        assert_eq!(std::fs::read_dir(root.join("things")).unwrap().count(), 3);
        assert_eq!(load(&KIND, &root, &keys[4]), Some(vec![4u8; 10]));
        assert_eq!(load(&KIND, &root, &keys[0]), None);
        let path = file(&KIND, &root, &keys[4]);
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[HEADER + 2] ^= 1;
        std::fs::write(&path, bytes).unwrap();
        assert_eq!(load(&KIND, &root, &keys[4]), None);
    }

    #[test]
    fn a_reader_names_the_offset_of_what_it_could_not_read() {
        let mut r = Reader::new(&[1, 0, 0, 0, 0, 0, 0xf8, 0x7f]);
        assert_eq!(r.u32().unwrap(), 1);
        let e = r.u64().unwrap_err();
        assert_eq!(e.offset, HEADER + 4);
        let mut r = Reader::new(&[0, 0, 0, 0, 0, 0, 0xf8, 0x7f]);
        assert_eq!(r.f64("x").unwrap_err().offset, HEADER);
    }
}
