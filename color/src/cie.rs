//! The CIE 1931 2-degree standard observer, and CIE XYZ -> linear sRGB.
//!
//! [`cmf_tabulated`] (and its `_f32` and `_integral` companions) interpolates the CIE's own
//! 1 nm table ([`crate::cie1931`]). Every spectrum-to-XYZ conversion uses it: temc-render's
//! film and the rest of the tracer, the denoiser's spectral input
//! (`temc::color::SpectralBands`, docs/contracts.md §1), and training's numpy copy
//! (`training/temc_train/color.py`, which reads the numbers from `cie1931.rs` itself), so a
//! render's colour and its spectral bands converted by temc agree.

/// The visible range the normalisation integrates over, in nm.
pub const VISIBLE_NM: (f64, f64) = (360.0, 830.0);

/// XYZ -> linear sRGB (IEC 61966-2-1, D65 white), rows R, G, B.
pub const XYZ_TO_SRGB: [[f64; 3]; 3] = [
    [3.2406, -1.5372, -0.4986],
    [-0.9689, 1.8758, 0.0415],
    [0.0557, -0.2040, 1.0570],
];

/// The tabulated CIE 1931 2-degree CMFs at `lambda` nm, linearly interpolated between the
/// 1 nm rows; 0 outside 360..830 nm, where the CIE table ends. No allocation: the film
/// calls this for every lane of every path.
pub fn cmf_tabulated_f32(lambda: f32) -> [f32; 3] {
    cmf_tabulated(lambda as f64).map(|v| v as f32)
}

/// [`cmf_tabulated_f32`] in f64, for tables built once (normalisations, the RGB uplift).
pub fn cmf_tabulated(lambda: f64) -> [f64; 3] {
    let t = &crate::cie1931::CIE_1931_2DEG;
    let x = lambda - crate::cie1931::FIRST_NM;
    // `contains` is false for NaN too, which must not index the table.
    if !(0.0..=(t.len() - 1) as f64).contains(&x) {
        return [0.0; 3];
    }
    let i = (x as usize).min(t.len() - 2);
    let f = x - i as f64;
    std::array::from_fn(|k| t[i][k] + (t[i + 1][k] - t[i][k]) * f)
}

/// Exact integral over [a, b] nm of the piecewise-linear [`cmf_tabulated`] (trapezoids
/// between the table's rows, clipped to [a, b]). Over 360..830 nm y-bar gives 106.8569,
/// the CIE sum less half its two (tiny) end rows.
pub fn cmf_tabulated_integral(a: f64, b: f64) -> [f64; 3] {
    let (lo, hi) = (a.max(VISIBLE_NM.0), b.min(VISIBLE_NM.1));
    let mut acc = [0.0; 3];
    if hi <= lo {
        return acc;
    }
    // Knots: the ends, and every whole nm strictly between them.
    let mut x0 = lo;
    let mut knot = lo.floor() + 1.0;
    while x0 < hi {
        let x1 = knot.min(hi);
        let (c0, c1) = (cmf_tabulated(x0), cmf_tabulated(x1));
        for k in 0..3 {
            acc[k] += 0.5 * (c0[k] + c1[k]) * (x1 - x0);
        }
        x0 = x1;
        knot += 1.0;
    }
    acc
}

/// CIE XYZ -> linear sRGB with [`XYZ_TO_SRGB`].
pub fn xyz_to_linear_srgb(xyz: [f64; 3]) -> [f32; 3] {
    XYZ_TO_SRGB.map(|row| (row[0] * xyz[0] + row[1] * xyz[1] + row[2] * xyz[2]) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tabulated_observer_has_the_cie_values() {
        // CIE 1931 2-degree rows (CIE 018:2019): (nm, x-bar, y-bar, z-bar).
        let rows = [
            (450.0, 0.3362, 0.038, 1.77211),
            (500.0, 0.0049, 0.323, 0.272),
            (555.0, 0.5120501, 1.0, 0.005749999),
            (600.0, 1.0622, 0.631, 0.0008),
            (650.0, 0.2835, 0.107, 0.0),
        ];
        for (l, x, y, z) in rows {
            let c = cmf_tabulated(l);
            let cf = cmf_tabulated_f32(l as f32);
            for (k, v) in [x, y, z].into_iter().enumerate() {
                assert!((c[k] - v).abs() < 1e-9, "{l} nm: {c:?}");
                assert!((cf[k] as f64 - v).abs() < 1e-6, "{l} nm: {cf:?}");
            }
        }
        // Halfway between rows: the mean of the two (linear interpolation).
        let (a, b, m) = (
            cmf_tabulated(600.0),
            cmf_tabulated(601.0),
            cmf_tabulated(600.5),
        );
        assert!((m[0] - 0.5 * (a[0] + b[0])).abs() < 1e-12);
        assert_eq!(cmf_tabulated(359.0), [0.0; 3]);
        assert_eq!(cmf_tabulated(f64::NAN), [0.0; 3]);
        assert_eq!(cmf_tabulated_f32(831.0), [0.0; 3]);
    }

    #[test]
    fn tabulated_integrals_match_the_cie_sums() {
        // The sum of the 1 nm rows of y-bar: 106.85692 (pbrt-v4's CIE_Y_integral,
        // 106.856895, is the same sum in single precision).
        let sum: f64 = (360..=830).map(|l| cmf_tabulated(l as f64)[1]).sum();
        assert!((sum - 106.85692).abs() < 1e-5, "{sum}");
        // The trapezoid integral differs from the sum by half the end rows only.
        let ends = 0.5 * (cmf_tabulated(360.0)[1] + cmf_tabulated(830.0)[1]);
        let t = cmf_tabulated_integral(360.0, 830.0);
        assert!((t[1] - (sum - ends)).abs() < 1e-9, "{t:?}");
        assert!(
            (t[0] - 106.865).abs() < 0.01 && (t[2] - 106.892).abs() < 0.01,
            "{t:?}"
        );
        // Pieces add up, across fractional ends too.
        let parts = [360.0, 402.3, 402.7, 555.0, 700.25, 830.0];
        let mut acc = [0.0; 3];
        for w in parts.windows(2) {
            let p = cmf_tabulated_integral(w[0], w[1]);
            (0..3).for_each(|k| acc[k] += p[k]);
        }
        (0..3).for_each(|k| assert!((acc[k] - t[k]).abs() < 1e-9));
        assert_eq!(cmf_tabulated_integral(500.0, 400.0), [0.0; 3]);
    }
}
