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
    /// Keeps only the hero wavelength (pbrt-v4's rule for wavelength-dependent directions):
    /// the other lanes stop contributing and the hero's weight grows fourfold, so the
    /// estimate stays unbiased.
    pub fn terminate_secondary(&mut self) {
        if self.pdf[1] == 0.0 {
            return;
        }
        for p in &mut self.pdf[1..] {
            *p = 0.0;
        }
        self.pdf[0] /= LANES as f32;
    }

    /// Whether only the hero wavelength is left.
    pub fn terminated(&self) -> bool {
        self.pdf[1] == 0.0
    }

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

/// How a render picks its wavelengths.
#[derive(Clone, Debug)]
pub enum LambdaSampler {
    /// The visible-importance density: right for smooth emitters.
    Visible,
    /// A tabulated density, half visible-importance and half the emitters' spectra
    /// weighted by the colour matching functions: spiky lamps and lasers then get samples
    /// on their lines. Piecewise constant over `BIN` nm bins.
    Table {
        /// Density per bin (per nm).
        pdf: Vec<f32>,
        /// Cumulative distribution at bin ends (last = 1).
        cdf: Vec<f32>,
    },
}

const BIN: f32 = 0.25;

impl LambdaSampler {
    /// A sampler for a scene whose emitters have these spectra.
    pub fn for_emitters(emitters: &[&Spectrum]) -> Self {
        let n = ((LAMBDA_MAX - LAMBDA_MIN) / BIN) as usize;
        let centre = |i: usize| LAMBDA_MIN + (i as f32 + 0.5) * BIN;
        let mut mix = vec![0.0f64; n];
        for s in emitters {
            let w: Vec<f64> = (0..n)
                .map(|i| {
                    let l = centre(i);
                    let c = temc::color::spectral::cmf(l as f64);
                    s.eval(l).max(0.0) as f64 * (c[0] + c[1] + c[2])
                })
                .collect();
            let total: f64 = w.iter().sum::<f64>() * BIN as f64;
            if total > 0.0 {
                for (m, v) in mix.iter_mut().zip(w) {
                    *m += v / total / emitters.len() as f64;
                }
            }
        }
        let pdf: Vec<f64> = (0..n)
            .map(|i| 0.5 * visible_pdf(centre(i)) as f64 + 0.5 * mix[i])
            .collect();
        let total: f64 = pdf.iter().sum::<f64>() * BIN as f64;
        let mut acc = 0.0;
        let mut cdf = Vec::with_capacity(n);
        for p in &pdf {
            acc += p / total * BIN as f64;
            cdf.push(acc as f32);
        }
        *cdf.last_mut().unwrap() = 1.0;
        LambdaSampler::Table {
            pdf: pdf.iter().map(|p| (p / total) as f32).collect(),
            cdf,
        }
    }

    /// Four stratified wavelengths from one uniform number.
    pub fn sample(&self, u: f32) -> Wavelengths {
        match self {
            LambdaSampler::Visible => Wavelengths::sample(u),
            LambdaSampler::Table { pdf, cdf } => {
                let mut wl = Wavelengths {
                    lambda: [0.0; LANES],
                    pdf: [0.0; LANES],
                };
                for i in 0..LANES {
                    let ui = (u + i as f32 / LANES as f32).fract();
                    let b = cdf.partition_point(|&c| c <= ui).min(cdf.len() - 1);
                    let lo = if b == 0 { 0.0 } else { cdf[b - 1] };
                    let f = ((ui - lo) / (cdf[b] - lo).max(1e-12)).clamp(0.0, 1.0);
                    wl.lambda[i] = LAMBDA_MIN + (b as f32 + f) * BIN;
                    wl.pdf[i] = pdf[b];
                }
                wl
            }
        }
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
    /// Piecewise-linear samples every 10 nm from 360 nm (measured data), held flat
    /// outside the table.
    Tabulated(&'static [f32; 48]),
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
            Spectrum::Tabulated(t) => {
                let x = ((l - 360.0) / 10.0).clamp(0.0, 47.0);
                let i = (x as usize).min(46);
                let f = x - i as f32;
                t[i] * (1.0 - f) + t[i + 1] * f
            }
        }
    }

    /// CIE standard illuminant D65.
    pub fn d65() -> Self {
        Spectrum::Tabulated(&crate::measured::D65)
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
        matches!(self, Spectrum::Lines { lines, .. } if lines.iter().any(|l| l.1 < 10.0))
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
    fn tabulated_sampler_integrates_spiky_spectra() {
        let lamp = crate::scene::spiky_lamp();
        let sampler = LambdaSampler::for_emitters(&[&lamp]);
        let LambdaSampler::Table { pdf, .. } = &sampler else {
            unreachable!()
        };
        assert!((pdf.iter().sum::<f32>() * BIN - 1.0).abs() < 1e-3);
        // Estimate the integral of ybar * lamp both ways; the table's estimate must agree
        // with a fine quadrature.
        let mut exact = 0.0f64;
        let mut l = LAMBDA_MIN;
        while l < LAMBDA_MAX {
            exact += (temc::color::spectral::cmf(l as f64)[1] * lamp.eval(l) as f64) * 0.01;
            l += 0.01;
        }
        let n = 40000;
        let mut est = 0.0f64;
        for k in 0..n {
            let wl = sampler.sample((k as f32 + 0.5) / n as f32);
            for i in 0..LANES {
                let y = temc::color::spectral::cmf(wl.lambda[i] as f64)[1];
                est += y * lamp.eval(wl.lambda[i]) as f64 / wl.pdf[i] as f64;
            }
        }
        est /= (n * LANES) as f64;
        assert!((est / exact - 1.0).abs() < 5e-3, "{est} vs {exact}");
    }

    #[test]
    fn d65_is_near_its_white_point() {
        let d65 = Spectrum::d65();
        let (mut x, mut y, mut z) = (0.0, 0.0, 0.0);
        for l in 360..=830 {
            let c = temc::color::spectral::cmf(l as f64);
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
    fn termination_keeps_the_hero_with_four_times_the_weight() {
        let mut wl = Wavelengths::sample(0.3);
        let p0 = wl.pdf[0];
        wl.terminate_secondary();
        assert!(wl.terminated());
        assert_eq!(wl.pdf[0], p0 / 4.0);
        assert_eq!(&wl.pdf[1..], &[0.0; 3]);
        wl.terminate_secondary();
        assert_eq!(wl.pdf[0], p0 / 4.0);
    }

    #[test]
    fn blackbody_peaks_at_one() {
        let s = Spectrum::Blackbody(5000.0);
        let peak = 2.897_772e6 / 5000.0;
        assert!((s.eval(peak) - 1.0).abs() < 1e-4);
        assert!(s.eval(400.0) < 1.0 && s.eval(800.0) < 1.0);
    }
}
