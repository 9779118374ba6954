//! Files the renderer writes appear whole or not at all: each is written to a temporary
//! name beside its destination and renamed into place (atomic on one file system), so an
//! interrupted render or a resumed data set never finds a partial file.

use std::path::{Path, PathBuf};

/// The temporary name for `path`: hidden, in the same folder (so the rename is atomic),
/// with the process id, so globs such as `spp*.exr` never match it and two processes never
/// share one. The same scheme as temc's own writer (`temc::io`): `.NAME.temc-PID.tmp.EXT`,
/// keeping the extension last.
pub fn temp_path(path: &Path) -> PathBuf {
    temp_path_tagged(path, "")
}

/// [`temp_path`] with `tag` after the process id (`.NAME.temc-PID-TAG.tmp.EXT`), for a
/// file that processes on several machines may write at once, such as the settings every
/// part of a cluster render writes into a shared data set folder: process ids on
/// different machines can coincide, and two writers sharing a temporary file would fail.
pub fn temp_path_tagged(path: &Path, tag: &str) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tag = if tag.is_empty() {
        String::new()
    } else {
        format!("-{tag}")
    };
    path.with_file_name(format!(
        ".{name}.temc-{}{tag}.tmp.{ext}",
        std::process::id()
    ))
}

/// Writes `path` through `write`, which gets the temporary path to fill; on any error the
/// temporary file is removed and `path` is left as it was.
pub fn write_atomic<E: std::fmt::Display>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), String> {
    write_through(&temp_path(path), path, write)
}

/// [`write_atomic`] through the temporary file `tmp`.
fn write_through<E: std::fmt::Display>(
    tmp: &Path,
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), String> {
    let result = write(tmp)
        .map_err(|e| format!("{}: {e}", tmp.display()))
        .and_then(|()| std::fs::rename(tmp, path).map_err(|e| format!("{}: {e}", path.display())));
    if result.is_err() {
        let _ = std::fs::remove_file(tmp);
    }
    result
}

/// Writes `bytes` to `path` atomically.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<(), String> {
    write_atomic(path, |tmp| std::fs::write(tmp, bytes))
}

/// Writes `bytes` to `path` atomically through [`temp_path_tagged`]`(path, tag)`.
pub fn write_bytes_atomic_tagged(path: &Path, tag: &str, bytes: &[u8]) -> Result<(), String> {
    write_through(&temp_path_tagged(path, tag), path, |tmp| {
        std::fs::write(tmp, bytes)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_leaves_neither_file_nor_temporary() {
        let dir = std::env::temp_dir().join(format!("temc-render-output-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.txt");
        write_bytes_atomic(&path, b"one").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"one");
        let e = write_atomic(&path, |tmp| {
            std::fs::write(tmp, b"partial")?;
            Err(std::io::Error::other("interrupted"))
        })
        .unwrap_err();
        assert!(e.contains("interrupted"), "{e}");
        assert_eq!(std::fs::read(&path).unwrap(), b"one");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn tagged_temporaries_differ_and_stay_hidden() {
        let path = Path::new("data/dataset.json");
        let (a, b) = (
            temp_path_tagged(path, "part-1-of-2"),
            temp_path_tagged(path, "part-2-of-2"),
        );
        assert_ne!(a, b);
        let name = a.file_name().unwrap().to_string_lossy().into_owned();
        assert!(name.starts_with(".dataset.json.temc-"), "{name}");
        assert!(name.ends_with("-part-1-of-2.tmp.json"), "{name}");
        assert_eq!(temp_path_tagged(path, ""), temp_path(path));
    }
}
