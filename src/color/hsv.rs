//! Hexcone HSV on PQ-encoded R'G'B', all three components in [0, 1].
//!
//! TEMC splits colour into chroma (H, S) and luma (V) so that separate encoders see each.
//! H is circular: 0 and 1 are the same hue. Where max = min the hue is undefined and we set
//! H = 0; this is harmless because [`hsv_to_rgb`] is continuous in H as S goes to 0, so a
//! near-grey pixel whose H is pure noise still decodes to near-grey.

/// Converts R'G'B' (each expected in [0, 1]) to (H, S, V).
///
/// V = max, S = (max - min) / max (0 when max = 0), H = hue angle / 360 in [0, 1)
/// (0 when max = min). Inputs must be finite; [`super::sanitize_rgb`] guarantees that in
/// the pipeline.
pub fn rgb_to_hsv(rgb: [f32; 3]) -> [f32; 3] {
    // f64 inside: each of H, S, V is then rounded to f32 once, which is what keeps the
    // round trip within 1e-5 relative for dim channels (see color::tests).
    let [r, g, b] = rgb.map(f64::from);
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let d = max - min;
    let v = max;
    let s = if max > 0.0 { d / max } else { 0.0 };
    if d <= 0.0 {
        return [0.0, s as f32, v as f32];
    }
    let h6 = if max == r {
        (g - b) / d
    } else if max == g {
        (b - r) / d + 2.0
    } else {
        (r - g) / d + 4.0
    };
    [wrap_hue((h6 / 6.0) as f32), s as f32, v as f32]
}

/// Converts (H, S, V) back to R'G'B' with the six-sector formula.
///
/// Any input is accepted and the result is always in [0, 1]: NaN components count as 0,
/// H wraps around (H - floor(H)), S and V are clamped to [0, 1]. Network outputs that drift
/// slightly out of range therefore never produce NaN or out-of-range values.
pub fn hsv_to_rgb(hsv: [f32; 3]) -> [f32; 3] {
    let [h, s, v] = sanitize_hsv(hsv).map(f64::from);
    let h6 = h * 6.0;
    let sector = h6.floor();
    let f = h6 - sector;
    let p = v * (1.0 - s);
    let q = v * (1.0 - s * f);
    let t = v * (1.0 - s * (1.0 - f));
    let rgb = match sector as i32 {
        0 => [v, t, p],
        1 => [q, v, p],
        2 => [p, v, t],
        3 => [p, q, v],
        4 => [t, p, v],
        _ => [v, p, q],
    };
    rgb.map(|c| c as f32)
}

/// Brings an arbitrary (possibly noisy) HSV triple into the valid domain: NaN -> 0,
/// H wrapped into [0, 1), S and V clamped to [0, 1].
pub fn sanitize_hsv(hsv: [f32; 3]) -> [f32; 3] {
    let fix = |x: f32| if x.is_nan() { 0.0 } else { x };
    let h = fix(hsv[0]);
    let h = if h.is_finite() { wrap_hue(h) } else { 0.0 };
    [h, fix(hsv[1]).clamp(0.0, 1.0), fix(hsv[2]).clamp(0.0, 1.0)]
}

/// Wraps a finite hue into [0, 1). `h - floor(h)` can round up to exactly 1.0 for tiny
/// negative `h`; that is the same hue as 0.
fn wrap_hue(h: f32) -> f32 {
    let w = h - h.floor();
    if w >= 1.0 {
        0.0
    } else {
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f32; 3], b: [f32; 3], tol: f32) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
    }

    #[test]
    fn primaries_and_secondaries() {
        assert_eq!(rgb_to_hsv([1.0, 0.0, 0.0]), [0.0, 1.0, 1.0]);
        assert!(close(
            rgb_to_hsv([0.0, 1.0, 0.0]),
            [1.0 / 3.0, 1.0, 1.0],
            1e-7
        ));
        assert!(close(
            rgb_to_hsv([0.0, 0.0, 1.0]),
            [2.0 / 3.0, 1.0, 1.0],
            1e-7
        ));
        assert!(close(
            rgb_to_hsv([1.0, 1.0, 0.0]),
            [1.0 / 6.0, 1.0, 1.0],
            1e-7
        ));
        assert!(close(
            rgb_to_hsv([1.0, 0.0, 1.0]),
            [5.0 / 6.0, 1.0, 1.0],
            1e-7
        ));
        for rgb in [
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.3, 0.7, 0.1],
        ] {
            assert!(close(hsv_to_rgb(rgb_to_hsv(rgb)), rgb, 1e-6));
        }
    }

    #[test]
    fn grey_and_black_have_zero_hue() {
        assert_eq!(rgb_to_hsv([0.5, 0.5, 0.5]), [0.0, 0.0, 0.5]);
        assert_eq!(rgb_to_hsv([0.0, 0.0, 0.0]), [0.0, 0.0, 0.0]);
        // Any hue decodes a grey pixel to grey.
        for h in [0.0, 0.2, 0.5, 0.99] {
            assert_eq!(hsv_to_rgb([h, 0.0, 0.4]), [0.4, 0.4, 0.4]);
        }
    }

    #[test]
    fn hue_wraps_around() {
        // A red slightly towards magenta has H just below 1, not negative.
        let h = rgb_to_hsv([1.0, 0.0, 1e-4])[0];
        assert!(h > 0.999 && h < 1.0);
        // H = 1 and H = 0 decode the same; so do -0.25 and 0.75.
        assert_eq!(hsv_to_rgb([1.0, 0.8, 0.6]), hsv_to_rgb([0.0, 0.8, 0.6]));
        assert!(close(
            hsv_to_rgb([-0.25, 0.8, 0.6]),
            hsv_to_rgb([0.75, 0.8, 0.6]),
            1e-6
        ));
        // Continuity across the wrap.
        let a = hsv_to_rgb([0.999_999, 1.0, 1.0]);
        let b = hsv_to_rgb([0.000_001, 1.0, 1.0]);
        assert!(close(a, b, 1e-4));
        // Tiny negative hue rounds to 1.0 in f32: wrapped to 0.
        assert_eq!(wrap_hue(-1e-9), 0.0);
    }

    #[test]
    fn garbage_hsv_stays_in_range() {
        for hsv in [
            [f32::NAN, f32::NAN, f32::NAN],
            [f32::INFINITY, 2.0, -1.0],
            [-7.3, -0.1, 1.5],
            [1e30, 0.5, 0.5],
        ] {
            let rgb = hsv_to_rgb(hsv);
            assert!(
                rgb.iter().all(|c| (0.0..=1.0).contains(c)),
                "{hsv:?} -> {rgb:?}"
            );
        }
    }
}
