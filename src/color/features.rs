//! Auxiliary feature buffers (albedo, normal, depth) brought into the network's [0, 1] range.
//!
//! Feature buffers are noise-free guides; they only need to be finite and in a fixed range.
//! Depth has no natural scale, so it is divided by a statistic of the whole image, computed
//! once before tiling so that every tile sees the same numbers.

/// Albedo: NaN -> 0, then clamped to [0, 1] per channel.
pub fn albedo(a: [f32; 3]) -> [f32; 3] {
    a.map(|x| if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) })
}

/// Normal: normalised to unit length (any input length is fine), then mapped from [-1, 1]
/// to [0, 1] by (n + 1) / 2. A zero, non-finite or denormal-length normal maps to 0.5
/// (the zero vector), which the network reads as "no normal".
pub fn normal(n: [f32; 3]) -> [f32; 3] {
    let v = n.map(|x| x as f64);
    let len2: f64 = v.iter().map(|x| x * x).sum();
    if !len2.is_finite() || len2 < 1e-30 {
        return [0.5; 3];
    }
    let inv = len2.sqrt().recip();
    v.map(|x| ((x * inv + 1.0) * 0.5).clamp(0.0, 1.0) as f32)
}

/// The per-image depth statistic: the largest finite positive depth, or `None` when the
/// image has none.
pub fn depth_scale(depths: impl IntoIterator<Item = f32>) -> Option<f32> {
    depths
        .into_iter()
        .filter(|d| d.is_finite() && *d > 0.0)
        .fold(None, |m: Option<f32>, d| Some(m.map_or(d, |m| m.max(d))))
}

/// Depth divided by the image's [`depth_scale`], in [0, 1]. NaN and non-positive depths give
/// 0, +Inf (background) gives 1; an image without a scale gives 0 everywhere.
pub fn depth(d: f32, scale: Option<f32>) -> f32 {
    let Some(s) = scale else { return 0.0 };
    if d.is_nan() || d <= 0.0 {
        0.0
    } else {
        (d / s).min(1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn albedo_clamps() {
        assert_eq!(albedo([f32::NAN, 2.0, -1.0]), [0.0, 1.0, 0.0]);
        assert_eq!(
            albedo([0.25, f32::INFINITY, f32::NEG_INFINITY]),
            [0.25, 1.0, 0.0]
        );
    }

    #[test]
    fn normals_any_length() {
        assert_eq!(normal([0.0, 0.0, 5.0]), [0.5, 0.5, 1.0]);
        assert_eq!(normal([0.0, -1e-3, 0.0]), [0.5, 0.0, 0.5]);
        assert_eq!(normal([0.0; 3]), [0.5; 3]);
        assert_eq!(normal([f32::NAN, 1.0, 0.0]), [0.5; 3]);
        assert_eq!(normal([f32::from_bits(1), 0.0, 0.0]), [0.5; 3]);
        // Huge but finite components: f64 keeps the length finite.
        let n = normal([3e38, 3e38, 0.0]);
        assert!((n[0] - n[1]).abs() < 1e-7 && n[0] > 0.85);
    }

    #[test]
    fn depth_normalisation() {
        let img = [1.0, f32::NAN, 4.0, f32::INFINITY, -2.0, 0.0];
        let s = depth_scale(img);
        assert_eq!(s, Some(4.0));
        let d: Vec<f32> = img.iter().map(|&x| depth(x, s)).collect();
        assert_eq!(d, vec![0.25, 0.0, 1.0, 1.0, 0.0, 0.0]);
        assert_eq!(depth_scale([f32::NAN, 0.0]), None);
        assert_eq!(depth(3.0, None), 0.0);
    }
}
