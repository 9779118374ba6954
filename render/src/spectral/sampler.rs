//! How a render picks its wavelengths: a table built from the visible-importance density
//! and the emitters' spectra, so line spectra get samples and smooth ones lose nothing;
//! or, to imitate a naive spectral renderer, one uniform wavelength per path.

use crate::spectral::spectrum::Spectrum;
use crate::spectral::wavelengths::{visible_pdf, Wavelengths, LAMBDA_MAX, LAMBDA_MIN, LANES};

/// How a render picks its wavelengths.
#[derive(Clone, Debug)]
pub enum LambdaSampler {
    /// A tabulated density, half visible-importance and half the emitters' spectra
    /// weighted by the colour matching functions: spiky lamps and lasers then get samples
    /// on their lines. Piecewise constant over `BIN` nm bins.
    Table {
        /// Density per bin (per nm).
        pdf: Vec<f32>,
        /// Cumulative distribution at bin ends (last = 1).
        cdf: Vec<f32>,
        /// For each of `GUIDE` equal steps of u, the first bin whose end lies past the
        /// step's start: the search starts there instead of bisecting the whole table.
        guide: Vec<u32>,
    },
    /// One wavelength per path, uniform over the sampled range: the naive spectral
    /// renderer's way, kept to imitate its colour noise (`Sampling::uniform_wavelength`).
    Uniform,
}

const GUIDE: usize = 1024;

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
                    let c = temc_color::cie::cmf_tabulated(l as f64);
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
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        let guide = (0..GUIDE)
            .map(|k| cdf.partition_point(|&c| c <= k as f32 / GUIDE as f32) as u32)
            .collect();
        LambdaSampler::Table {
            pdf: pdf.iter().map(|p| (p / total) as f32).collect(),
            cdf,
            guide,
        }
    }

    /// Four stratified wavelengths from one uniform number.
    pub fn sample(&self, u: f32) -> Wavelengths {
        match self {
            LambdaSampler::Table { pdf, cdf, guide } => {
                let mut wl = Wavelengths {
                    lambda: [0.0; LANES],
                    pdf: [0.0; LANES],
                };
                for i in 0..LANES {
                    let ui = wrap(u + i as f32 / LANES as f32);
                    let k = ((ui * GUIDE as f32) as usize).min(GUIDE - 1);
                    let lo = guide[k] as usize;
                    let hi = guide.get(k + 1).map_or(cdf.len(), |&g| g as usize + 1);
                    let hi = hi.min(cdf.len());
                    let b = (lo + cdf[lo..hi].partition_point(|&c| c <= ui)).min(cdf.len() - 1);
                    let lo = if b == 0 { 0.0 } else { cdf[b - 1] };
                    let f = ((ui - lo) / (cdf[b] - lo).max(1e-12)).clamp(0.0, 1.0);
                    wl.lambda[i] = LAMBDA_MIN + (b as f32 + f) * BIN;
                    wl.pdf[i] = pdf[b];
                }
                wl
            }
            LambdaSampler::Uniform => {
                let range = LAMBDA_MAX - LAMBDA_MIN;
                let mut wl = Wavelengths {
                    lambda: std::array::from_fn(|i| {
                        LAMBDA_MIN + wrap(u + i as f32 / LANES as f32) * range
                    }),
                    pdf: [1.0 / range; LANES],
                };
                // Only the hero goes on, with four times the weight: one wavelength.
                wl.terminate_secondary();
                wl
            }
        }
    }
}

/// `x.fract()` for `x` in [0, 2), the stratified lanes' range, to the bit: `fract` is a
/// libm call per lane on baseline x86_64 (no SSE4.1 rounding), 5 % of a render's time
/// with the search.
#[inline]
fn wrap(x: f32) -> f32 {
    if x >= 1.0 {
        x - 1.0
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_sampler_draws_one_wavelength_over_the_range() {
        // The film weighs a lane by 1 / (pdf x LANES): one uniform wavelength then
        // estimates the integral of y-bar over the range.
        let n = 20000;
        let mut est = 0.0f64;
        for k in 0..n {
            let wl = LambdaSampler::Uniform.sample((k as f32 + 0.5) / n as f32);
            assert!(wl.terminated());
            let y = temc_color::cie::cmf_tabulated(wl.lambda[0] as f64)[1];
            est += y / (wl.pdf[0] as f64 * LANES as f64);
        }
        est /= n as f64;
        let exact = crate::spectral::spectrum::cie_y_integral() as f64;
        assert!((est / exact - 1.0).abs() < 2e-3, "{est} vs {exact}");
    }

    #[test]
    fn tabulated_sampler_integrates_spiky_spectra() {
        let lamp = Spectrum::fluorescent();
        let sampler = LambdaSampler::for_emitters(&[&lamp]);
        let LambdaSampler::Table { pdf, cdf, .. } = &sampler else {
            panic!("a table");
        };
        assert!((pdf.iter().sum::<f32>() * BIN - 1.0).abs() < 1e-3);
        // Estimate the integral of ybar * lamp both ways; the table's estimate must agree
        // with a fine quadrature.
        let mut exact = 0.0f64;
        let mut l = LAMBDA_MIN;
        while l < LAMBDA_MAX {
            exact += (temc_color::cie::cmf_tabulated(l as f64)[1] * lamp.eval(l) as f64) * 0.01;
            l += 0.01;
        }
        let n = 40000;
        let mut est = 0.0f64;
        for k in 0..n {
            let wl = sampler.sample((k as f32 + 0.5) / n as f32);
            for i in 0..LANES {
                let y = temc_color::cie::cmf_tabulated(wl.lambda[i] as f64)[1];
                est += y * lamp.eval(wl.lambda[i]) as f64 / wl.pdf[i] as f64;
            }
        }
        est /= (n * LANES) as f64;
        assert!((est / exact - 1.0).abs() < 5e-3, "{est} vs {exact}");
        // The guided search finds the bin bisection finds.
        for k in 0..10_000 {
            let u = k as f32 / 10_000.0;
            let wl = sampler.sample(u);
            let b = cdf.partition_point(|&c| c <= u).min(cdf.len() - 1);
            let lo = LAMBDA_MIN + b as f32 * BIN;
            assert!(
                wl.lambda[0] >= lo - 1e-3 && wl.lambda[0] <= lo + BIN + 1e-3,
                "{u}"
            );
        }
    }
}
