//! Spectra and hero-wavelength sampling.
//!
//! A path carries four wavelengths (pbrt-v4's scheme): one sampled from the visible-range
//! importance density of Radziszewski et al. 2009, the other three rotated by a quarter of
//! the sample space, so the four lanes stratify the spectrum.

/// Wavelengths a path carries.
pub const LANES: usize = 4;
/// The sampled range, nm.
pub const LAMBDA_MIN: f32 = 360.0;
/// The sampled range, nm.
pub const LAMBDA_MAX: f32 = 830.0;

/// Four values, one per wavelength lane.
pub type Lanes = [f32; LANES];

/// The four wavelengths of a path and their sampling densities.
#[derive(Clone, Copy, Debug)]
pub struct Wavelengths {
    /// Wavelengths in nm.
    pub lambda: Lanes,
    /// Densities per nm.
    pub pdf: Lanes,
}

/// The visible-importance density (integrates to 1 over [360, 830] nm).
pub fn visible_pdf(l: f32) -> f32 {
    if !(LAMBDA_MIN..=LAMBDA_MAX).contains(&l) {
        return 0.0;
    }
    0.003_939_804 / (0.0072 * (l - 538.0)).cosh().powi(2)
}

impl Wavelengths {
    /// Samples four stratified wavelengths from one uniform number `u`.
    pub fn sample(u: f32) -> Self {
        let mut lambda = [0.0; LANES];
        let mut pdf = [0.0; LANES];
        for i in 0..LANES {
            let ui = (u + i as f32 / LANES as f32).fract();
            let l = 538.0 - 138.888_89 * (0.856_910_6 - 1.827_502 * ui).atanh();
            lambda[i] = l.clamp(LAMBDA_MIN, LAMBDA_MAX);
            pdf[i] = visible_pdf(lambda[i]);
        }
        Self { lambda, pdf }
    }
}

/// A spectral distribution over wavelength.
#[derive(Clone, Debug)]
pub enum Spectrum {
    /// The same value everywhere.
    Constant(f32),
    /// Planck's law at a temperature in K, normalised to a peak of 1.
    Blackbody(f32),
    /// A reflectance built from linear RGB in [0, 1] (see [`Spectrum::eval`]).
    Rgb([f32; 3]),
    /// Gaussian emission lines (centre nm, width nm, height) on a constant floor: a
    /// synthetic spiky lamp, like the CIE F-series (mercury lines plus phosphors).
    Lines {
        /// Value between the lines.
        floor: f32,
        /// (centre nm, width nm, height) per line.
        lines: Vec<(f32, f32, f32)>,
    },
}

fn planck(l_nm: f32, t: f32) -> f32 {
    let l = l_nm as f64 * 1e-9;
    let c1 = 3.741_771_852e-16;
    let c2 = 1.438_776_877e-2;
    (c1 / (l.powi(5) * ((c2 / (l * t as f64)).exp() - 1.0))) as f32
}

/// Smooth partition of unity over blue, green and red: the RGB uplift. Each basis is 1 in
/// its band and blends over 20 nm, so (1, 1, 1) gives exactly 1 and every RGB in [0, 1]
/// gives a reflectance in [0, 1] (energy conserving, unlike unbounded fits).
fn rgb_basis(l: f32) -> [f32; 3] {
    let s = |a: f32, b: f32| ((l - a) / (b - a)).clamp(0.0, 1.0);
    let smooth = |t: f32| t * t * (3.0 - 2.0 * t);
    let to_green = smooth(s(480.0, 500.0));
    let to_red = smooth(s(570.0, 590.0));
    [to_red, to_green * (1.0 - to_red), 1.0 - to_green]
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
            Spectrum::Rgb(c) => {
                let b = rgb_basis(l);
                c[0] * b[0] + c[1] * b[1] + c[2] * b[2]
            }
            Spectrum::Lines { floor, lines } => {
                floor
                    + lines
                        .iter()
                        .map(|&(c, w, h)| h * (-0.5 * ((l - c) / w).powi(2)).exp())
                        .sum::<f32>()
            }
        }
    }

    /// The values at a path's four wavelengths.
    pub fn sample(&self, wl: &Wavelengths) -> Lanes {
        wl.lambda.map(|l| self.eval(l))
    }

    /// Luminance-normalised copy factor: 1 / integral of y-bar times the spectrum, so
    /// emitters of different shapes with the same scale are equally bright.
    pub fn luminance(&self) -> f32 {
        let mut sum = 0.0;
        let mut l = LAMBDA_MIN;
        while l <= LAMBDA_MAX {
            sum += temc::color::spectral::cmf(l as f64)[1] as f32 * self.eval(l);
            l += 1.0;
        }
        sum / cie_y_integral()
    }
}

/// Integral of the CMF fit's y-bar over 360..830 nm at 1 nm steps.
pub fn cie_y_integral() -> f32 {
    let mut sum = 0.0;
    let mut l = LAMBDA_MIN;
    while l <= LAMBDA_MAX {
        sum += temc::color::spectral::cmf(l as f64)[1];
        l += 1.0;
    }
    sum as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn visible_density_integrates_to_one_and_sampling_follows_it() {
        let mut sum = 0.0;
        let mut l = LAMBDA_MIN;
        while l <= LAMBDA_MAX {
            sum += visible_pdf(l) * 0.1;
            l += 0.1;
        }
        assert!((sum - 1.0).abs() < 2e-3, "{sum}");
        // Importance-sampled estimate of the integral of y-bar.
        let n = 20000;
        let mut est = 0.0;
        for k in 0..n {
            let wl = Wavelengths::sample((k as f32 + 0.5) / n as f32);
            for i in 0..LANES {
                est += temc::color::spectral::cmf(wl.lambda[i] as f64)[1] as f32 / wl.pdf[i];
            }
        }
        est /= (n * LANES) as f32;
        assert!((est / cie_y_integral() - 1.0).abs() < 2e-3, "{est}");
    }

    #[test]
    fn rgb_uplift_is_bounded_and_white_is_flat() {
        for l in (360..=830).step_by(5) {
            let l = l as f32;
            assert!((Spectrum::Rgb([1.0; 3]).eval(l) - 1.0).abs() < 1e-6);
            for c in [[1.0, 0.0, 0.0], [0.2, 0.9, 0.4], [0.0, 0.0, 0.0]] {
                let v = Spectrum::Rgb(c).eval(l);
                assert!((0.0..=1.0).contains(&v));
            }
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
