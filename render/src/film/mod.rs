//! The film: paths accumulate into each pixel's sums, which become the output layers
//! (colour through the CIE observer, spectral bands, albedo, normal, depth); [`exr`]
//! writes them, and [`relmse`] compares two renders.

pub mod exr;

use temc_color::layers::{SPECTRAL_BANDS, SPECTRAL_BAND_NM, SPECTRAL_MIN_NM};

use crate::integrator::PathSample;
use crate::spectral::wavelengths::LANES;

/// One pixel's running sums.
#[derive(Clone, Default)]
pub struct Pixel {
    xyz: [f64; 3],
    bands: [f64; SPECTRAL_BANDS],
    albedo: [f64; 3],
    normal: [f64; 3],
    depth: f64,
    n: u32,
}

impl Pixel {
    /// Adds one path.
    pub fn add(&mut self, s: &PathSample, y_norm: f64) {
        for i in 0..LANES {
            let (l, pdf) = (s.wavelengths.lambda[i], s.wavelengths.pdf[i]);
            if pdf <= 0.0 {
                continue;
            }
            let w = s.radiance[i] as f64 / pdf as f64 / LANES as f64;
            let c = temc_color::cie::cmf_tabulated_f32(l);
            for (acc, cmf) in self.xyz.iter_mut().zip(c) {
                *acc += cmf as f64 * w / y_norm;
            }
            let b = ((l - SPECTRAL_MIN_NM) / SPECTRAL_BAND_NM).floor();
            if (0.0..SPECTRAL_BANDS as f32).contains(&b) {
                // Mean radiance over the band: the band's integral over its width.
                self.bands[b as usize] += w / SPECTRAL_BAND_NM as f64;
            }
        }
        for k in 0..3 {
            self.albedo[k] += s.albedo[k] as f64;
        }
        self.normal[0] += s.normal.0 as f64;
        self.normal[1] += s.normal.1 as f64;
        self.normal[2] += s.normal.2 as f64;
        self.depth += s.depth as f64;
        self.n += 1;
    }
}

/// A finished image: every layer as planes of f32, row-major.
#[derive(Clone)]
pub struct Layers {
    /// Width.
    pub width: usize,
    /// Height.
    pub height: usize,
    /// Linear sRGB (may hold small negative values for colours outside sRGB).
    pub color: Vec<[f32; 3]>,
    /// Mean radiance per band.
    pub spectral: Vec<[f32; SPECTRAL_BANDS]>,
    /// Albedo at the first hit.
    pub albedo: Vec<[f32; 3]>,
    /// Normal at the first hit (mean over the pixel's paths).
    pub normal: Vec<[f32; 3]>,
    /// Distance to the first hit.
    pub depth: Vec<f32>,
}

impl Layers {
    /// Averages the pixels' sums.
    pub fn from_pixels(width: usize, height: usize, px: &[Pixel]) -> Self {
        let mean = |v: f64, n: u32| (v / n.max(1) as f64) as f32;
        Layers {
            width,
            height,
            color: px
                .iter()
                .map(|p| temc_color::cie::xyz_to_linear_srgb(p.xyz.map(|v| v / p.n.max(1) as f64)))
                .collect(),
            spectral: px.iter().map(|p| p.bands.map(|v| mean(v, p.n))).collect(),
            albedo: px.iter().map(|p| p.albedo.map(|v| mean(v, p.n))).collect(),
            normal: px.iter().map(|p| p.normal.map(|v| mean(v, p.n))).collect(),
            depth: px.iter().map(|p| mean(p.depth, p.n)).collect(),
        }
    }
}

/// Relative MSE with eps 0.01, the data set's error measure
/// (training/temc_train/evaluate.py): the mean over pixels and channels of
/// (x - r)^2 / (r^2 + 0.01).
pub fn relmse(x: &[[f32; 3]], reference: &[[f32; 3]]) -> f64 {
    let sum: f64 = x
        .iter()
        .zip(reference)
        .flat_map(|(a, r)| (0..3).map(move |c| (a[c] as f64, r[c] as f64)))
        .map(|(a, r)| (a - r).powi(2) / (r * r + 0.01))
        .sum();
    sum / (3 * x.len().max(1)) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relmse_is_zero_on_equal_images_and_relative() {
        let r = vec![[1.0f32, 2.0, 0.0]; 4];
        assert_eq!(relmse(&r, &r), 0.0);
        let x = vec![[1.1f32, 2.2, 0.1]; 4];
        let want = (0.01 / 1.01 + 0.04 / 4.01 + 0.01 / 0.01) / 3.0;
        assert!((relmse(&x, &r) - want).abs() < 1e-6);
    }
}
