//! The colour input stage of an execution: the caller's colour as linear RGB, from linear
//! RGB as given, from sRGB-encoded RGB, or from spectral bands (through
//! [`SpectralBands`]); and the matching output encoding.

use super::RawImage;
use crate::color::SpectralBands;
use crate::image::{read3, read_channel, Format, Layout};
use crate::Error;

/// How the colour input becomes the linear RGB the network and the reconstruction see.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorInput {
    /// "color" is linear RGB, read as it is.
    Linear,
    /// "color" is sRGB-encoded (OIDN's "srgb" with "hdr" false): decoded into a staging
    /// buffer, and the output encoded back.
    Srgb,
    /// "spectral" holds N bands per pixel: converted to linear sRGB in a staging buffer.
    Spectral,
}

impl ColorInput {
    /// Whether the colour is converted into the staging buffer first.
    pub(super) fn staged(self) -> bool {
        self != ColorInput::Linear
    }
}

/// Stage 0: fills `staged` (packed RGB f32 of the colour's size) from the colour input
/// and returns the image that the denoise then reads as "color"; `None` for
/// [`ColorInput::Linear`], which reads the caller's colour directly.
pub(super) fn stage(
    input: ColorInput,
    source: Option<&RawImage>,
    bands: Option<&SpectralBands>,
    staged: &mut [f32],
) -> Option<RawImage> {
    let src = source?;
    let l = src.layout;
    match (input, bands) {
        (ColorInput::Linear, _) => return None,
        (ColorInput::Srgb, _) => {
            for y in 0..l.height {
                for x in 0..l.width {
                    // SAFETY: the layout was validated when the image was set.
                    let v = unsafe { read3(src.ptr, &l, x, y) };
                    staged[(y * l.width + x) * 3..][..3].copy_from_slice(&v.map(srgb_to_linear));
                }
            }
        }
        (ColorInput::Spectral, None) => return None,
        (ColorInput::Spectral, Some(bands)) => {
            let n = bands.len();
            let (cb, px) = (l.format.channel_bytes(), spectral_pixel_stride(&l, n));
            let row = if l.row_stride == 0 {
                px * l.width
            } else {
                l.row_stride
            };
            let mut values = vec![0f32; n];
            for y in 0..l.height {
                for x in 0..l.width {
                    let base = l.byte_offset + y * row + x * px;
                    for (b, v) in values.iter_mut().enumerate() {
                        // SAFETY: commit checked the span of N bands per pixel; the caller
                        // keeps the image valid (its setter's contract).
                        *v = unsafe { read_channel(src.ptr.add(base + b * cb), l.format) };
                    }
                    let rgb = bands.to_linear_srgb(&values);
                    staged[(y * l.width + x) * 3..][..3].copy_from_slice(&rgb);
                }
            }
        }
    }
    let layout = Layout::packed(Format::Float3, l.width, l.height);
    Some(RawImage {
        ptr: staged.as_ptr() as *mut u8,
        layout,
        span: std::mem::size_of_val(staged),
        capacity: std::mem::size_of_val(staged),
    })
}

/// The output stage matching the colour input: sRGB input gives sRGB output.
pub(super) fn encode_output(input: ColorInput, rgb: &mut [f32]) {
    if input == ColorInput::Srgb {
        for v in rgb {
            *v = linear_to_srgb(*v);
        }
    }
}

fn spectral_pixel_stride(l: &Layout, bands: usize) -> usize {
    if l.pixel_stride == 0 {
        l.format.channel_bytes() * bands
    } else {
        l.pixel_stride
    }
}

/// Checks the layout of a "spectral" image when it is set: `format` is the type of one
/// band, and the size is within the limits. The band count is checked at commit.
pub(super) fn check_spectral_layout(layout: &Layout) -> Result<(), Error> {
    if layout.format.channels() != 1 {
        return Err(Error::InvalidArgument(
            "image \"spectral\": the format is the type of one band (TEMC_FORMAT_FLOAT or \
             TEMC_FORMAT_HALF); the band count is the \"spectralBands\" parameter"
                .into(),
        ));
    }
    Layout {
        pixel_stride: 0,
        row_stride: 0,
        ..*layout
    }
    .validate("spectral")?;
    Ok(())
}

/// Bytes a spectral image of `bands` bands spans, after checking its strides.
pub(super) fn spectral_span(l: &Layout, bands: usize) -> Result<usize, Error> {
    let cb = l.format.channel_bytes();
    let px = spectral_pixel_stride(l, bands);
    let pixel = cb.saturating_mul(bands);
    if px < pixel {
        return Err(Error::InvalidArgument(format!(
            "image \"spectral\": pixel stride {px} is smaller than {bands} bands ({pixel} bytes)"
        )));
    }
    let wide = Layout {
        format: l.format,
        pixel_stride: px,
        row_stride: if l.row_stride == 0 {
            px.saturating_mul(l.width)
        } else {
            l.row_stride
        },
        ..*l
    };
    let span = wide.validate("spectral")?;
    span.checked_add(pixel - cb)
        .ok_or_else(|| Error::InvalidArgument("image \"spectral\": the byte span overflows".into()))
}

/// The sRGB transfer function (IEC 61966-2-1), decoding.
fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// The sRGB transfer function, encoding.
fn linear_to_srgb(v: f32) -> f32 {
    if v <= 0.0031308 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trips() {
        for v in [0.0f32, 0.002, 0.04, 0.2, 0.5, 1.0] {
            assert!((linear_to_srgb(srgb_to_linear(v)) - v).abs() < 1e-5, "{v}");
        }
    }
}
