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
    let y = if y.is_nan() { 0.0 } else { y.clamp(0.0, 1.0) };
    let ym = y.powf(M1);
    ((C1 + C2 * ym) / (1.0 + C3 * ym)).powf(M2)
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
