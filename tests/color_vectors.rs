//! The shared colour test vectors: tests/data/color_vectors.json is written by this Rust code
//! and read by training/tests/test_color_vectors.py, which checks the Python transform used
//! in training against it to 1e-5. This test fails when the Rust pipeline drifts from the
//! committed file; `TEMC_BLESS=1 cargo test --release --test color_vectors` rewrites it
//! (then rerun the Python tests).

mod common;

use common::json_f32 as parse;
use serde_json::{json, Value};
use temc::color::{self, Exposure, SpectralBands};

const PATH: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/color_vectors.json");

/// JSON has no NaN or Inf: they travel as strings.
fn num(x: f32) -> Value {
    if x.is_nan() {
        json!("nan")
    } else if x == f32::INFINITY {
        json!("inf")
    } else if x == f32::NEG_INFINITY {
        json!("-inf")
    } else {
        json!(x)
    }
}

fn nums(xs: &[f32]) -> Value {
    Value::Array(xs.iter().map(|&x| num(x)).collect())
}

fn pixel_cases() -> Vec<(&'static str, [f32; 3], f32)> {
    let d = f32::from_bits(3);
    let mut v = vec![
        ("black", [0.0; 3], 1.0),
        ("grey", [0.18; 3], 1.0),
        ("white", [1.0; 3], 1.0),
        ("red", [1.0, 0.0, 0.0], 1.0),
        ("green", [0.0, 1.0, 0.0], 1.0),
        ("blue", [0.0, 0.0, 1.0], 1.0),
        ("orange", [0.9, 0.4, 0.05], 1.0),
        ("hue near 1", [1.0, 0.0, 1e-4], 1.0),
        ("hue near 0", [1.0, 1e-4, 0.0], 1.0),
        ("dim", [1e-6, 2e-6, 5e-7], 1.0),
        ("bright", [40.0, 60.0, 20.0], 1.0),
        ("above pq range", [500.0, 250.0, 50.0], 1.0),
        ("negative", [0.5, -0.2, 0.1], 1.0),
        ("negative luminance", [-1.0, -1.0, 0.5], 1.0),
        ("denormal", [d, d, 0.0], 1.0),
        ("1e30", [1e30, 1e30, 1e30], 1.0),
        ("nan", [f32::NAN, 0.5, 0.25], 1.0),
        ("+inf", [f32::INFINITY, 0.5, 0.5], 1.0),
        ("-inf", [f32::NEG_INFINITY, 0.5, 0.5], 1.0),
        ("scaled down", [20.0, 10.0, 5.0], 1e-3),
        ("scaled up", [0.02, 0.01, 0.005], 50.0),
    ];
    // A deterministic spread over the whole range, so the comparison is not only corners.
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    for _ in 0..40 {
        let mut c = [0f32; 3];
        for ch in &mut c {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let u = (x >> 11) as f64 / (1u64 << 53) as f64;
            *ch = 10f64.powf(-8.0 + 11.0 * u) as f32;
        }
        v.push(("random", c, 1.0));
    }
    v
}

fn hsv_cases() -> Vec<(&'static str, [f32; 3])> {
    vec![
        ("valid", [0.3, 0.5, 0.7]),
        ("hue above 1", [1.2, 0.5, 0.7]),
        ("hue negative", [-0.1, 0.5, 0.7]),
        ("hue exactly 1", [1.0, 0.9, 0.9]),
        ("saturation out of range", [0.6, 1.3, 0.5]),
        ("value out of range", [0.6, 0.5, 1.7]),
        ("negative value", [0.6, 0.5, -0.2]),
        ("nan", [f32::NAN, 0.5, 0.5]),
        ("all nan", [f32::NAN; 3]),
        ("inf hue", [f32::INFINITY, 0.5, 0.5]),
        ("grey any hue", [0.77, 0.0, 0.4]),
        ("sector boundary", [1.0 / 6.0, 1.0, 1.0]),
    ]
}

fn spectral_cases() -> Vec<(&'static str, Vec<f32>, Vec<f32>)> {
    let edges16: Vec<f32> = (0..=16).map(|i| 380.0 + 25.0 * i as f32).collect();
    let ramp: Vec<f32> = (0..16).map(|i| i as f32 / 15.0).collect();
    let spike: Vec<f32> = (0..16).map(|i| if i == 9 { 20.0 } else { 0.05 }).collect();
    vec![
        ("flat 16", edges16.clone(), vec![1.0; 16]),
        ("ramp 16", edges16.clone(), ramp),
        ("spike 16", edges16.clone(), spike),
        ("laser 500", vec![495.0, 505.0], vec![3.0]),
        ("whole range", vec![360.0, 830.0], vec![1.0]),
        (
            "three uneven",
            vec![400.0, 480.0, 560.0, 700.0],
            vec![0.2, 0.5, 0.9],
        ),
        (
            "garbage",
            vec![400.0, 500.0, 600.0, 700.0],
            vec![f32::NAN, -1.0, f32::INFINITY],
        ),
    ]
}

fn vectors() -> Value {
    let pixels: Vec<Value> = pixel_cases()
        .into_iter()
        .map(|(name, rgb, scale)| {
            let x = Exposure::new(scale, color::DEFAULT_NITS_PER_UNIT).unwrap();
            let sanitized = color::sanitize_rgb(rgb);
            let e = color::encode(rgb, x);
            let pq = color::hsv_to_rgb(e.hsv);
            let decoded = color::decode(e.hsv, e.excess, x);
            json!({
                "name": name, "rgb": nums(&rgb), "input_scale": scale,
                "sanitized": nums(&sanitized), "excess": e.excess, "pq": nums(&pq),
                "hsv": nums(&e.hsv), "decoded": nums(&decoded),
            })
        })
        .collect();
    let hsv: Vec<Value> = hsv_cases()
        .into_iter()
        .map(|(name, h)| json!({"name": name, "hsv": nums(&h), "rgb_pq": nums(&color::hsv_to_rgb(h))}))
        .collect();
    let spectral: Vec<Value> = spectral_cases()
        .into_iter()
        .map(|(name, edges, values)| {
            let b = SpectralBands::new(&edges).unwrap();
            let xyz = b.to_xyz(&values).map(|v| v as f32);
            json!({
                "name": name, "edges": nums(&edges), "values": nums(&values),
                "xyz": nums(&xyz), "rgb": nums(&b.to_linear_srgb(&values)),
            })
        })
        .collect();
    json!({
        "comment": "Written by tests/color_vectors.rs (TEMC_BLESS=1 to rewrite); read by training/tests/test_color_vectors.py. Rules: docs/contracts.md section 1.",
        "pq_nits_per_unit": color::DEFAULT_NITS_PER_UNIT,
        "linear_max": color::LINEAR_MAX,
        "highlight_knee": color::HIGHLIGHT_KNEE,
        "pixels": pixels,
        "hsv_inverse": hsv,
        "spectral": spectral,
    })
}

/// Compares two JSON trees; numbers must agree to 1e-6 relative (f32 printing is exact,
/// the slack only absorbs libm differences between machines).
fn assert_same(a: &Value, b: &Value, path: &str) {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            assert_eq!(
                x.keys().collect::<Vec<_>>(),
                y.keys().collect::<Vec<_>>(),
                "{path}"
            );
            for (k, v) in x {
                assert_same(v, &y[k], &format!("{path}.{k}"));
            }
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{path}");
            for (i, (u, v)) in x.iter().zip(y).enumerate() {
                assert_same(u, v, &format!("{path}[{i}]"));
            }
        }
        (Value::Number(_), _) | (_, Value::Number(_)) => {
            let (u, v) = (parse(a), parse(b));
            assert!(
                u == v || (u - v).abs() <= 1e-6 * u.abs().max(v.abs()),
                "{path}: file {u} vs code {v}"
            );
        }
        _ => assert_eq!(a, b, "{path}"),
    }
}

#[test]
fn committed_vectors_match_the_rust_pipeline() {
    let now = vectors();
    if std::env::var_os("TEMC_BLESS").is_some() {
        let text = serde_json::to_string_pretty(&now).unwrap() + "\n";
        std::fs::write(PATH, text).expect("write vectors");
        return;
    }
    let text = std::fs::read_to_string(PATH)
        .expect("tests/data/color_vectors.json missing: run with TEMC_BLESS=1 to create it");
    let file: Value = serde_json::from_str(&text).expect("valid JSON");
    assert_same(&file, &now, "$");
}

#[test]
fn every_vector_is_finite_where_the_contract_says_so() {
    let v = vectors();
    for p in v["pixels"].as_array().unwrap() {
        for key in ["sanitized", "pq", "hsv", "decoded"] {
            for c in p[key].as_array().unwrap() {
                assert!(parse(c).is_finite(), "{} {key}", p["name"]);
            }
        }
    }
}
