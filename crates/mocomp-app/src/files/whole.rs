//! Files written whole: into a file beside the target, then renamed over it, so that an
//! interruption (a crash, a full disk, Ctrl-C) leaves the old file or the new one, never half
//! of either. The file beside it is named for the process and the write, so two writers of the
//! same file (processes or threads) do not write into one another's.

use crate::{AppError, Context};
use std::path::{Path, PathBuf};

/// Writes `bytes` to `path` whole; `what` names the file in an error ("the targets file").
pub fn write_whole(path: &Path, bytes: &[u8], what: &str) -> Result<(), AppError> {
    let tmp = beside(path);
    if let Err(e) = std::fs::write(&tmp, bytes) {
        // Nothing half-written is left behind.
        std::fs::remove_file(&tmp).ok();
        return Err(e).what(|| format!("writing {what} {}", tmp.display()));
    }
    std::fs::rename(&tmp, path).what(|| {
        std::fs::remove_file(&tmp).ok();
        format!("writing {what} {}", path.display())
    })
}

/// [`write_whole`], making the folder it goes in first.
pub fn write_whole_making_folder(path: &Path, bytes: &[u8], what: &str) -> Result<(), AppError> {
    if let Some(parent) = path.parent()
        && !parent.as_os_str().is_empty()
    {
        std::fs::create_dir_all(parent).what(|| format!("making {}", parent.display()))?;
    }
    write_whole(path, bytes, what)
}

/// The file `path` is written through: its name, this process's id, a count of this process's
/// writes (two threads writing one file write two files), and `.tmp`.
fn beside(path: &Path) -> PathBuf {
    static WRITES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = WRITES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(format!(".{}-{n}.tmp", std::process::id()));
    PathBuf::from(tmp)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    #[test]
    fn a_file_is_replaced_whole_and_nothing_is_left_beside_it() {
        let dir = mocomp_testkit::TempDir::new("whole-file");
        let path = PathBuf::from(dir.path("sub/f.toml"));
        write_whole_making_folder(&path, b"one", "the file").unwrap();
        write_whole(&path, b"two", "the file").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"two");
        let names: Vec<_> = std::fs::read_dir(path.parent().unwrap())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("f.toml")]);
    }

    #[test]
    fn a_file_that_cannot_be_written_is_named_and_the_old_one_kept() {
        let dir = mocomp_testkit::TempDir::new("whole-file-bad");
        let path = PathBuf::from(dir.path("f.toml"));
        std::fs::write(&path, b"old").unwrap();
        // A folder where the target is: the rename fails.
        let blocked = PathBuf::from(dir.path("d"));
        std::fs::create_dir_all(blocked.join("x")).unwrap();
        let e = write_whole(&blocked, b"new", "the targets file").unwrap_err();
        assert!(e.to_string().contains("the targets file"), "{e}");
        assert!(
            e.to_string().contains(&blocked.display().to_string()),
            "{e}"
        );
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(dir.path("")).unwrap().count(), 2);
    }
}
