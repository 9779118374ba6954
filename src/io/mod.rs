//! Reading and writing the image files the command line meets: PFM and OpenEXR.
//!
//! Writes are atomic: the file is written beside its destination under a temporary name
//! and renamed into place, so a failure never leaves a partial output.

pub mod exr;
pub mod pfm;

use std::path::{Path, PathBuf};

use crate::Error;

/// An image as planes the filter takes: interleaved RGB for colour-like buffers, one
/// channel for depth. Missing buffers are `None`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Buffers {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Noisy colour, RGB.
    pub color: Option<Vec<f32>>,
    /// Albedo, RGB.
    pub albedo: Option<Vec<f32>>,
    /// Normal, XYZ.
    pub normal: Option<Vec<f32>>,
    /// Depth, one channel.
    pub depth: Option<Vec<f32>>,
    /// Spectral radiance in bands (temc-render's `spectral` layer), `spectral_bands` values
    /// per pixel, interleaved.
    pub spectral: Option<Vec<f32>>,
    /// Bands per pixel of `spectral` (0 without it).
    pub spectral_bands: usize,
}

fn is_exr(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
}

/// Reads a PFM or EXR file (by extension). A 3-channel PFM or single-layer RGB EXR fills
/// `color`; a 1-channel one fills `depth`; a multi-layer EXR fills every buffer it names
/// (see [`exr::read`]).
pub fn read(path: &Path) -> Result<Buffers, Error> {
    if is_exr(path) {
        exr::read(path)
    } else {
        pfm::read(path)
    }
}

/// Writes interleaved RGB to a PFM or EXR file (by extension), atomically.
pub fn write_rgb(path: &Path, width: usize, height: usize, rgb: &[f32]) -> Result<(), Error> {
    if rgb.len() != width * height * 3 {
        return Err(Error::InvalidArgument(format!(
            "{}: {} values for a {width}x{height} RGB image",
            path.display(),
            rgb.len()
        )));
    }
    let tmp = temp_path(path);
    let result = if is_exr(path) {
        exr::write_rgb(&tmp, width, height, rgb)
    } else {
        pfm::write_rgb(&tmp, width, height, rgb)
    };
    match result.and_then(|_| {
        std::fs::rename(&tmp, path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })
    }) {
        Ok(()) => Ok(()),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(e)
        }
    }
}

/// A temporary name in the destination's folder (same file system, so rename is atomic),
/// keeping the extension so format detection still works.
fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(
        ".{name}.temc-{}.tmp.{}",
        std::process::id(),
        extension(path)
    ))
}

fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().into_owned())
        .unwrap_or_default()
}

pub(crate) fn io_err(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |source| Error::Io {
        path: path.to_path_buf(),
        source,
    }
}
