//! SMPTE ST 2084 perceptual quantiser (PQ), the "Dolby Vision" transfer curve.
//!
//! PQ spreads code values evenly in perceived brightness over 0..10000 cd/m2, which is why
//! the network sees PQ values rather than linear radiance. The arithmetic runs in f64: near
//! black the decode subtracts two nearly equal numbers (`P - c1`), and f32 there would cost
//! the round trip its 1e-5 relative accuracy.

/// m1 = 2610 / 16384.
pub const M1: f64 = 2610.0 / 16384.0;
/// m2 = 2523 / 4096 * 128.
pub const M2: f64 = 2523.0 / 4096.0 * 128.0;
/// c1 = 3424 / 4096 (= c3 - c2 + 1).
pub const C1: f64 = 3424.0 / 4096.0;
/// c2 = 2413 / 4096 * 32.
pub const C2: f64 = 2413.0 / 4096.0 * 32.0;
/// c3 = 2392 / 4096 * 32.
pub const C3: f64 = 2392.0 / 4096.0 * 32.0;
/// The luminance that PQ code value 1.0 stands for, in cd/m2.
pub const PQ_MAX_NITS: f64 = 10000.0;

/// Encodes normalised luminance `y` = L / 10000 cd/m2 to a PQ code value in [0, 1].
///
/// `y` is clamped to [0, 1] first; NaN encodes as black. PQ(0) is not 0 but c1^m2 (about
/// 7.3e-7), the curve's own black.
///
/// ```
/// // 100 cd/m2, the usual SDR reference white, sits near the middle of the PQ range.
/// let e = temc::color::pq::encode(100.0 / 10000.0);
/// assert!((e - 0.50808).abs() < 1e-4);
/// ```
pub fn encode(y: f64) -> f64 {
    curve(y)
}

/// The body of [`encode`], inlined into each instruction-set version of [`encode_all`].
#[inline(always)]
fn curve(y: f64) -> f64 {
    // max then min: NaN becomes 0 (clamp would keep it), branch-free for `encode_all`.
    #[allow(clippy::manual_clamp)]
    let y = y.max(0.0).min(1.0);
    let ym = pow_unit(y, M1);
    pow_unit((C1 + C2 * ym) / (1.0 + C3 * ym), M2)
}

/// [`encode`] in place over many values, to the bit the same: one loop the compiler
/// vectorises (8 values at a time with AVX-512), where libm's `pow` took two thirds of
/// preparing a tile's network input.
pub fn encode_all(ys: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512dq") {
        // SAFETY: the CPU has AVX-512F and DQ. No FMA: the same bits as the scalar code.
        return unsafe { encode_all_avx512(ys) };
    }
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2.
        return unsafe { encode_all_avx2(ys) };
    }
    ys.iter_mut().for_each(|y| *y = curve(*y));
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq")]
fn encode_all_avx512(ys: &mut [f64]) {
    ys.iter_mut().for_each(|y| *y = curve(*y));
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn encode_all_avx2(ys: &mut [f64]) {
    ys.iter_mut().for_each(|y| *y = curve(*y));
}

/// y^p for y in [0, 1] and p > 0, as 2^(p log2 y): within a few ulp of `powf`, and 0
/// for y = 0.
#[inline(always)]
fn pow_unit(y: f64, p: f64) -> f64 {
    let r = exp2_nonpos(p * log2(y.max(f64::MIN_POSITIVE)));
    if y > 0.0 {
        r
    } else {
        0.0
    }
}

/// log2 x for finite x >= `f64::MIN_POSITIVE`: x = 2^e m with m in [sqrt(1/2), sqrt(2)),
/// log2 m = 2 atanh(s) / ln 2 with s = (m - 1) / (m + 1), |s| <= 0.172, by the series of
/// atanh to s^21 (the next term is below 1e-18 of the sum).
#[inline(always)]
fn log2(x: f64) -> f64 {
    const MANTISSA: u64 = (1 << 52) - 1;
    let bits = x.to_bits();
    let e = (bits >> 52) as f64 - 1023.0;
    let m = f64::from_bits((bits & MANTISSA) | 1f64.to_bits());
    let big = m > std::f64::consts::SQRT_2;
    let (m, e) = if big { (0.5 * m, e + 1.0) } else { (m, e) };
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    let mut sum = 1.0 / 21.0;
    for k in (0..10).rev() {
        sum = sum * s2 + 1.0 / (2 * k + 1) as f64;
    }
    e + s * sum * (2.0 * std::f64::consts::LOG2_E)
}

/// 2^t for t in [-1022, 0] (lower t gives 2^-1022): t = n + f with n an integer and
/// |f| <= 1/2, e^(f ln 2) by its Taylor series to the 13th power (the next term is below
/// 1e-17), and 2^n built from bits.
#[inline(always)]
fn exp2_nonpos(t: f64) -> f64 {
    const MAGIC: f64 = 6_755_399_441_055_744.0; // 1.5 * 2^52: adding it rounds to an integer
    const INV_FACTORIAL: [f64; 14] = {
        let mut c = [1.0; 14];
        let mut k = 1;
        while k < 14 {
            c[k] = c[k - 1] / k as f64;
            k += 1;
        }
        c
    };
    let t = t.max(-1022.0);
    let r = t + MAGIC;
    let n = r - MAGIC;
    let x = (t - n) * std::f64::consts::LN_2;
    let mut p = INV_FACTORIAL[13];
    for c in INV_FACTORIAL[..13].iter().rev() {
        p = p * x + c;
    }
    // r's bits are MAGIC's plus n (n in -1022..=0 lies in MAGIC's binade).
    let n = r.to_bits().wrapping_sub(MAGIC.to_bits()) as i64;
    p * f64::from_bits(((n + 1023) as u64) << 52)
}

/// Decodes a PQ code value to normalised luminance L / 10000 cd/m2, the inverse of [`encode`].
///
/// The code value is clamped to [0, 1] (NaN decodes as 0), so the result always lies in
/// [0, 1]: the denominator `c2 - c3 P` stays above 0.16 on that interval.
pub fn decode(e: f64) -> f64 {
    let e = if e.is_nan() { 0.0 } else { e.clamp(0.0, 1.0) };
    let p = e.powf(1.0 / M2);
    let num = (p - C1).max(0.0);
    let den = C2 - C3 * p;
    (num / den).powf(1.0 / M1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_points() {
        // ST 2084 tables: 100 cd/m2 -> 0.5081, 1000 cd/m2 -> 0.7518, 10000 -> 1.
        assert!((encode(0.01) - 0.50808).abs() < 1e-4);
        assert!((encode(0.1) - 0.75183).abs() < 1e-4);
        assert!((encode(1.0) - 1.0).abs() < 1e-12);
        assert!(encode(0.0) > 0.0 && encode(0.0) < 1e-6);
        assert_eq!(decode(encode(0.0)), 0.0);
    }

    /// The polynomial curve against libm's `powf` (correctly rounded or nearly): within
    /// 5e-14 relative over the whole range (M2 = 78.8 scales log2's last ulps; f32, which
    /// the network sees, resolves 6e-8), and `encode_all` gives the same bits as `encode`.
    #[test]
    fn the_curve_follows_libm() {
        let libm = |y: f64| {
            let ym = y.powf(M1);
            ((C1 + C2 * ym) / (1.0 + C3 * ym)).powf(M2)
        };
        let mut ys = vec![0.0, f64::MIN_POSITIVE, 1e-300, 0.5, 1.0];
        let mut y = 1e-40;
        while y < 1.0 {
            ys.push(y);
            y *= 1.013;
        }
        let mut all = ys.clone();
        encode_all(&mut all);
        // The dispatch takes the widest build; the AVX2 one must agree too.
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            let mut avx2 = ys.clone();
            // SAFETY: the CPU has AVX2.
            unsafe { encode_all_avx2(&mut avx2) };
            assert!(avx2
                .iter()
                .zip(&all)
                .all(|(a, b)| a.to_bits() == b.to_bits()));
        }
        for (&y, &batch) in ys.iter().zip(&all) {
            let (got, want) = (encode(y), libm(y));
            assert!((got - want).abs() <= 5e-14 * want, "y={y}: {got} vs {want}");
            assert_eq!(got.to_bits(), batch.to_bits(), "y={y}");
        }
    }

    #[test]
    fn round_trip_over_the_range() {
        let mut y = 1e-10;
        while y <= 1.0 {
            let back = decode(encode(y));
            assert!((back - y).abs() <= 1e-9 * y, "y={y} back={back}");
            y *= 1.37;
        }
    }

    #[test]
    fn out_of_range_inputs_clamp() {
        assert_eq!(encode(f64::NAN), encode(0.0));
        assert_eq!(encode(-5.0), encode(0.0));
        assert_eq!(encode(1e300), 1.0);
        assert_eq!(encode(f64::INFINITY), 1.0);
        assert_eq!(decode(f64::NAN), 0.0);
        assert_eq!(decode(-1.0), 0.0);
        assert!((decode(7.0) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn monotonic() {
        let mut prev = -1.0;
        for i in 0..=1000 {
            let e = encode(i as f64 / 1000.0);
            assert!(e > prev);
            prev = e;
        }
    }
}
