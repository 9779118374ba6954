//! The wavelengths a path carries (pbrt-v4's hero-wavelength scheme): one sampled from the
//! visible-range importance density of Radziszewski et al. 2009, the other three rotated
//! by a quarter of the sample space, so the four lanes stratify the spectrum.

/// Wavelengths a path carries.
pub const LANES: usize = 4;
/// The sampled range, nm.
pub const LAMBDA_MIN: f32 = 360.0;
/// The sampled range, nm.
pub const LAMBDA_MAX: f32 = 830.0;

/// Four values, one per wavelength lane.
pub type Lanes = [f32; LANES];

/// Per-lane product.
pub fn mul(a: Lanes, b: Lanes) -> Lanes {
    std::array::from_fn(|i| a[i] * b[i])
}

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
                est += temc_color::cie::cmf_tabulated(wl.lambda[i] as f64)[1] as f32 / wl.pdf[i];
            }
        }
        est /= (n * LANES) as f32;
        assert!(
            (est / crate::spectral::spectrum::cie_y_integral() - 1.0).abs() < 2e-3,
            "{est}"
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
}
