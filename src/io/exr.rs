//! OpenEXR: single-layer RGB files, and multi-layer files whose layers are named
//! `color`/`albedo`/`normal`/`depth` (temc-render) or as Blender names its passes.
//!
//! A channel's full name is `[layer.]pass.channel` (e.g. `ViewLayer.Denoising Albedo.R`);
//! the pass is the component before the channel letter, matched case-insensitively:
//!
//! | buffer | passes (first found wins) | channels |
//! | --- | --- | --- |
//! | color | `color`, `Noisy Image`, `Combined`, `rgba`, none (plain R, G, B) | R G B |
//! | albedo | `albedo`, `Denoising Albedo` | R G B |
//! | normal | `normal`, `Denoising Normal`, `Normal` | X Y Z or R G B |
//! | depth | `depth`, `Depth`, `Z` | Z, V, Y or R; a file with a single channel |
//! | spectral | `spectral` | `b00`, `b01`, ... (consecutive from `b00`; band values) |

use std::collections::HashMap;
use std::path::Path;

use exr::prelude::*;

use super::Buffers;
use crate::Error as TemcError;

const COLOR: &[&str] = &["color", "noisy image", "combined", "rgba", ""];
const ALBEDO: &[&str] = &["albedo", "denoising albedo"];
const NORMAL: &[&str] = &["normal", "denoising normal"];
const DEPTH: &[&str] = &["depth", "z"];

fn samples(s: &FlatSamples) -> Vec<f32> {
    match s {
        FlatSamples::F16(v) => v.iter().map(|x| x.to_f32()).collect(),
        FlatSamples::F32(v) => v.clone(),
        FlatSamples::U32(v) => v.iter().map(|&x| x as f32).collect(),
    }
}

/// Splits `a.b.Pass.R` into (`pass` lower-cased, `R`).
fn split(full: &str) -> (String, String) {
    match full.rsplit_once('.') {
        Some((rest, ch)) => {
            let pass = rest.rsplit_once('.').map_or(rest, |(_, p)| p);
            (pass.to_ascii_lowercase(), ch.to_string())
        }
        None => (String::new(), full.to_string()),
    }
}

/// Reads an EXR file into the buffers its channel names identify.
pub fn read(path: &Path) -> std::result::Result<Buffers, TemcError> {
    let bytes = std::fs::read(path).map_err(|source| TemcError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&bytes, &path.display().to_string())
}

/// Parses EXR bytes; `name` prefixes error messages. The header is checked against the
/// image limits before any pixel is decoded, so a hostile header cannot make the decoder
/// allocate gigabytes (the fuzz target `exr` checks that any input gives a result or an
/// `InvalidArgument` error).
pub fn parse(bytes: &[u8], name: &str) -> std::result::Result<Buffers, TemcError> {
    let bad =
        |e: String| TemcError::InvalidArgument(format!("{name}: not a readable OpenEXR file: {e}"));
    let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false)
        .map_err(|e| bad(e.to_string()))?;
    check_headers(&meta, bytes.len()).map_err(bad)?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .map_err(|e| bad(e.to_string()))?;
    let (size, channels) = decode_channels(&image, name)?;
    let out = assemble(size, channels);
    if out.color.is_none()
        && out.depth.is_none()
        && out.albedo.is_none()
        && out.normal.is_none()
        && out.spectral.is_none()
    {
        return Err(TemcError::InvalidArgument(format!(
            "{name}: no colour, albedo, normal, depth or spectral channels recognised"
        )));
    }
    Ok(out)
}

/// Refuses layers too large for temc and headers that claim more samples than the file
/// can hold, before the decoder allocates for them.
fn check_headers(meta: &exr::meta::MetaData, file_bytes: usize) -> std::result::Result<(), String> {
    let mut total = 0usize;
    for header in &meta.headers {
        let (w, h) = (header.layer_size.width(), header.layer_size.height());
        let px = w.saturating_mul(h);
        total = total.saturating_add(px.saturating_mul(header.channels.list.len()));
        if w > crate::image::MAX_DIMENSION
            || h > crate::image::MAX_DIMENSION
            || px > crate::image::MAX_PIXELS
            || header.deep
        {
            return Err(format!("unsupported layer of {w}x{h} pixels"));
        }
    }
    // Deflate, the strongest of EXR's codecs, expands at most about 1032:1, so half-float
    // data stays under ~516 samples per byte. A header claiming more is lying.
    if total > file_bytes.saturating_mul(1024).max(1 << 16) {
        return Err(format!(
            "{total} samples cannot come from {file_bytes} bytes"
        ));
    }
    Ok(())
}

/// (pass, channel letter) -> samples.
type Channels = HashMap<(String, String), Vec<f32>>;

/// Every channel of every layer, by pass and letter; all layers must share one size.
fn decode_channels(
    image: &exr::image::FlatImage,
    name: &str,
) -> std::result::Result<((usize, usize), Channels), TemcError> {
    let mut size = None;
    let mut channels = Channels::new();
    for layer in &image.layer_data {
        let (w, h) = (layer.size.width(), layer.size.height());
        match size {
            None => size = Some((w, h)),
            Some(s) if s != (w, h) => {
                return Err(TemcError::InvalidArgument(format!(
                    "{name}: layers of different sizes ({}x{} and {w}x{h})",
                    s.0, s.1
                )))
            }
            _ => {}
        }
        let prefix = layer.attributes.layer_name.as_ref().map(|n| n.to_string());
        for ch in &layer.channel_data.list {
            let name = ch.name.to_string();
            let full = match &prefix {
                Some(p) if !p.is_empty() => format!("{p}.{name}"),
                _ => name,
            };
            channels.insert(split(&full), samples(&ch.sample_data));
        }
    }
    let size = size.ok_or_else(|| TemcError::InvalidArgument(format!("{name}: no layers")))?;
    Ok((size, channels))
}

/// The buffers temc knows, found among `channels` by their pass names and letters.
fn assemble((width, height): (usize, usize), channels: Channels) -> Buffers {
    let find3 = |passes: &[&str], letters: [&[&str]; 3]| -> Option<Vec<f32>> {
        passes.iter().find_map(|pass| {
            let pick = |options: &[&str]| {
                options
                    .iter()
                    .find_map(|l| channels.get(&(pass.to_string(), l.to_string())))
            };
            let (a, b, c) = (pick(letters[0])?, pick(letters[1])?, pick(letters[2])?);
            Some((0..a.len()).flat_map(|i| [a[i], b[i], c[i]]).collect())
        })
    };
    let rgb: [&[&str]; 3] = [&["R"], &["G"], &["B"]];
    let xyz: [&[&str]; 3] = [&["X", "R"], &["Y", "G"], &["Z", "B"]];
    let mut out = Buffers {
        width,
        height,
        color: find3(COLOR, rgb),
        albedo: find3(ALBEDO, rgb),
        normal: find3(NORMAL, xyz),
        depth: None,
        spectral: None,
        spectral_bands: 0,
    };
    let band = |b: usize| channels.get(&("spectral".to_string(), format!("b{b:02}")));
    let bands = (0..).take_while(|&b| band(b).is_some()).count();
    if bands > 0 {
        let planes: Vec<&Vec<f32>> = (0..bands).filter_map(band).collect();
        out.spectral = Some(
            (0..width * height)
                .flat_map(|i| planes.iter().map(move |p| p[i]))
                .collect(),
        );
        out.spectral_bands = bands;
    }
    out.depth = DEPTH.iter().find_map(|pass| {
        ["Z", "V", "Y", "R"]
            .iter()
            .find_map(|l| channels.get(&(pass.to_string(), l.to_string())).cloned())
    });
    if out.depth.is_none() && channels.len() == 1 && out.color.is_none() {
        out.depth = channels.into_values().next();
    }
    out
}

/// Writes interleaved RGB as a 32-bit float EXR (not atomic; see [`super::write_rgb`]).
pub fn write_rgb(
    path: &Path,
    w: usize,
    h: usize,
    rgb: &[f32],
) -> std::result::Result<(), TemcError> {
    write_rgb_file(path, w, h, |x, y| {
        let i = (y * w + x) * 3;
        (rgb[i], rgb[i + 1], rgb[i + 2])
    })
    .map_err(|e| TemcError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::other(e.to_string()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use smallvec::smallvec;

    fn channel(name: &str, v: f32, n: usize) -> AnyChannel<FlatSamples> {
        AnyChannel::new(name, FlatSamples::F32(vec![v; n]))
    }

    #[test]
    fn blender_pass_names_are_recognised() {
        let dir = std::env::temp_dir().join(format!("temc-exr-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("blender.exr");
        let size = Vec2(4, 3);
        let n = 12;
        let layer = Layer::new(
            size,
            LayerAttributes::default(),
            Encoding::FAST_LOSSLESS,
            AnyChannels::sort(smallvec![
                channel("ViewLayer.Combined.R", 9.0, n),
                channel("ViewLayer.Combined.G", 9.0, n),
                channel("ViewLayer.Combined.B", 9.0, n),
                channel("ViewLayer.Noisy Image.R", 1.0, n),
                channel("ViewLayer.Noisy Image.G", 2.0, n),
                channel("ViewLayer.Noisy Image.B", 3.0, n),
                channel("ViewLayer.Denoising Albedo.R", 0.5, n),
                channel("ViewLayer.Denoising Albedo.G", 0.5, n),
                channel("ViewLayer.Denoising Albedo.B", 0.5, n),
                channel("ViewLayer.Denoising Normal.X", 0.0, n),
                channel("ViewLayer.Denoising Normal.Y", 1.0, n),
                channel("ViewLayer.Denoising Normal.Z", 0.0, n),
                channel("ViewLayer.Depth.Z", 7.0, n),
            ]),
        );
        Image::from_layer(layer).write().to_file(&p).unwrap();
        let b = read(&p).unwrap();
        assert_eq!((b.width, b.height), (4, 3));
        // The noisy image wins over Combined, which Blender denoises itself.
        assert_eq!(&b.color.unwrap()[..3], &[1.0, 2.0, 3.0]);
        assert_eq!(&b.albedo.unwrap()[..3], &[0.5; 3]);
        assert_eq!(&b.normal.unwrap()[..3], &[0.0, 1.0, 0.0]);
        assert_eq!(b.depth.unwrap()[0], 7.0);

        let rgb: Vec<f32> = (0..36).map(|i| i as f32).collect();
        let q = dir.join("rgb.exr");
        super::super::write_rgb(&q, 4, 3, &rgb).unwrap();
        assert_eq!(read(&q).unwrap().color.unwrap(), rgb);
        std::fs::write(&q, b"not an exr").unwrap();
        assert!(read(&q).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn b44_blocks_that_wrap_decode_without_panicking() {
        // Found by the `exr` fuzz target: a B44A block whose deltas wrap below zero made
        // the decoder's u32 arithmetic panic under overflow checks (Cargo.toml turns them
        // off for exr). Any result is fine; a panic is not.
        let bytes = include_bytes!("../../tests/data/fuzz/exr-b44a-wrapping.exr");
        let _ = parse(bytes, "b44a");
    }
}
