//! The CIE 1931 2-degree standard observer, and CIE XYZ -> linear sRGB.
//!
//! The colour matching functions are the multi-lobe piecewise-Gaussian fit of Wyman, Sloan
//! and Shirley, "Simple Analytic Approximations to the CIE XYZ Color Matching Functions",
//! JCGT 2(2), 2013. Its error against the tabulated CIE 1931 2-degree observer (1 nm,
//! 360..830 nm), measured by `training/tests/test_cmf.py`: at most 0.015, 0.0076 and 0.024
//! absolute for x-bar, y-bar and z-bar (whose peaks are about 1.06, 1.0 and 1.78);
//! integrated over a flat, a ramp, a 3000 K blackbody and a green band spectrum, XYZ is
//! within 0.33 % of Y of the tabulated result.

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

/// Step of [`cmf_fast`]'s table, nm.
const TABLE_STEP: f32 = 0.1;

/// The CMFs at `lambda` nm (clamped to [`VISIBLE_NM`]) from a table of [`cmf`] every
/// 0.1 nm, linearly interpolated: within 2e-5 of the fit (a test checks) at a fraction of
/// its cost (eight exponentials), for the renderer's film, which converts every path.
pub fn cmf_fast(lambda: f32) -> [f32; 3] {
    static TABLE: std::sync::OnceLock<Vec<[f32; 3]>> = std::sync::OnceLock::new();
    let t = TABLE.get_or_init(|| {
        let n = ((VISIBLE_NM.1 - VISIBLE_NM.0) / TABLE_STEP as f64).round() as usize;
        (0..=n)
            .map(|i| cmf(VISIBLE_NM.0 + i as f64 * TABLE_STEP as f64).map(|v| v as f32))
            .collect()
    });
    let x = ((lambda - VISIBLE_NM.0 as f32) / TABLE_STEP).clamp(0.0, (t.len() - 1) as f32);
    let i = (x as usize).min(t.len() - 2);
    let f = x - i as f32;
    std::array::from_fn(|k| t[i][k] + (t[i + 1][k] - t[i][k]) * f)
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

/// CIE XYZ -> linear sRGB with [`XYZ_TO_SRGB`].
pub fn xyz_to_linear_srgb(xyz: [f64; 3]) -> [f32; 3] {
    XYZ_TO_SRGB.map(|row| (row[0] * xyz[0] + row[1] * xyz[1] + row[2] * xyz[2]) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_follows_the_fit() {
        let mut worst = 0.0f64;
        for i in 0..47_000 {
            let l = 360.0 + i as f64 * 0.01;
            let (a, b) = (cmf(l), cmf_fast(l as f32));
            for k in 0..3 {
                worst = worst.max((a[k] - b[k] as f64).abs());
            }
        }
        assert!(worst < 2e-5, "{worst}");
        assert_eq!(cmf_fast(100.0), cmf_fast(360.0));
    }

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
}
