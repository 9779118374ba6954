//! Portable float maps: "PF" (RGB) and "Pf" (one channel), either byte order, rows stored
//! bottom-up.

use std::io::Write;
use std::path::Path;

use super::{io_err, Buffers};
use crate::Error;

/// Reads a PFM file; RGB goes to `color`, one channel to `depth`.
pub fn read(path: &Path) -> Result<Buffers, Error> {
    let bytes = std::fs::read(path).map_err(io_err(path))?;
    parse(&bytes, &path.display().to_string())
}

/// Parses PFM bytes; `name` prefixes error messages. Any input gives a result or an
/// `InvalidArgument` error (the fuzz target `pfm` checks this).
pub fn parse(bytes: &[u8], name: &str) -> Result<Buffers, Error> {
    let bad = |m: &str| Error::InvalidArgument(format!("{name}: {m}"));
    // Header: three whitespace-separated tokens after the magic, then one whitespace byte.
    let mut tokens = Vec::new();
    let mut pos = 0;
    while tokens.len() < 4 {
        while pos < bytes.len() && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while pos < bytes.len() && !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if start == pos || pos - start > 32 {
            return Err(bad("not a PFM file (bad header)"));
        }
        tokens.push(String::from_utf8_lossy(&bytes[start..pos]).into_owned());
    }
    pos += 1;
    let channels = match tokens[0].as_str() {
        "PF" => 3,
        "Pf" => 1,
        _ => return Err(bad("not a PFM file (magic must be PF or Pf)")),
    };
    let w: usize = tokens[1].parse().map_err(|_| bad("bad width"))?;
    let h: usize = tokens[2].parse().map_err(|_| bad("bad height"))?;
    let scale: f64 = tokens[3].parse().map_err(|_| bad("bad scale"))?;
    if w == 0
        || h == 0
        || w > crate::image::MAX_DIMENSION
        || h > crate::image::MAX_DIMENSION
        || w * h > crate::image::MAX_PIXELS
    {
        return Err(bad("image size out of range"));
    }
    let n = w * h * channels;
    let body = bytes.get(pos..).unwrap_or_default();
    if body.len() < n * 4 {
        return Err(bad(&format!(
            "truncated: {} data bytes for {w}x{h}x{channels}",
            body.len()
        )));
    }
    let little = scale < 0.0;
    let mut data = vec![0f32; n];
    let row = w * channels;
    for y in 0..h {
        let src = &body[(h - 1 - y) * row * 4..(h - y) * row * 4];
        for (d, c) in data[y * row..(y + 1) * row]
            .iter_mut()
            .zip(src.chunks_exact(4))
        {
            let b = [c[0], c[1], c[2], c[3]];
            *d = if little {
                f32::from_le_bytes(b)
            } else {
                f32::from_be_bytes(b)
            };
        }
    }
    let mut out = Buffers {
        width: w,
        height: h,
        ..Default::default()
    };
    if channels == 3 {
        out.color = Some(data);
    } else {
        out.depth = Some(data);
    }
    Ok(out)
}

/// Writes interleaved RGB as a little-endian "PF" file (not atomic; see [`super::write_rgb`]).
pub fn write_rgb(path: &Path, w: usize, h: usize, rgb: &[f32]) -> Result<(), Error> {
    let mut bytes = format!("PF\n{w} {h}\n-1.0\n").into_bytes();
    bytes.reserve(rgb.len() * 4);
    for y in (0..h).rev() {
        for v in &rgb[y * w * 3..(y + 1) * w * 3] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    let mut f = std::fs::File::create(path).map_err(io_err(path))?;
    f.write_all(&bytes).map_err(io_err(path))?;
    f.sync_all().map_err(io_err(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_errors() {
        let dir = std::env::temp_dir().join(format!("temc-pfm-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.pfm");
        let rgb: Vec<f32> = (0..2 * 3 * 3).map(|i| i as f32 * 0.5 - 1.0).collect();
        write_rgb(&p, 3, 2, &rgb).unwrap();
        let b = read(&p).unwrap();
        assert_eq!((b.width, b.height), (3, 2));
        assert_eq!(b.color.unwrap(), rgb);
        for bad in [
            &b"P6\n1 1\n255\n"[..],
            b"PF\n2 2\n-1.0\n\0\0",
            b"PF\n0 2\n-1\n",
            b"",
            b"PF 99999999999 1 -1 ",
        ] {
            std::fs::write(&p, bad).unwrap();
            assert!(read(&p).is_err());
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
