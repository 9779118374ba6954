//! Spectral distributions: constants, blackbodies, uplifted RGB reflectances and emitters,
//! emission lines and measured tables.

use std::sync::Arc;

use crate::spectral::uplift::{self, Illuminant, SigmoidPoly};
use crate::spectral::wavelengths::{Lanes, Wavelengths, LAMBDA_MAX, LAMBDA_MIN, LANES};

/// A spectral distribution over wavelength.
#[derive(Clone, Debug)]
pub enum Spectrum {
    /// The same value everywhere.
    Constant(f32),
    /// Planck's law at a temperature in K, normalised to a peak of 1.
    Blackbody(f32),
    /// A reflectance given as linear sRGB in [0, 1], uplifted smoothly (Jakob & Hanika
    /// 2019, [`uplift::reflectance`]).
    RgbReflectance(SigmoidPoly),
    /// An emitter given as linear sRGB: a smooth spectrum times D65 ([`uplift::illuminant`]).
    RgbIlluminant(Illuminant),
    /// Gaussian emission lines (centre nm, width nm, height) on a constant floor: a
    /// synthetic spiky lamp, like the CIE F-series (mercury lines plus phosphors).
    Lines {
        /// Value between the lines.
        floor: f32,
        /// (centre nm, width nm, height) per line.
        lines: Vec<(f32, f32, f32)>,
    },
    /// Piecewise-linear samples every 10 nm from 360 nm (measured data), held flat
    /// outside the table.
    Tabulated(&'static [f32; 48]),
    /// Piecewise-linear (wavelength nm, value) pairs with increasing wavelengths, held flat
    /// outside the table: measured data a scene file gives inline or from a CSV file.
    Sampled(Arc<[(f32, f32)]>),
    /// An analytic spectrum tabulated finely over the renderer's range (see
    /// [`Spectrum::dense`]).
    Dense(Arc<Dense>),
}

/// Values every `1 / inv_step` nm from [`LAMBDA_MIN`] to [`LAMBDA_MAX`], interpolated
/// linearly: what a scene stores for a blackbody or a line spectrum, whose exp calls were
/// the hot path's most expensive arithmetic under such lamps.
#[derive(Debug)]
pub struct Dense {
    values: Box<[f32]>,
    inv_step: f32,
    /// The analytic spectrum's [`Spectrum::is_spiky`].
    spiky: bool,
}

impl Dense {
    #[inline]
    fn eval(&self, l: f32) -> f32 {
        let x = ((l - LAMBDA_MIN) * self.inv_step).clamp(0.0, (self.values.len() - 1) as f32);
        let i = (x as usize).min(self.values.len() - 2);
        let f = x - i as f32;
        self.values[i] * (1.0 - f) + self.values[i + 1] * f
    }
}

fn planck(l_nm: f32, t: f32) -> f32 {
    let l = l_nm as f64 * 1e-9;
    let c1 = 3.741_771_852e-16;
    let c2 = 1.438_776_877e-2;
    (c1 / (l.powi(5) * ((c2 / (l * t as f64)).exp() - 1.0))) as f32
}

impl Spectrum {
    /// The value at `l` nm.
    pub fn eval(&self, l: f32) -> f32 {
        match self {
            Spectrum::Constant(v) => *v,
            Spectrum::Blackbody(t) => {
                let peak = 2.897_772e6 / t; // Wien's displacement law, nm
                planck(l, *t) / planck(peak, *t)
            }
            Spectrum::RgbReflectance(p) => p.eval(l),
            Spectrum::RgbIlluminant(e) => e.eval(l),
            Spectrum::Lines { floor, lines } => {
                // Past 8 widths a line is below 1e-14 of its height: skip its exp (the
                // hot path's most expensive call under a spiky lamp).
                floor
                    + lines
                        .iter()
                        .filter(|&&(c, w, _)| (l - c).abs() < 8.0 * w)
                        .map(|&(c, w, h)| h * (-0.5 * ((l - c) / w).powi(2)).exp())
                        .sum::<f32>()
            }
            Spectrum::Tabulated(t) => {
                let x = ((l - 360.0) / 10.0).clamp(0.0, 47.0);
                let i = (x as usize).min(46);
                let f = x - i as f32;
                t[i] * (1.0 - f) + t[i + 1] * f
            }
            Spectrum::Sampled(t) => sampled(t, l),
            Spectrum::Dense(t) => t.eval(l),
        }
    }

    /// The spectrum as a scene stores it: blackbodies and line spectra tabulated (a
    /// blackbody every 0.5 nm, lines at a sixteenth of the narrowest width, at least
    /// 0.005 nm, so the interpolation error stays below about 0.05 % of a line's peak);
    /// every other kind as it is.
    pub fn dense(&self) -> Spectrum {
        let step = match self {
            Spectrum::Blackbody(_) => 0.5,
            Spectrum::Lines { lines, .. } => lines
                .iter()
                .map(|l| l.1 / 16.0)
                .fold(0.5f32, f32::min)
                .max(0.005),
            _ => return self.clone(),
        };
        let n = ((LAMBDA_MAX - LAMBDA_MIN) / step).ceil() as usize + 1;
        let values = (0..n)
            .map(|k| self.eval(LAMBDA_MIN + k as f32 * step))
            .collect();
        Spectrum::Dense(Arc::new(Dense {
            values,
            inv_step: 1.0 / step,
            spiky: self.is_spiky(),
        }))
    }

    /// The reflectance of linear sRGB `rgb` (clamped to [0, 1]).
    pub fn rgb_reflectance(rgb: [f32; 3]) -> Self {
        Spectrum::RgbReflectance(uplift::reflectance(rgb))
    }

    /// An emitter of linear sRGB `rgb`: seen directly, its colour is `rgb`.
    pub fn rgb_illuminant(rgb: [f32; 3]) -> Self {
        Spectrum::RgbIlluminant(uplift::illuminant(rgb))
    }

    /// CIE standard illuminant D65.
    pub fn d65() -> Self {
        Spectrum::Tabulated(&crate::spectral::measured::D65)
    }

    /// A synthetic fluorescent lamp: mercury lines and narrow phosphor bands over a low
    /// floor, balanced to a cool white (chromaticity about x 0.361, y 0.357, near 4500 K).
    pub fn fluorescent() -> Self {
        Spectrum::Lines {
            floor: 0.03,
            lines: vec![
                (404.7, 1.5, 0.5),
                (435.8, 1.5, 1.3),
                (487.0, 4.0, 0.5),
                (546.1, 1.5, 2.1),
                (578.0, 2.0, 0.5),
                (611.0, 3.0, 1.1),
            ],
        }
    }

    /// A narrow-band laser line: a Gaussian of standard deviation `width` nm.
    pub fn laser(centre: f32, width: f32) -> Self {
        Spectrum::Lines {
            floor: 0.0,
            lines: vec![(centre, width, 1.0)],
        }
    }

    /// Whether the spectrum has narrow peaks that visible-range sampling would miss
    /// (line lamps, lasers): such emitters make the renderer sample wavelengths from the
    /// emitters' own spectra.
    pub fn is_spiky(&self) -> bool {
        match self {
            Spectrum::Lines { lines, .. } => lines.iter().any(|l| l.1 < 10.0),
            // A measured line: a value at least twice its neighbour's within 10 nm.
            Spectrum::Sampled(t) => t.windows(2).any(|w| {
                let (lo, hi) = (w[0].1.min(w[1].1), w[0].1.max(w[1].1));
                w[1].0 - w[0].0 < 10.0 && hi > 2.0 * lo
            }),
            Spectrum::Dense(t) => t.spiky,
            _ => false,
        }
    }

    /// A spectrum from (wavelength nm, value) pairs: at least two, wavelengths strictly
    /// increasing within 200..2000 nm, values finite and in `range`.
    pub fn sampled(points: Vec<(f32, f32)>, range: (f32, f32)) -> Result<Self, String> {
        if points.len() < 2 {
            return Err("a table needs at least two (nm, value) pairs".into());
        }
        for (k, &(l, v)) in points.iter().enumerate() {
            if !(200.0..=2000.0).contains(&l) {
                return Err(format!("wavelength {l} nm is outside 200..2000"));
            }
            if k > 0 && l <= points[k - 1].0 {
                return Err(format!(
                    "wavelengths must increase: {l} nm after {} nm",
                    points[k - 1].0
                ));
            }
            if !(v.is_finite() && (range.0..=range.1).contains(&v)) {
                return Err(format!(
                    "value {v} at {l} nm is outside {}..{}",
                    range.0, range.1
                ));
            }
        }
        Ok(Spectrum::Sampled(points.into()))
    }

    /// The values at a path's four wavelengths.
    pub fn sample(&self, wl: &Wavelengths) -> Lanes {
        // One dispatch for the four lanes on the kinds the hot path meets most.
        match self {
            Spectrum::Constant(v) => [*v; LANES],
            Spectrum::RgbReflectance(p) => wl.lambda.map(|l| p.eval(l)),
            Spectrum::Dense(t) => wl.lambda.map(|l| t.eval(l)),
            _ => wl.lambda.map(|l| self.eval(l)),
        }
    }

    /// Luminance-normalised copy factor: 1 / integral of y-bar times the spectrum, so
    /// emitters of different shapes with the same scale are equally bright.
    pub fn luminance(&self) -> f32 {
        let mut sum = 0.0;
        let mut l = LAMBDA_MIN;
        while l <= LAMBDA_MAX {
            sum += temc_color::cie::cmf_tabulated(l as f64)[1] as f32 * self.eval(l);
            l += 1.0;
        }
        sum / cie_y_integral()
    }
}

/// Piecewise-linear interpolation in a table of increasing wavelengths, flat outside.
fn sampled(t: &[(f32, f32)], l: f32) -> f32 {
    let k = t.partition_point(|p| p.0 < l);
    if k == 0 {
        return t[0].1;
    }
    if k == t.len() {
        return t[k - 1].1;
    }
    let ((l0, v0), (l1, v1)) = (t[k - 1], t[k]);
    v0 + (v1 - v0) * (l - l0) / (l1 - l0)
}

/// Integral of the CMF fit's y-bar over 360..830 nm at 1 nm steps.
pub fn cie_y_integral() -> f32 {
    let mut sum = 0.0;
    let mut l = LAMBDA_MIN;
    while l <= LAMBDA_MAX {
        sum += temc_color::cie::cmf_tabulated(l as f64)[1];
        l += 1.0;
    }
    sum as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rgb_reflectances_are_bounded_and_white_is_flat() {
        for l in (360..=830).step_by(5) {
            let l = l as f32;
            assert!((Spectrum::rgb_reflectance([1.0; 3]).eval(l) - 1.0).abs() < 1e-4);
            for c in [[1.0, 0.0, 0.0], [0.2, 0.9, 0.4], [0.0, 0.0, 0.0]] {
                let v = Spectrum::rgb_reflectance(c).eval(l);
                assert!((0.0..=1.0).contains(&v));
            }
        }
    }

    #[test]
    fn dense_spectra_follow_the_analytic_ones() {
        for s in [
            Spectrum::fluorescent(),
            Spectrum::laser(532.0, 0.3),
            Spectrum::Blackbody(2700.0),
            Spectrum::Blackbody(9000.0),
        ] {
            let d = s.dense();
            assert!(matches!(d, Spectrum::Dense(_)) && d.is_spiky() == s.is_spiky());
            let peak = (0..=47000)
                .map(|k| s.eval(360.0 + k as f32 * 0.01))
                .fold(0.0, f32::max);
            for k in 0..=47000 {
                let l = 360.0 + k as f32 * 0.01;
                let err = (d.eval(l) - s.eval(l)).abs();
                assert!(
                    err <= 1e-3 * peak,
                    "{s:?} at {l} nm: {} vs {}",
                    d.eval(l),
                    s.eval(l)
                );
            }
        }
        assert!(matches!(
            Spectrum::Constant(2.0).dense(),
            Spectrum::Constant(_)
        ));
    }

    #[test]
    fn d65_is_near_its_white_point() {
        let d65 = Spectrum::d65();
        let (mut x, mut y, mut z) = (0.0, 0.0, 0.0);
        for l in 360..=830 {
            let c = temc_color::cie::cmf_tabulated(l as f64);
            let v = d65.eval(l as f32) as f64;
            x += c[0] * v;
            y += c[1] * v;
            z += c[2] * v;
        }
        let (cx, cy) = (x / (x + y + z), y / (x + y + z));
        // D65's nominal chromaticity is (0.3127, 0.3290); the analytic CMF fit is close.
        assert!(
            (cx - 0.3127).abs() < 0.004 && (cy - 0.3290).abs() < 0.004,
            "{cx} {cy}"
        );
    }

    #[test]
    fn sampled_spectra_interpolate_and_find_their_lines() {
        let s =
            Spectrum::sampled(vec![(400.0, 0.0), (500.0, 1.0), (600.0, 0.5)], (0.0, 1.0)).unwrap();
        assert_eq!(s.eval(300.0), 0.0);
        assert!((s.eval(450.0) - 0.5).abs() < 1e-6);
        assert!((s.eval(550.0) - 0.75).abs() < 1e-6);
        assert_eq!(s.eval(900.0), 0.5);
        assert!(!s.is_spiky());
        let line = vec![(540.0, 0.1), (545.0, 10.0), (550.0, 0.1)];
        assert!(Spectrum::sampled(line, (0.0, f32::MAX)).unwrap().is_spiky());
        for (bad, msg) in [
            (vec![(400.0, 0.5)], "at least two"),
            (vec![(500.0, 0.5), (400.0, 0.5)], "must increase"),
            (vec![(400.0, 0.5), (500.0, 1.5)], "outside 0..1"),
            (vec![(100.0, 0.5), (500.0, 0.5)], "200..2000"),
        ] {
            let e = Spectrum::sampled(bad, (0.0, 1.0)).unwrap_err();
            assert!(e.contains(msg), "{e}");
        }
    }

    #[test]
    fn blackbody_peaks_at_one() {
        let s = Spectrum::Blackbody(5000.0);
        let peak = 2.897_772e6 / 5000.0;
        assert!((s.eval(peak) - 1.0).abs() < 1e-4);
        assert!(s.eval(400.0) < 1.0 && s.eval(800.0) < 1.0);
    }
}
