//! N spectral bands -> CIE XYZ -> linear sRGB.
//!
//! A spectral renderer can hand temc its per-band radiance instead of RGB, so that the
//! conversion to colour happens once, here, with the same numbers as in training.
//!
//! The CIE 1931 2-degree observer itself (the CIE's 1 nm table, its exact integrals, XYZ ->
//! linear sRGB) lives in the `temc-color` crate, which temc-render shares: the tracer's film
//! and these bands use the same table, so a render's colour and its bands converted here
//! agree (up to what averaging a spectrum over a band loses). It is re-exported here.

use crate::Error;

pub use temc_color::cie::{
    cmf_tabulated, cmf_tabulated_f32, cmf_tabulated_integral, xyz_to_linear_srgb, VISIBLE_NM,
    XYZ_TO_SRGB,
};

/// Converts spectra sampled in fixed bands to linear sRGB; built once per band layout.
///
/// ```
/// use temc::color::SpectralBands;
/// // 16 equal bands over 380..780 nm, as the paper's renders use.
/// let edges: Vec<f32> = (0..=16).map(|i| 380.0 + 25.0 * i as f32).collect();
/// let bands = SpectralBands::new(&edges).unwrap();
/// let rgb = bands.to_linear_srgb(&[1.0; 16]);
/// // An equal-energy spectrum (illuminant E) is pinker than sRGB's D65 white.
/// assert!(rgb[0] > rgb[1] && rgb[1] > rgb[2]);
/// assert!((rgb[1] - 0.95).abs() < 0.05); // 380..780 nm holds ~95 % of Y
/// ```
#[derive(Clone, Debug)]
pub struct SpectralBands {
    edges: Vec<f32>,
    /// Per band, the XYZ that a unit value in that band contributes.
    weights: Vec<[f64; 3]>,
}

impl SpectralBands {
    /// Builds the band-to-XYZ weights for `edges` (N + 1 strictly increasing wavelengths in
    /// nm, N >= 1). Each band's value is its mean spectral radiance; XYZ is normalised so a
    /// flat spectrum of 1.0 over 360..830 nm has Y = 1. The weights are exact integrals of
    /// the tabulated observer over each band (0 outside 360..830 nm, where the table ends),
    /// computed once here.
    pub fn new(edges: &[f32]) -> Result<Self, Error> {
        if edges.len() < 2 {
            return Err(Error::InvalidArgument(format!(
                "spectral band edges: need at least 2, got {}",
                edges.len()
            )));
        }
        if let Some(bad) = edges.iter().find(|e| !e.is_finite() || **e <= 0.0) {
            return Err(Error::InvalidArgument(format!(
                "spectral band edge {bad} is not a positive wavelength in nm"
            )));
        }
        if edges.windows(2).any(|w| w[1] <= w[0]) {
            return Err(Error::InvalidArgument(
                "spectral band edges must be strictly increasing".into(),
            ));
        }
        let y_norm = cmf_tabulated_integral(VISIBLE_NM.0, VISIBLE_NM.1)[1];
        let weights = edges
            .windows(2)
            .map(|w| cmf_tabulated_integral(w[0] as f64, w[1] as f64).map(|v| v / y_norm))
            .collect();
        Ok(Self {
            edges: edges.to_vec(),
            weights,
        })
    }

    /// `bands` equal bands over `min_nm..max_nm`: the layout of temc-render's `spectral`
    /// EXR layer (16 over 380..780 nm) and of the C API's "spectral" image.
    pub fn uniform(bands: usize, min_nm: f32, max_nm: f32) -> Result<Self, Error> {
        if bands == 0 || max_nm.partial_cmp(&min_nm) != Some(std::cmp::Ordering::Greater) {
            return Err(Error::InvalidArgument(format!(
                "spectral bands: need at least one band over a range with max > min, got \
                 {bands} over {min_nm}..{max_nm} nm"
            )));
        }
        let edges: Vec<f32> = (0..=bands)
            .map(|i| min_nm + (max_nm - min_nm) * i as f32 / bands as f32)
            .collect();
        Self::new(&edges)
    }

    /// Linear sRGB, interleaved, of an image whose pixels hold [`Self::len`] band values
    /// each, interleaved (a trailing partial pixel is ignored).
    pub fn image_to_linear_srgb(&self, values: &[f32]) -> Vec<f32> {
        values
            .chunks_exact(self.len())
            .flat_map(|px| self.to_linear_srgb(px))
            .collect()
    }

    /// Number of bands.
    pub fn len(&self) -> usize {
        self.weights.len()
    }

    /// Always false: a band layout has at least one band.
    pub fn is_empty(&self) -> bool {
        self.weights.is_empty()
    }

    /// The band edges in nm.
    pub fn edges(&self) -> &[f32] {
        &self.edges
    }

    /// CIE XYZ of one spectrum. Band values go through the channel sanitiser and negative
    /// radiance counts as 0. `values.len()` must equal [`Self::len`] (extra values are ignored,
    /// missing ones count as 0).
    pub fn to_xyz(&self, values: &[f32]) -> [f64; 3] {
        let mut xyz = [0.0; 3];
        for (w, &v) in self.weights.iter().zip(values) {
            let v = super::sanitize_channel(v).max(0.0) as f64;
            for k in 0..3 {
                xyz[k] += v * w[k];
            }
        }
        xyz
    }

    /// Linear sRGB of one spectrum; may have negative components for colours outside the
    /// sRGB gamut (the pipeline's sanitiser removes them by its documented rule).
    pub fn to_linear_srgb(&self, values: &[f32]) -> [f32; 3] {
        xyz_to_linear_srgb(self.to_xyz(values))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_spectrum_has_unit_luminance_and_is_near_white() {
        let bands = SpectralBands::new(&[360.0, 830.0]).unwrap();
        let xyz = bands.to_xyz(&[1.0]);
        assert!((xyz[1] - 1.0).abs() < 1e-12);
        let edges: Vec<f32> = (0..=16).map(|i| 380.0 + 25.0 * i as f32).collect();
        let rgb = SpectralBands::new(&edges)
            .unwrap()
            .to_linear_srgb(&[2.0; 16]);
        // Illuminant E in linear sRGB is (1.2049, 0.9483, 0.9088) at Y = 1.
        let (rg, bg) = (rgb[0] / rgb[1], rgb[2] / rgb[1]);
        assert!(
            (rg - 1.2706).abs() < 0.02 && (bg - 0.9583).abs() < 0.02,
            "{rgb:?}"
        );
        assert!((rgb[1] - 2.0 * 0.95).abs() < 0.1, "{rgb:?}");
    }

    /// XYZ of `s` as the tracer's film sees it: the expectation of its per-wavelength
    /// estimate, the integral of s(λ) `cmf_tabulated_f32`(λ) over 360..830 nm (midpoint
    /// rule, 0.01 nm), over the same Y normalisation (render/src/render.rs).
    fn tracer_xyz(s: impl Fn(f64) -> f64) -> [f64; 3] {
        let h = 0.01;
        let mut acc = [0.0; 3];
        for i in 0..47_000 {
            let l = 360.0 + (i as f64 + 0.5) * h;
            let c = cmf_tabulated_f32(l as f32);
            (0..3).for_each(|k| acc[k] += c[k] as f64 * s(l) * h);
        }
        let y_norm = cmf_tabulated_integral(360.0, 830.0)[1];
        acc.map(|v| v / y_norm)
    }

    fn assert_close(a: [f64; 3], b: [f64; 3], what: &str) {
        let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for k in 0..3 {
            assert!(
                (a[k] - b[k]).abs() <= 1e-4 * scale,
                "{what}: {a:?} vs {b:?}"
            );
        }
    }

    #[test]
    fn bands_convert_a_spectrum_as_the_tracer_does() {
        // A narrow line: one band exactly covering it.
        let line = |l: f64| {
            if (549.5..550.5).contains(&l) {
                3.0
            } else {
                0.0
            }
        };
        let b = SpectralBands::new(&[549.5, 550.5]).unwrap();
        assert_close(b.to_xyz(&[3.0]), tracer_xyz(line), "line at 550 nm");
        // A smooth spectrum (3000 K blackbody, scaled) through 1 nm bands holding its means.
        let bb = |l: f64| 1e17 / (l.powi(5) * ((1.4388e7 / (l * 3000.0)).exp() - 1.0));
        let edges: Vec<f32> = (360..=830).map(|l| l as f32).collect();
        let means: Vec<f32> = edges
            .windows(2)
            .map(|w| {
                let n = 100;
                let h = (w[1] - w[0]) as f64 / n as f64;
                ((0..n)
                    .map(|i| bb(w[0] as f64 + (i as f64 + 0.5) * h))
                    .sum::<f64>()
                    / n as f64) as f32
            })
            .collect();
        let b = SpectralBands::new(&edges).unwrap();
        assert_close(b.to_xyz(&means), tracer_xyz(bb), "3000 K blackbody");
        // The whole range: a flat spectrum has Y = 1 on both sides.
        let flat = tracer_xyz(|_| 1.0);
        assert!((flat[1] - 1.0).abs() < 1e-6, "{flat:?}");
    }

    #[test]
    fn narrow_bands_give_out_of_gamut_colour() {
        // A 500 nm laser-like band is more saturated than sRGB green: negative red.
        let rgb = SpectralBands::new(&[495.0, 505.0])
            .unwrap()
            .to_linear_srgb(&[1.0]);
        assert!(rgb[0] < 0.0 && rgb[1] > 0.0);
    }

    #[test]
    fn bad_edges_are_refused() {
        assert!(SpectralBands::new(&[500.0]).is_err());
        assert!(SpectralBands::new(&[500.0, 500.0]).is_err());
        assert!(SpectralBands::new(&[600.0, 500.0]).is_err());
        assert!(SpectralBands::new(&[f32::NAN, 500.0]).is_err());
        assert!(SpectralBands::new(&[-1.0, 500.0]).is_err());
    }

    #[test]
    fn garbage_band_values_stay_finite() {
        let edges: Vec<f32> = (0..=4).map(|i| 400.0 + 100.0 * i as f32).collect();
        let b = SpectralBands::new(&edges).unwrap();
        let rgb = b.to_linear_srgb(&[f32::NAN, f32::INFINITY, -5.0, 1e30]);
        assert!(rgb.iter().all(|c| c.is_finite()));
    }
}
