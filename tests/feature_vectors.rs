//! The shared feature vectors: tests/data/feature_vectors.json is written by
//! training/temc_train/vectors/feature_vectors.py (what training feeds the network) and checked
//! here against the core's automatic exposure and aux features (docs/contracts.md §1,
//! steps 3 and 7), so inference sees the numbers training saw. After a deliberate change
//! on either side, regenerate the file (`python -m temc_train.vectors.feature_vectors` in
//! training/) and run this test and training/tests/test_feature_vectors.py.

mod common;

use common::json_f32 as parse;
use serde_json::Value;
use temc::color::{self, features};

const PATH: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/data/feature_vectors.json"
);

fn load() -> Value {
    let text = std::fs::read_to_string(PATH).expect("tests/data/feature_vectors.json");
    serde_json::from_str(&text).expect("valid JSON")
}

fn floats(v: &Value) -> Vec<f32> {
    v.as_array().expect("array").iter().map(parse).collect()
}

fn triple(v: &Value) -> [f32; 3] {
    floats(v).try_into().expect("three values")
}

fn tolerance(doc: &Value, key: &str) -> f64 {
    doc[key].as_f64().expect(key)
}

/// Absolute difference for the [0, 1] features; prints the largest so a drift inside the
/// tolerance is still seen (`--nocapture`).
fn check_features(doc: &Value, kind: &str, f: impl Fn([f32; 3]) -> [f32; 3]) {
    let tol = tolerance(doc, "feature_tolerance");
    let mut worst = 0.0f64;
    for c in doc[kind].as_array().unwrap() {
        let (input, want) = (triple(&c["in"]), triple(&c["out"]));
        let got = f(input);
        for (g, w) in got.iter().zip(want) {
            let d = (*g as f64 - w as f64).abs();
            worst = worst.max(d);
            assert!(
                d <= tol,
                "{kind} {input:?}: rust {got:?} vs python {want:?}"
            );
        }
    }
    eprintln!("{kind}: largest difference {worst:e}");
}

#[test]
fn exposure_matches_training() {
    let doc = load();
    assert_eq!(
        doc["auto_exposure_key"].as_f64(),
        Some(color::AUTO_EXPOSURE_KEY)
    );
    let tol = tolerance(&doc, "exposure_tolerance");
    let cases = doc["exposure"].as_array().unwrap();
    assert!(cases.len() >= 10);
    let mut worst = 0.0f64;
    for c in cases {
        let rgb = floats(&c["rgb"]);
        let pixels = rgb.chunks_exact(3).map(|p| [p[0], p[1], p[2]]);
        let got = color::auto_input_scale(pixels) as f64;
        let want = c["scale"].as_f64().unwrap();
        let rel = (got - want).abs() / want;
        worst = worst.max(rel);
        assert!(rel <= tol, "{}: rust {got} vs python {want}", c["name"]);
    }
    eprintln!("exposure: largest relative difference {worst:e}");
}

#[test]
fn albedo_matches_training() {
    check_features(&load(), "albedo", features::albedo);
}

#[test]
fn normal_matches_training() {
    check_features(&load(), "normal", features::normal);
}

#[test]
fn depth_matches_training() {
    let doc = load();
    let tol = tolerance(&doc, "feature_tolerance");
    for c in doc["depth"].as_array().unwrap() {
        let name = c["name"].as_str().unwrap();
        let d = floats(&c["in"]);
        let scale = features::depth_scale(d.iter().copied());
        let want_scale = c["scale"].as_f64().map(|s| s as f32);
        assert_eq!(scale, want_scale, "{name}: depth scale");
        for (x, w) in d.iter().zip(floats(&c["out"])) {
            let got = features::depth(*x, scale);
            assert!(
                (got as f64 - w as f64).abs() <= tol,
                "{name} depth {x}: rust {got} vs python {w}"
            );
        }
    }
}
