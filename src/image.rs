//! Caller-owned images: pixel formats and strided layouts, validated before any access.
//!
//! Images follow OIDN's model: a buffer, a format, a size, and byte offset / pixel stride /
//! row stride (0 = tightly packed). Every size computation is checked for overflow and
//! against the buffer length, so a bad stride becomes an error instead of a stray read.

use half::f16;

use crate::Error;

/// Pixel formats, with OIDN's numeric values (the C ABI passes them through).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum Format {
    /// No format set.
    Undefined = 0,
    /// One f32 channel.
    Float = 1,
    /// Two f32 channels.
    Float2 = 2,
    /// Three f32 channels.
    Float3 = 3,
    /// Four f32 channels (the fourth is ignored on input and left alone on output).
    Float4 = 4,
    /// One f16 channel.
    Half = 257,
    /// Two f16 channels.
    Half2 = 258,
    /// Three f16 channels.
    Half3 = 259,
    /// Four f16 channels.
    Half4 = 260,
}

impl Format {
    /// The format with this numeric value, if any.
    pub fn from_raw(v: u32) -> Option<Self> {
        use Format::*;
        Some(match v {
            0 => Undefined,
            1 => Float,
            2 => Float2,
            3 => Float3,
            4 => Float4,
            257 => Half,
            258 => Half2,
            259 => Half3,
            260 => Half4,
            _ => return None,
        })
    }

    /// Channels per pixel (0 for `Undefined`).
    pub fn channels(self) -> usize {
        match self {
            Format::Undefined => 0,
            Format::Float | Format::Half => 1,
            Format::Float2 | Format::Half2 => 2,
            Format::Float3 | Format::Half3 => 3,
            Format::Float4 | Format::Half4 => 4,
        }
    }

    /// Bytes per channel.
    pub fn channel_bytes(self) -> usize {
        if (self as u32) >= 257 {
            2
        } else {
            4
        }
    }

    /// Bytes of one tightly packed pixel.
    pub fn pixel_bytes(self) -> usize {
        self.channels() * self.channel_bytes()
    }
}

/// The largest width or height accepted: far above any render, far below overflow.
pub const MAX_DIMENSION: usize = 1 << 20;

/// The most pixels an image may have (16384 x 16384): larger sizes are refused as
/// invalid arguments before anything is allocated, instead of failing halfway through
/// gigabytes of staging buffers.
pub const MAX_PIXELS: usize = 1 << 28;

/// Where an image's pixels are in its buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// Pixel format.
    pub format: Format,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Bytes before the first pixel.
    pub byte_offset: usize,
    /// Bytes from one pixel to the next (0 = packed).
    pub pixel_stride: usize,
    /// Bytes from one row to the next (0 = packed).
    pub row_stride: usize,
}

impl Layout {
    /// A tightly packed layout.
    pub fn packed(format: Format, width: usize, height: usize) -> Self {
        Self {
            format,
            width,
            height,
            byte_offset: 0,
            pixel_stride: 0,
            row_stride: 0,
        }
    }

    /// The effective pixel stride.
    pub fn pixel_stride(&self) -> usize {
        if self.pixel_stride == 0 {
            self.format.pixel_bytes()
        } else {
            self.pixel_stride
        }
    }

    /// The effective row stride.
    pub fn row_stride(&self) -> usize {
        if self.row_stride == 0 {
            self.pixel_stride().saturating_mul(self.width)
        } else {
            self.row_stride
        }
    }

    /// Checks the layout and returns the number of bytes it spans from the buffer start
    /// (offset included). `name` labels errors.
    pub fn validate(&self, name: &str) -> Result<usize, Error> {
        let bad = |m: String| Err(Error::InvalidArgument(format!("image \"{name}\": {m}")));
        if self.format == Format::Undefined {
            return bad("format is undefined".into());
        }
        if self.width == 0 || self.height == 0 {
            return bad(format!("size {}x{} has no pixels", self.width, self.height));
        }
        if self.width > MAX_DIMENSION || self.height > MAX_DIMENSION {
            return bad(format!(
                "size {}x{} exceeds the limit of {MAX_DIMENSION} per side",
                self.width, self.height
            ));
        }
        if self.width * self.height > MAX_PIXELS {
            return bad(format!(
                "size {}x{} exceeds the limit of {MAX_PIXELS} pixels",
                self.width, self.height
            ));
        }
        let px = self.pixel_stride();
        if px < self.format.pixel_bytes() {
            return bad(format!(
                "pixel stride {px} is smaller than a pixel ({} bytes)",
                self.format.pixel_bytes()
            ));
        }
        let row_span = (self.width - 1)
            .checked_mul(px)
            .and_then(|v| v.checked_add(self.format.pixel_bytes()));
        let Some(row_span) = row_span else {
            return bad("pixel stride x width overflows".into());
        };
        let row = self.row_stride();
        if self.height > 1 && row < row_span {
            return bad(format!(
                "row stride {row} is smaller than a row ({row_span} bytes)"
            ));
        }
        let total = (self.height - 1)
            .checked_mul(row)
            .and_then(|v| v.checked_add(row_span))
            .and_then(|v| v.checked_add(self.byte_offset));
        match total {
            Some(t) if t <= isize::MAX as usize => Ok(t),
            _ => bad("the image's byte span overflows".into()),
        }
    }

    /// Byte position of channel `c` of pixel (x, y); the layout must be valid.
    #[inline]
    pub fn at(&self, x: usize, y: usize, c: usize) -> usize {
        self.byte_offset
            + y * self.row_stride()
            + x * self.pixel_stride()
            + c * self.format.channel_bytes()
    }
}

/// Reads up to three channels of pixel (x, y) as f32; missing channels read as 0.
///
/// # Safety
/// `base` must point to a buffer of at least `layout.validate()` bytes, readable for the
/// duration of the call, and (x, y) must be inside the image.
#[inline]
pub unsafe fn read3(base: *const u8, layout: &Layout, x: usize, y: usize) -> [f32; 3] {
    let format = layout.format;
    let n = format.channels().min(3);
    // The pixel's position once, its channels from there: this runs for every pixel of
    // every input buffer.
    // SAFETY: (x, y) lies inside the validated layout (this function's contract).
    let pixel = unsafe { base.add(layout.at(x, y, 0)) };
    let step = format.channel_bytes();
    let mut out = [0.0; 3];
    for (c, o) in out.iter_mut().enumerate().take(n) {
        // SAFETY: channel c < the format's channels of a pixel inside the layout, so its
        // bytes are inside the caller's buffer; reads may be unaligned.
        *o = unsafe { read_channel(pixel.add(c * step), format) };
    }
    out
}

/// Reads one channel value of `format` (f32, or f16 widened) at `p`, unaligned.
///
/// # Safety
/// `p` must be readable for one channel of `format`.
#[inline]
pub unsafe fn read_channel(p: *const u8, format: Format) -> f32 {
    if format.channel_bytes() == 4 {
        // SAFETY: the caller's contract.
        f32::from_ne_bytes(unsafe { std::ptr::read_unaligned(p as *const [u8; 4]) })
    } else {
        // SAFETY: the caller's contract.
        f16::from_bits(u16::from_ne_bytes(unsafe {
            std::ptr::read_unaligned(p as *const [u8; 2])
        }))
        .to_f32()
    }
}

/// Writes up to three channels of pixel (x, y) from f32 (half formats round to nearest).
///
/// # Safety
/// As [`read3`], with the buffer writable and not read concurrently at this pixel.
#[inline]
pub unsafe fn write3(base: *mut u8, layout: &Layout, x: usize, y: usize, v: [f32; 3]) {
    let n = layout.format.channels().min(3);
    for (c, &val) in v.iter().enumerate().take(n) {
        // SAFETY: as in `read3`; the caller guarantees the pixel is writable and unshared.
        unsafe {
            let p = base.add(layout.at(x, y, c));
            if layout.format.channel_bytes() == 4 {
                std::ptr::write_unaligned(p as *mut [u8; 4], val.to_ne_bytes());
            } else {
                std::ptr::write_unaligned(
                    p as *mut [u8; 2],
                    f16::from_f32(val).to_bits().to_ne_bytes(),
                );
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packed_sizes() {
        let l = Layout::packed(Format::Float3, 4, 3);
        assert_eq!(l.validate("color").unwrap(), 4 * 3 * 12);
        let l = Layout::packed(Format::Half3, 5, 1);
        assert_eq!(l.validate("color").unwrap(), 5 * 6);
    }

    #[test]
    fn bad_layouts_are_refused() {
        let base = Layout::packed(Format::Float3, 4, 4);
        let cases = [
            Layout {
                format: Format::Undefined,
                ..base
            },
            Layout { width: 0, ..base },
            Layout { height: 0, ..base },
            Layout {
                width: MAX_DIMENSION + 1,
                ..base
            },
            Layout {
                pixel_stride: 8,
                ..base
            },
            Layout {
                row_stride: 20,
                ..base
            },
            Layout {
                pixel_stride: usize::MAX / 2,
                ..base
            },
            Layout {
                row_stride: usize::MAX / 2,
                ..base
            },
            Layout {
                byte_offset: usize::MAX - 10,
                ..base
            },
        ];
        for l in cases {
            assert!(l.validate("color").is_err(), "{l:?}");
        }
    }

    #[test]
    fn strided_read_write_round_trip() {
        // RGBA float with a padded row: read and write through the stride.
        let l = Layout {
            format: Format::Float3,
            width: 2,
            height: 2,
            byte_offset: 4,
            pixel_stride: 16,
            row_stride: 48,
        };
        let n = l.validate("x").unwrap();
        let mut buf = vec![0u8; n];
        // SAFETY: `buf` holds the `n` bytes the layout spans; the pixels are inside it.
        unsafe {
            write3(buf.as_mut_ptr(), &l, 1, 1, [1.0, 2.0, 3.0]);
            assert_eq!(read3(buf.as_ptr(), &l, 1, 1), [1.0, 2.0, 3.0]);
            assert_eq!(read3(buf.as_ptr(), &l, 0, 1), [0.0; 3]);
        }
        let h = Layout::packed(Format::Half3, 1, 1);
        let mut hb = vec![0u8; 6];
        // SAFETY: one half-float RGB pixel, six bytes.
        unsafe {
            write3(hb.as_mut_ptr(), &h, 0, 0, [0.5, 65504.0, 1e9]);
            assert_eq!(read3(hb.as_ptr(), &h, 0, 0), [0.5, 65504.0, f32::INFINITY]);
        }
    }
}
