//! tract against onnxruntime: every architecture's test model, run by the engine on the
//! golden inputs, must match the golden filter logits (every pyramid level) that
//! onnxruntime computed (max abs 1e-4).
//! Models and goldens are made by `python -m temc_train.drivers.export --golden tests/data`.
//! The shipped, trained models in onnx/ are checked the same way against the goldens
//! `scripts/ship-models` wrote for them in tests/data/golden/shipped/. (The baselines
//! return as shipped files with issue 15's equal-budget runs.)

mod common;

use std::path::PathBuf;

use temc::engine::{Model, NetInput};

const ARCHS: [&str; 4] = ["ae", "demc", "temc1", "temc2"];
const TEST_WIDTH: &str = "w0.0625";

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data")
}

fn check_arch(arch: &str) {
    let name = format!("{arch}_{TEST_WIDTH}");
    let model = Model::from_path(data_dir().join("models").join(format!("{name}.onnx")))
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(model.info().architecture, arch);
    assert!(
        model.info().is_untrained(),
        "test models are untrained by contract"
    );
    check_golden(&model, &name, &data_dir().join("golden").join(&name));
}

/// A shipped model (path under onnx/) against its golden: trained, of the named
/// architecture, and matching onnxruntime.
fn check_shipped(file: &str, arch: &str) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("onnx")
        .join(format!("{file}.onnx"));
    let model = Model::from_path(&path).unwrap_or_else(|e| panic!("{file}: {e}"));
    assert_eq!(model.info().architecture, arch);
    assert!(!model.info().is_untrained(), "{file}: shipped untrained");
    let name = file.rsplit('/').next().unwrap();
    check_golden(
        &model,
        file,
        &data_dir().join("golden").join("shipped").join(name),
    );
}

fn check_golden(model: &Model, name: &str, golden: &std::path::Path) {
    let chroma = common::read_npy(&golden.join("chroma.npy"));
    let luma = common::read_npy(&golden.join("luma.npy"));
    let aux = common::read_npy(&golden.join("aux.npy"));
    let (h, w) = (chroma.shape[2], chroma.shape[3]);
    let input = NetInput {
        chroma: &chroma.data,
        luma: &luma.data,
        aux: &aux.data,
    };
    let out = model
        .run(input, h, w)
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    let got = out.levels().unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(
        got.len(),
        model.info().levels,
        "{name}: one output per level"
    );
    for (level, got) in got.iter().enumerate() {
        let want = common::read_npy(&golden.join(format!("filters{level}.npy")));
        let c = model.info().filter_channels();
        assert_eq!(want.shape, vec![1, c, h >> level, w >> level]);
        // Relative to the level's largest logit when that exceeds 1 (export.max_diff):
        // trained logits reach tens, and an error e scales a weight by exp(e).
        let scale = want.data.iter().fold(1f32, |m, v| m.max(v.abs()));
        let max_diff = got
            .iter()
            .zip(&want.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0f32, f32::max)
            / scale;
        assert!(
            got.iter().all(|v| v.is_finite()),
            "{name}: non-finite output"
        );
        assert!(
            max_diff <= 1e-4,
            "{name} level {level}: max abs diff {max_diff:e} > 1e-4"
        );
        // The output must actually depend on the input: a constant output would hide a
        // broken graph behind a matching golden.
        let spread = want.data.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v))
            - want.data.iter().fold(f32::INFINITY, |m, &v| m.min(v));
        assert!(spread > 1e-3, "{name}: golden output is constant");
        println!("{name} level {level}: {h}x{w}, max abs diff vs onnxruntime {max_diff:.2e}");
    }
}

#[test]
fn shipped_temc2_models_match_onnxruntime() {
    for q in ["fast", "balanced", "high"] {
        check_shipped(&format!("temc2-{q}"), "temc2");
    }
}

#[test]
fn ae_matches_onnxruntime() {
    check_arch(ARCHS[0]);
}

#[test]
fn demc_matches_onnxruntime() {
    check_arch(ARCHS[1]);
}

#[test]
fn temc1_matches_onnxruntime() {
    check_arch(ARCHS[2]);
}

#[test]
fn temc2_matches_onnxruntime() {
    check_arch(ARCHS[3]);
}

#[test]
fn plans_are_cached_per_size_and_sizes_checked() {
    let model = Model::from_path(
        data_dir()
            .join("models")
            .join(format!("temc2_{TEST_WIDTH}.onnx")),
    )
    .unwrap();
    let a = model.info().alignment;
    assert!(model
        .run(
            NetInput {
                chroma: &[],
                luma: &[],
                aux: &[]
            },
            a + 1,
            a
        )
        .is_err());
    assert!(model.plan(0, a).is_err());
    let n = a * a;
    let chroma = vec![0.5; 2 * n];
    let luma = vec![0.5; n];
    let aux = vec![0.5; 7 * n];
    let input = NetInput {
        chroma: &chroma,
        luma: &luma,
        aux: &aux,
    };
    let first = model.run(input, a, a).unwrap();
    let again = model.run(input, a, a).unwrap();
    assert_eq!(
        first.levels().unwrap(),
        again.levels().unwrap(),
        "same plan, same input: same output"
    );
    assert_eq!(model.cached_sizes(), vec![(a, a)]);
    // Wrong buffer lengths are refused, not read past.
    let short = NetInput {
        chroma: &chroma[1..],
        luma: &luma,
        aux: &aux,
    };
    assert!(model.run(short, a, a).is_err());
}

#[test]
fn garbage_bytes_are_refused_with_an_error() {
    for bytes in [&b""[..], b"not an onnx model", &[0xff; 64]] {
        assert!(Model::from_bytes(bytes).is_err());
    }
}
