//! The colour pipeline: linear (or spectral) radiance <-> the network's PQ-HSV inputs.
//!
//! Forward, per pixel: [`sanitize_rgb`] -> scale to nits -> ceiling at 10000 cd/m2 ->
//! [`pq::encode`] per channel -> [`rgb_to_hsv`]. Inverse: [`sanitize_hsv`] -> [`hsv_to_rgb`]
//! -> [`pq::decode`] -> unscale -> highlight restore. Every rule is written down in
//! docs/contracts.md §1, and `training/temc_train/color.py` implements the same rules; the
//! shared vectors in tests/data/color_vectors.json prove the two agree.

pub mod features;
pub mod hsv;
pub mod pq;
pub mod sanitize;
pub mod spectral;

pub use hsv::{hsv_to_rgb, rgb_to_hsv, sanitize_hsv};
pub use sanitize::{sanitize_channel, sanitize_rgb, LINEAR_MAX, LUMA_WEIGHTS};
pub use spectral::SpectralBands;
/// The channels of temc-render's multi-layer EXR (from the shared `temc-color` crate).
pub use temc_color::layers;

use crate::Error;

/// The default absolute scale: linear 1.0 = 100 cd/m2 (SDR reference white).
pub const DEFAULT_NITS_PER_UNIT: f32 = 100.0;

/// The PQ code value of V above which the denoised pixel gets its clipped highlight back;
/// full restoration at V = 1. PQ 0.95 is about 6900 cd/m2.
pub const HIGHLIGHT_KNEE: f32 = 0.95;

/// How linear values map to absolute luminance before PQ.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Exposure {
    input_scale: f32,
    nits_per_unit: f32,
}

impl Exposure {
    /// `input_scale` multiplies the linear input (OIDN's "inputScale"); `nits_per_unit` is
    /// the model's `temc.pq_nits_per_unit`. Both must be finite and positive.
    pub fn new(input_scale: f32, nits_per_unit: f32) -> Result<Self, Error> {
        for (name, v) in [
            ("inputScale", input_scale),
            ("nits per unit", nits_per_unit),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::InvalidArgument(format!(
                    "{name} must be finite and positive, got {v}"
                )));
            }
        }
        Ok(Self {
            input_scale,
            nits_per_unit,
        })
    }

    /// The input scale.
    pub fn input_scale(&self) -> f32 {
        self.input_scale
    }

    /// Normalised PQ luminance (L / 10000 cd/m2) per linear unit of input.
    fn y_per_unit(&self) -> f64 {
        self.input_scale as f64 * self.nits_per_unit as f64 / pq::PQ_MAX_NITS
    }
}

impl Default for Exposure {
    fn default() -> Self {
        Self {
            input_scale: 1.0,
            nits_per_unit: DEFAULT_NITS_PER_UNIT,
        }
    }
}

/// One pixel as the network sees it, plus what the inverse needs to undo the ceiling.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Encoded {
    /// (H, S, V) of the PQ-encoded colour, each in [0, 1].
    pub hsv: [f32; 3],
    /// How far the pixel's brightest channel exceeded the PQ range (>= 1; 1 = not at all).
    pub excess: f32,
}

/// Forward colour transform of one linear sRGB pixel. Any input gives a finite result.
///
/// ```
/// use temc::color::{decode, encode, Exposure};
/// let e = encode([0.8, 0.4, 0.1], Exposure::default());
/// let back = decode(e.hsv, e.excess, Exposure::default());
/// assert!((back[0] - 0.8).abs() < 1e-5 && (back[2] - 0.1).abs() < 1e-6);
/// ```
pub fn encode(rgb: [f32; 3], exposure: Exposure) -> Encoded {
    let (y, excess) = normalised(rgb, exposure);
    finish(y.map(pq::encode), excess)
}

/// [`encode`] of a row of pixels, to the bit the same: the PQ curve, most of the time,
/// runs over the whole row at once ([`pq::encode_all`]).
pub fn encode_row(rgb: &[[f32; 3]], exposure: Exposure) -> Vec<Encoded> {
    let (mut ys, excess): (Vec<[f64; 3]>, Vec<f64>) =
        rgb.iter().map(|&c| normalised(c, exposure)).unzip();
    pq::encode_all(ys.as_flattened_mut());
    ys.into_iter()
        .zip(excess)
        .map(|(pq, e)| finish(pq, e))
        .collect()
}

/// The pixel's normalised luminances y = L / 10000 cd/m2 before PQ, and its excess: a
/// pixel brighter than PQ's range is scaled into it.
fn normalised(rgb: [f32; 3], exposure: Exposure) -> ([f64; 3], f64) {
    let k = exposure.y_per_unit();
    let y = sanitize_rgb(rgb).map(|c| c as f64 * k);
    let m = y[0].max(y[1]).max(y[2]);
    if m > 1.0 {
        (y.map(|c| c / m), m)
    } else {
        (y, 1.0)
    }
}

/// HSV of the PQ code values, and the excess in f32.
fn finish(pq: [f64; 3], excess: f64) -> Encoded {
    Encoded {
        hsv: rgb_to_hsv(pq.map(|v| v as f32)),
        excess: excess.min(f32::MAX as f64) as f32,
    }
}

/// Inverse colour transform: a network output (any values) back to linear sRGB.
///
/// `excess` is the value [`encode`] gave for this pixel of the noisy input. The result is
/// finite, non-negative and at most [`LINEAR_MAX`], the sanitiser's ceiling.
pub fn decode(hsv: [f32; 3], excess: f32, exposure: Exposure) -> [f32; 3] {
    let hsv = sanitize_hsv(hsv);
    let pq = hsv_to_rgb(hsv);
    let k = exposure.y_per_unit();
    let excess = if excess.is_finite() && excess > 1.0 {
        excess as f64
    } else {
        1.0
    };
    let w = ((hsv[2] - HIGHLIGHT_KNEE) / (1.0 - HIGHLIGHT_KNEE)).clamp(0.0, 1.0) as f64;
    let restore = 1.0 + (excess - 1.0) * w;
    let limit = LINEAR_MAX as f64;
    pq.map(|e| (pq::decode(e as f64) * restore / k).min(limit) as f32)
}

/// The grey level that automatic exposure maps an image's log-average luminance to.
pub const AUTO_EXPOSURE_KEY: f64 = 0.18;

/// Automatic input scale, as OIDN computes it for HDR images: `0.18 / exp(mean(ln Y))` over
/// the pixels with luminance above 1e-8 (after sanitising), so the image's log-average
/// maps to mid-grey. An image with no such pixel gets 1.0. The result is computed from
/// the whole image once, before tiling, so it is the same for every tile.
pub fn auto_input_scale(pixels: impl Iterator<Item = [f32; 3]>) -> f32 {
    LogLuminance::of(pixels).input_scale()
}

/// The sum of ln Y over the pixels [`auto_input_scale`] counts, and their number: parts of
/// an image summed apart (in parallel) and merged in a fixed order give one scale whatever
/// the thread count.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LogLuminance {
    sum: f64,
    n: u64,
}

impl LogLuminance {
    /// The sum over `pixels`.
    pub fn of(pixels: impl Iterator<Item = [f32; 3]>) -> Self {
        let mut acc = Self::default();
        for p in pixels {
            let c = sanitize_rgb(p);
            let y: f64 = c
                .iter()
                .zip(LUMA_WEIGHTS)
                .map(|(&v, w)| v as f64 * w as f64)
                .sum();
            if y > 1e-8 {
                acc.sum += y.ln();
                acc.n += 1;
            }
        }
        acc
    }

    /// Both parts' pixels together.
    pub fn merge(self, other: Self) -> Self {
        LogLuminance {
            sum: self.sum + other.sum,
            n: self.n + other.n,
        }
    }

    /// The input scale of [`auto_input_scale`].
    pub fn input_scale(self) -> f32 {
        if self.n == 0 {
            return 1.0;
        }
        let scale = AUTO_EXPOSURE_KEY / (self.sum / self.n as f64).exp();
        (scale as f32).clamp(1e-20, 1e20)
    }
}

#[cfg(test)]
mod tests;
