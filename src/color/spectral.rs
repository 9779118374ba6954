//! N spectral bands -> CIE XYZ -> linear sRGB.
//!
//! A spectral renderer can hand temc its per-band radiance instead of RGB, so that the
//! conversion to colour happens once, here, with the same numbers as in training.
//!
//! The CIE 1931 2-degree colour matching functions are the multi-lobe piecewise-Gaussian fit
//! of Wyman, Sloan and Shirley, "Simple Analytic Approximations to the CIE XYZ Color Matching
//! Functions", JCGT 2(2), 2013. Its error against the tabulated CIE 1931 2-degree observer
//! (1 nm, 360..830 nm), measured by `training/tests/test_cmf.py`: at most 0.015, 0.0076 and
//! 0.024 absolute for x-bar, y-bar and z-bar (whose peaks are about 1.06, 1.0 and 1.78);
//! integrated over a flat, a ramp, a 3000 K blackbody and a green band spectrum, XYZ is
//! within 0.33 % of Y of the tabulated result.

use crate::Error;

/// The visible range the normalisation integrates over, in nm.
pub const VISIBLE_NM: (f64, f64) = (360.0, 830.0);

/// XYZ -> linear sRGB (IEC 61966-2-1, D65 white), rows R, G, B.
pub const XYZ_TO_SRGB: [[f64; 3]; 3] = [
    [3.2406, -1.5372, -0.4986],
    [-0.9689, 1.8758, 0.0415],
    [0.0557, -0.2040, 1.0570],
];

/// A lobe of the fit: a Gaussian with different widths left and right of its mean.
fn lobe(lambda: f64, mean: f64, sigma_left: f64, sigma_right: f64) -> f64 {
    let s = if lambda < mean {
        sigma_left
    } else {
        sigma_right
    };
    let t = (lambda - mean) / s;
    (-0.5 * t * t).exp()
}

/// The CIE 1931 2-degree colour matching functions (x-bar, y-bar, z-bar) at `lambda` nm.
pub fn cmf(lambda: f64) -> [f64; 3] {
    let x = 1.056 * lobe(lambda, 599.8, 37.9, 31.0) + 0.362 * lobe(lambda, 442.0, 16.0, 26.7)
        - 0.065 * lobe(lambda, 501.1, 20.4, 26.2);
    let y = 0.821 * lobe(lambda, 568.8, 46.9, 40.5) + 0.286 * lobe(lambda, 530.9, 16.3, 31.1);
    let z = 1.217 * lobe(lambda, 437.0, 11.8, 36.0) + 0.681 * lobe(lambda, 459.0, 26.0, 13.8);
    [x, y, z]
}

/// Integral of the CMFs over [a, b] nm, composite Simpson with steps of at most 0.5 nm
/// (the fit is smooth except for the kinks at each lobe's mean, which this resolves well).
pub fn cmf_integral(a: f64, b: f64) -> [f64; 3] {
    if b <= a {
        return [0.0; 3];
    }
    let n = (((b - a) / 0.5).ceil() as usize).max(1) * 2;
    let h = (b - a) / n as f64;
    let mut acc = [0.0; 3];
    for i in 0..=n {
        let w = if i == 0 || i == n {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        };
        let c = cmf(a + i as f64 * h);
        for k in 0..3 {
            acc[k] += w * c[k];
        }
    }
    acc.map(|v| v * h / 3.0)
}

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
    /// flat spectrum of 1.0 over 360..830 nm has Y = 1.
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
        let y_norm = cmf_integral(VISIBLE_NM.0, VISIBLE_NM.1)[1];
        let weights = edges
            .windows(2)
            .map(|w| cmf_integral(w[0] as f64, w[1] as f64).map(|v| v / y_norm))
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

/// CIE XYZ -> linear sRGB with [`XYZ_TO_SRGB`].
pub fn xyz_to_linear_srgb(xyz: [f64; 3]) -> [f32; 3] {
    XYZ_TO_SRGB.map(|row| (row[0] * xyz[0] + row[1] * xyz[1] + row[2] * xyz[2]) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_has_the_known_peaks() {
        // y-bar peaks near 555 nm at about 1; x-bar's main lobe near 600 nm; z-bar near 445.
        let y555 = cmf(555.0)[1];
        assert!((y555 - 1.0).abs() < 0.02, "{y555}");
        assert!(cmf(600.0)[0] > 1.0 && cmf(600.0)[0] < 1.1);
        assert!(cmf(445.0)[2] > 1.7 && cmf(445.0)[2] < 1.8);
        assert!(cmf(830.0).iter().all(|v| v.abs() < 1e-3));
    }

    #[test]
    fn integrals_match_the_cie_totals() {
        // The tabulated CIE 1931 CMFs each integrate to about 106.86 over 360..830 nm.
        let t = cmf_integral(360.0, 830.0);
        for v in t {
            assert!((v - 106.86).abs() / 106.86 < 0.01, "{t:?}");
        }
    }

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
