//! Files the renderer writes appear whole or not at all: each is written to a temporary
//! name beside its destination and renamed into place (atomic on one file system), so an
//! interrupted render or a resumed data set never finds a partial file.

use std::path::{Path, PathBuf};

/// The temporary name for `path`: hidden, in the same folder (so the rename is atomic),
/// with the process id, so globs such as `spp*.exr` never match it and two processes never
/// share one. The same scheme as temc's own writer (`temc::io`): `.NAME.temc-PID.tmp.EXT`,
/// keeping the extension last.
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.temc-{}.tmp.{ext}", std::process::id()))
}

/// Writes `path` through `write`, which gets the temporary path to fill; on any error the
/// temporary file is removed and `path` is left as it was.
pub fn write_atomic<E: std::fmt::Display>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), String> {
    let tmp = temp_path(path);
    let result = write(&tmp)
        .map_err(|e| format!("{}: {e}", tmp.display()))
        .and_then(|()| std::fs::rename(&tmp, path).map_err(|e| format!("{}: {e}", path.display())));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Writes `bytes` to `path` atomically.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<(), String> {
    write_atomic(path, |tmp| std::fs::write(tmp, bytes))
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
}
