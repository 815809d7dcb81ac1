//! Files read whole under a limit: the size is checked before a byte is read and the read stops
//! one byte past the limit, so a huge file, or one that grows or never ends (a device, a pipe),
//! is refused by name instead of filling memory.

use crate::{AppError, Context};
use std::io::Read;
use std::path::Path;

/// The bytes of `path`, refused when over `limit`; `what` names the kind in the error ("a head
/// file").
pub fn read_capped(path: &Path, limit: u64, what: &str) -> Result<Vec<u8>, AppError> {
    let name = path.display().to_string();
    let file = std::fs::File::open(path).what(|| format!("{name}: cannot open"))?;
    let size = file
        .metadata()
        .what(|| format!("{name}: cannot read its size"))?
        .len();
    let too_big = |size: u64| {
        AppError::Config(format!(
            "{name}: {size} bytes, more than the {limit} {what} may have"
        ))
    };
    if size > limit {
        return Err(too_big(size));
    }
    let mut bytes = Vec::with_capacity(usize::try_from(size).unwrap_or(0));
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .what(|| format!("{name}: cannot read"))?;
    if bytes.len() as u64 > limit {
        return Err(too_big(bytes.len() as u64));
    }
    Ok(bytes)
}

/// [`read_capped`] as UTF-8 text; a byte that is not names its offset.
pub fn read_capped_text(path: &Path, limit: u64, what: &str) -> Result<String, AppError> {
    let bytes = read_capped(path, limit, what)?;
    String::from_utf8(bytes).map_err(|e| {
        AppError::Config(format!(
            "{}: not text: the byte at offset {} is not UTF-8",
            path.display(),
            e.utf8_error().valid_up_to()
        ))
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    #[test]
    fn a_file_over_its_limit_or_not_text_is_refused_by_name() {
        let dir = mocomp_testkit::TempDir::new("capped-file");
        let path = std::path::PathBuf::from(dir.path("f.txt"));
        std::fs::write(&path, b"0123456789").unwrap();
        assert_eq!(read_capped(&path, 10, "a file").unwrap().len(), 10);
        let e = read_capped(&path, 9, "a coil file")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("f.txt: 10 bytes, more than the 9 a coil file may have"),
            "{e}"
        );
        std::fs::write(&path, b"ab\xffcd").unwrap();
        let e = read_capped_text(&path, 10, "a file")
            .unwrap_err()
            .to_string();
        assert!(e.contains("offset 2"), "{e}");
        let e = read_capped(Path::new(&dir.path("none")), 10, "a file")
            .unwrap_err()
            .to_string();
        assert!(e.contains("none: cannot open"), "{e}");
        // A device that never ends stops one byte past the limit.
        let e = read_capped(Path::new("/dev/zero"), 1000, "a file")
            .unwrap_err()
            .to_string();
        assert!(e.contains("1001 bytes, more than the 1000"), "{e}");
    }
}
