//! Pipeline-level tests: named hard cases, property tests, and the shared vector file.

use super::*;
use proptest::prelude::*;

const NITS: f32 = DEFAULT_NITS_PER_UNIT;

fn round_trip(rgb: [f32; 3]) -> [f32; 3] {
    let e = encode(rgb, Exposure::default());
    decode(e.hsv, e.excess, Exposure::default())
}

fn finite_in_range(c: [f32; 3]) -> bool {
    c.iter()
        .all(|x| x.is_finite() && *x >= 0.0 && *x <= LINEAR_MAX)
}

#[test]
fn named_hard_cases_give_finite_results() {
    let denormal = f32::from_bits(7);
    let cases: [(&str, [f32; 3]); 14] = [
        ("black", [0.0; 3]),
        ("grey", [0.5; 3]),
        ("red", [1.0, 0.0, 0.0]),
        ("green", [0.0, 1.0, 0.0]),
        ("blue", [0.0, 0.0, 1.0]),
        ("hue near 1", [1.0, 0.0, 1e-4]),
        ("hue near 0", [1.0, 1e-4, 0.0]),
        ("negative", [0.5, -0.2, 0.1]),
        ("denormals", [denormal, denormal, 0.0]),
        ("1e30", [1e30, 1e30, 1e30]),
        ("NaN", [f32::NAN, f32::NAN, f32::NAN]),
        ("+Inf", [f32::INFINITY, 0.5, 0.5]),
        ("-Inf", [f32::NEG_INFINITY, 0.5, 0.5]),
        ("f32::MAX", [f32::MAX, 0.0, f32::MIN]),
    ];
    for (name, rgb) in cases {
        let e = encode(rgb, Exposure::default());
        assert!(
            e.hsv.iter().all(|x| (0.0..=1.0).contains(x)),
            "{name}: hsv {:?}",
            e.hsv
        );
        assert!(e.excess.is_finite() && e.excess >= 1.0, "{name}");
        let back = decode(e.hsv, e.excess, Exposure::default());
        assert!(finite_in_range(back), "{name}: {back:?}");
    }
}

#[test]
fn documented_rules_for_hard_cases() {
    // Grey and black: S = 0 and H = 0 by convention.
    let g = encode([0.5; 3], Exposure::default());
    assert_eq!((g.hsv[0], g.hsv[1]), (0.0, 0.0));
    let b = encode([0.0; 3], Exposure::default());
    assert_eq!(b.hsv[..2], [0.0, 0.0]);
    assert_eq!(round_trip([0.0; 3]), [0.0; 3]);
    // NaN is black; +Inf is the ceiling value.
    assert_eq!(round_trip([f32::NAN; 3]), [0.0; 3]);
    let inf = round_trip([f32::INFINITY; 3]);
    assert!(
        inf.iter().all(|c| (c / LINEAR_MAX - 1.0).abs() < 1e-5),
        "{inf:?}"
    );
    // 1e30 is clamped like +Inf.
    assert_eq!(round_trip([1e30; 3]), inf);
}

#[test]
fn highlights_above_the_pq_range_are_restored() {
    // 500 linear units = 50000 cd/m2, five times the PQ range.
    let rgb = [500.0, 250.0, 50.0];
    let e = encode(rgb, Exposure::default());
    assert!((e.excess - 5.0).abs() < 1e-5);
    assert!((e.hsv[2] - 1.0).abs() < 1e-6);
    let back = decode(e.hsv, e.excess, Exposure::default());
    for k in 0..3 {
        assert!((back[k] / rgb[k] - 1.0).abs() < 1e-5, "{back:?}");
    }
    // A network output well below the ceiling (a removed firefly) gets no boost.
    let dimmed = decode([e.hsv[0], e.hsv[1], 0.6], e.excess, Exposure::default());
    let plain = decode([e.hsv[0], e.hsv[1], 0.6], 1.0, Exposure::default());
    assert_eq!(dimmed, plain);
}

#[test]
fn exposure_is_validated_and_undone() {
    assert!(Exposure::new(0.0, NITS).is_err());
    assert!(Exposure::new(f32::NAN, NITS).is_err());
    assert!(Exposure::new(1.0, -1.0).is_err());
    let x = Exposure::new(1e-3, NITS).unwrap();
    let e = encode([20.0, 10.0, 5.0], x);
    let back = decode(e.hsv, e.excess, x);
    assert!((back[0] - 20.0).abs() < 2e-4, "{back:?}");
    // Huge scales do not overflow.
    let big = Exposure::new(f32::MAX, NITS).unwrap();
    let e = encode([1.0, 0.5, 0.0], big);
    assert!(e.excess.is_finite());
    assert!(finite_in_range(decode(e.hsv, e.excess, big)));
}

/// Linear values whose luminance at the default exposure is log-uniform in
/// [1e-6, 1e4] cd/m2.
fn nits_channel() -> impl Strategy<Value = f32> {
    (-6.0f64..4.0).prop_map(|e| (10f64.powf(e) / NITS as f64) as f32)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    /// RGB -> PQ -> HSV -> RGB: every channel within 1e-5 relative of the pixel's largest
    /// channel, and within 1e-5 relative of itself when the channels lie within a factor 100
    /// of each other. HSV stores the smallest channel as V (1 - S) in f32, so a channel much
    /// dimmer than the largest keeps less of its own relative precision: measured worst cases
    /// over 2e6 random pixels were 9e-7 (ratio < 10), 4e-6 (< 100), 1.6e-5 (< 1e3),
    /// 5.5e-5 (< 1e4), 2.4e-3 (< 1e10), always tiny next to the largest channel.
    #[test]
    fn round_trip_relative(r in nits_channel(), g in nits_channel(), b in nits_channel()) {
        let rgb = [r, g, b];
        let back = round_trip(rgb);
        let max = r.max(g).max(b);
        let min = r.min(g).min(b);
        for k in 0..3 {
            let err = (back[k] - rgb[k]).abs();
            prop_assert!(err <= 1e-5 * max, "{rgb:?} -> {back:?}");
            if max <= 1e2 * min {
                prop_assert!(err <= 1e-5 * rgb[k], "{rgb:?} -> {back:?}");
            }
        }
    }

    /// Grey pixels survive exactly enough at every level.
    #[test]
    fn grey_round_trip(v in nits_channel()) {
        let back = round_trip([v; 3]);
        for c in back {
            prop_assert!((c - v).abs() <= 1e-5 * v);
        }
    }

    /// Noisy network outputs: perturbing a valid HSV never gives NaN or leaves the PQ range.
    #[test]
    fn perturbed_hsv_recombines_in_range(
        r in nits_channel(), g in nits_channel(), b in nits_channel(),
        dh in -0.6f32..0.6, ds in -0.3f32..0.3, dv in -0.3f32..0.3,
    ) {
        let e = encode([r, g, b], Exposure::default());
        let noisy = [e.hsv[0] + dh, e.hsv[1] + ds, e.hsv[2] + dv];
        let pq = hsv_to_rgb(sanitize_hsv(noisy));
        prop_assert!(pq.iter().all(|c| (0.0..=1.0).contains(c)), "{noisy:?} -> {pq:?}");
        let lin = decode(noisy, e.excess, Exposure::default());
        prop_assert!(finite_in_range(lin));
    }

    /// Arbitrary bit patterns, NaN and Inf included, always encode into range.
    #[test]
    fn any_bits_encode_into_range(bits in proptest::array::uniform3(any::<u32>())) {
        let rgb = bits.map(f32::from_bits);
        let e = encode(rgb, Exposure::default());
        prop_assert!(e.hsv.iter().all(|x| (0.0..=1.0).contains(x)));
        prop_assert!(finite_in_range(decode(e.hsv, e.excess, Exposure::default())));
    }

    /// Hue continuity across the wrap: H = 1 - d and H = d decode to nearly the same colour.
    #[test]
    fn hue_wrap_is_continuous(d in 0.0f32..1e-4, s in 0.0f32..=1.0, v in 0.0f32..=1.0) {
        let a = hsv_to_rgb([1.0 - d, s, v]);
        let b = hsv_to_rgb([d, s, v]);
        for k in 0..3 {
            prop_assert!((a[k] - b[k]).abs() <= 2e-3);
        }
    }
}

#[test]
fn auto_exposure_maps_the_log_average_to_mid_grey() {
    let img = [[0.5f32; 3], [2.0; 3], [f32::NAN; 3], [0.0; 3]];
    // ln-average of Y over 0.5 and 2.0 is 1.0 (NaN and black are skipped).
    assert!((auto_input_scale(img.into_iter()) - 0.18).abs() < 1e-6);
    assert_eq!(auto_input_scale([[0.0f32; 3]].into_iter()), 1.0);
    assert_eq!(auto_input_scale(std::iter::empty()), 1.0);
    let huge = auto_input_scale([[f32::INFINITY; 3]].into_iter());
    assert!(huge.is_finite() && huge > 0.0);
}
