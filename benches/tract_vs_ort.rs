//! Times temc's tract engine on an ONNX model, for comparison with onnxruntime on the same
//! file (training/temc_train/bench_ort.py); scripts/bench-tract-vs-ort runs both and writes
//! docs/tract-vs-onnxruntime.md.
//!
//! cargo bench --bench tract_vs_ort -- --model M.onnx --size 256 [--threads 2] [--reps 5]
//!     [--profile]
//!
//! `--threads N` runs N images at once on the one shared plan (how temc runs tiles);
//! throughput is images x pixels / wall time. `--profile` times every node of one run and
//! prints the total per op kind. Output: one JSON object per line.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use temc::engine::{Model, NetInput};
use tract_onnx::prelude::*;

struct Args {
    model: String,
    size: usize,
    threads: usize,
    reps: usize,
    profile: bool,
}

fn args() -> Args {
    let mut a = Args {
        model: String::new(),
        size: 256,
        threads: 1,
        reps: 5,
        profile: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut val = || it.next().unwrap_or_else(|| panic!("{k} needs a value"));
        match k.as_str() {
            "--model" => a.model = val(),
            "--size" => a.size = val().parse().expect("--size"),
            "--threads" => a.threads = val().parse().expect("--threads"),
            "--reps" => a.reps = val().parse().expect("--reps"),
            "--profile" => a.profile = true,
            "--bench" => {}
            other => panic!("unknown argument {other}"),
        }
    }
    assert!(!a.model.is_empty(), "--model is required");
    a
}

fn inputs(model: &Model, n: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    // Deterministic, image-like values in [0, 1]; the time does not depend on them.
    let wave = |c: usize| -> Vec<f32> {
        (0..c * n)
            .map(|i| 0.5 + 0.4 * ((i as f32) * 0.013).sin())
            .collect()
    };
    (
        wave(model.info().chroma_channels),
        wave(1),
        wave(model.info().aux_channels),
    )
}

fn main() {
    let a = args();
    let model = Model::from_path(&a.model).expect("load model");
    let s = a.size;
    let (chroma, luma, aux) = inputs(&model, s * s);
    let input = NetInput {
        chroma: &chroma,
        luma: &luma,
        aux: &aux,
    };
    let t0 = Instant::now();
    let plan = model.plan(s, s).expect("plan");
    let plan_s = t0.elapsed().as_secs_f64();
    model.run(input, s, s).expect("warm-up run");

    if a.profile {
        profile(&plan, &chroma, &luma, &aux, s, &model);
    }

    let mut times = Vec::with_capacity(a.reps);
    for _ in 0..a.reps {
        let t = Instant::now();
        std::thread::scope(|scope| {
            for _ in 0..a.threads {
                scope.spawn(|| model.run(input, s, s).expect("run"));
            }
        });
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    let median = times[times.len() / 2];
    let pixels = (a.threads * s * s) as f64;
    println!(
        "{{\"engine\":\"tract\",\"model\":{:?},\"width\":{},\"size\":{s},\"threads\":{},\"config\":\"{} image(s) in parallel, shared plan\",\"reps\":{},\"min_s\":{:.5},\"median_s\":{median:.5},\"plan_s\":{plan_s:.4},\"mpix_per_s\":{:.4}}}",
        a.model,
        model.info().width,
        a.threads,
        a.threads,
        a.reps,
        times[0],
        pixels / median / 1e6
    );
}

fn profile(
    plan: &std::sync::Arc<TypedSimplePlan>,
    chroma: &[f32],
    luma: &[f32],
    aux: &[f32],
    s: usize,
    model: &Model,
) {
    let shapes = [
        (chroma, model.info().chroma_channels),
        (luma, 1),
        (aux, model.info().aux_channels),
    ];
    let mut per_op: BTreeMap<String, (Duration, usize)> = BTreeMap::new();
    let mut state = plan.spawn().expect("state");
    // Inputs in graph order: the engine validated the names; the bench models list them as
    // chroma, luma, aux, which the export contract fixes.
    let ins: TVec<TValue> = shapes
        .iter()
        .map(|(d, c)| Tensor::from_shape(&[1, *c, s, s], d).unwrap().into())
        .collect();
    let total = Instant::now();
    state
        .run_plan_with_eval(ins, |ctx, st, node, inputs| {
            let t = Instant::now();
            let r = tract_onnx::tract_core::plan::eval(ctx, st, node, inputs);
            let e = per_op.entry(node.op().name().to_string()).or_default();
            e.0 += t.elapsed();
            e.1 += 1;
            r
        })
        .expect("profiled run");
    let total = total.elapsed().as_secs_f64();
    let mut rows: Vec<_> = per_op.into_iter().collect();
    rows.sort_by_key(|r| std::cmp::Reverse(r.1 .0));
    for (op, (d, n)) in rows {
        println!(
            "{{\"profile\":{op:?},\"nodes\":{n},\"s\":{:.5},\"share\":{:.3}}}",
            d.as_secs_f64(),
            d.as_secs_f64() / total
        );
    }
}
