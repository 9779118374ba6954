//! Indices of refraction as functions of wavelength: constant, Cauchy and Sellmeier, with
//! tables, with the two Schott glasses the scenes name.

use crate::spectral::spectrum::Spectrum;

/// Index of refraction as a function of wavelength.
#[derive(Clone, Debug)]
pub enum Ior {
    /// The same at every wavelength (no dispersion).
    Constant(f32),
    /// Cauchy: n = a + b / lambda^2, lambda in micrometres.
    Cauchy {
        /// Constant term.
        a: f32,
        /// Coefficient of 1/lambda^2 (um^2).
        b: f32,
    },
    /// Sellmeier: n^2 = 1 + sum B_i lambda^2 / (lambda^2 - C_i), lambda in micrometres.
    Sellmeier {
        /// B coefficients.
        b: [f32; 3],
        /// C coefficients (um^2).
        c: [f32; 3],
    },
    /// Measured: n tabulated against wavelength.
    Tabulated(Spectrum),
}

/// Schott N-BK7 (Abbe number about 64: faint rainbows).
pub const BK7: Ior = Ior::Sellmeier {
    b: [1.039_612, 0.231_792_34, 1.010_469_4],
    c: [0.006_000_699, 0.020_017_914, 103.560_65],
};
/// Schott N-SF11 (Abbe number about 25.7: strong rainbows).
pub const SF11: Ior = Ior::Sellmeier {
    b: [1.737_597, 0.313_747_35, 1.898_781],
    c: [0.013_188_707, 0.062_306_814, 155.236_3],
};

impl Ior {
    /// n at `l` nm.
    pub fn eval(&self, l: f32) -> f32 {
        let um = l * 1e-3;
        match self {
            Ior::Constant(n) => *n,
            Ior::Cauchy { a, b } => a + b / (um * um),
            Ior::Tabulated(s) => s.eval(l),
            Ior::Sellmeier { b, c } => {
                let l2 = um * um;
                (1.0 + (0..3).map(|i| b[i] * l2 / (l2 - c[i])).sum::<f32>()).sqrt()
            }
        }
    }

    /// Whether n depends on wavelength (then refraction splits the wavelengths).
    pub fn dispersive(&self) -> bool {
        match self {
            Ior::Constant(_) => false,
            Ior::Tabulated(Spectrum::Sampled(t)) => t.iter().any(|p| p.1 != t[0].1),
            _ => true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sellmeier_matches_catalogue_indices() {
        // n_d at 587.6 nm from the Schott catalogue.
        assert!((BK7.eval(587.56) - 1.5168).abs() < 2e-4);
        assert!((SF11.eval(587.56) - 1.7847).abs() < 2e-4);
        assert!(SF11.eval(450.0) > SF11.eval(650.0));
    }
}
