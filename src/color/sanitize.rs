//! Turning whatever a renderer wrote into finite, non-negative linear RGB.
//!
//! Renderers hand us NaN from 0/0 in a BSDF, +Inf from a degenerate pdf, and negative
//! components from spectral-to-RGB conversion of saturated spectra. None of it may reach the
//! network; the rule for each is fixed here and documented in docs/contracts.md §1.

/// The largest value a channel keeps: the largest finite half float, so float and half
/// input buffers sanitise to the same numbers.
pub const LINEAR_MAX: f32 = 65504.0;

/// Rec. 709 / sRGB luminance weights.
pub const LUMA_WEIGHTS: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// Sanitises one channel: NaN and -Inf become 0, +Inf and values above [`LINEAR_MAX`]
/// become [`LINEAR_MAX`]. Negative finite values pass (the pixel rule handles them).
pub fn sanitize_channel(x: f32) -> f32 {
    if x.is_nan() || x == f32::NEG_INFINITY {
        0.0
    } else {
        x.min(LINEAR_MAX)
    }
}

/// Sanitises a linear RGB pixel.
///
/// Channels first go through [`sanitize_channel`]. A pixel with a negative component is then
/// desaturated toward its own luminance Y: `c' = Y + t (c - Y)` with the largest `t` in
/// [0, 1] that makes every component non-negative, which keeps Y and the hue angle. A pixel
/// whose Y is not positive becomes black.
///
/// ```
/// use temc::color::sanitize_rgb;
/// // NaN -> 0, +Inf -> 65504; the negative blue is removed by desaturation.
/// let p = sanitize_rgb([f32::NAN, f32::INFINITY, -1.0]);
/// assert!(p.iter().all(|c| c.is_finite() && *c >= 0.0));
/// assert_eq!(sanitize_rgb([0.25, f32::NAN, 2.0]), [0.25, 0.0, 2.0]);
/// ```
pub fn sanitize_rgb(rgb: [f32; 3]) -> [f32; 3] {
    let c = rgb.map(sanitize_channel);
    if c.iter().all(|&x| x >= 0.0) {
        return c;
    }
    // f64: Y - min can be as large as 2 * LINEAR_MAX and t must make min land on 0, not -eps.
    let y: f64 = c
        .iter()
        .zip(LUMA_WEIGHTS)
        .map(|(&x, w)| x as f64 * w as f64)
        .sum();
    if y <= 0.0 {
        return [0.0; 3];
    }
    let min = c.iter().fold(f64::INFINITY, |m, &x| m.min(x as f64));
    let t = y / (y - min);
    c.map(|x| ((y + t * (x as f64 - y)) as f32).max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn luma(c: [f32; 3]) -> f32 {
        c.iter().zip(LUMA_WEIGHTS).map(|(x, w)| x * w).sum()
    }

    #[test]
    fn non_finite_channels() {
        assert_eq!(sanitize_channel(f32::NAN), 0.0);
        assert_eq!(sanitize_channel(f32::NEG_INFINITY), 0.0);
        assert_eq!(sanitize_channel(f32::INFINITY), LINEAR_MAX);
        assert_eq!(sanitize_channel(1e30), LINEAR_MAX);
        assert_eq!(sanitize_channel(f32::MAX), LINEAR_MAX);
        let denormal = f32::from_bits(1);
        assert_eq!(sanitize_channel(denormal), denormal);
    }

    #[test]
    fn positive_pixels_pass_unchanged() {
        for p in [[0.0; 3], [1.0, 2.0, 3.0], [1e-40, 0.0, 5e4]] {
            assert_eq!(sanitize_rgb(p), p);
        }
    }

    #[test]
    fn negative_component_keeps_luminance_and_hue() {
        let p = [1.0, 0.5, -0.2];
        let s = sanitize_rgb(p);
        assert!(s.iter().all(|&c| c >= 0.0));
        assert!((luma(s) - luma(p)).abs() < 1e-6);
        // Still reddish-orange: R > G > B = 0.
        assert!(s[0] > s[1] && s[1] > s[2]);
        assert_eq!(s[2], 0.0);
    }

    #[test]
    fn negative_luminance_is_black() {
        assert_eq!(sanitize_rgb([-1.0, -1.0, 0.5]), [0.0; 3]);
        assert_eq!(sanitize_rgb([f32::NEG_INFINITY, 0.0, 0.0]), [0.0; 3]);
        assert_eq!(sanitize_rgb([-3.0, 0.0, 0.0]), [0.0; 3]);
    }

    #[test]
    fn mixed_garbage_is_finite() {
        let s = sanitize_rgb([f32::INFINITY, -1e30, f32::NAN]);
        assert!(s
            .iter()
            .all(|c| c.is_finite() && *c >= 0.0 && *c <= LINEAR_MAX));
    }
}
