//! Threads inside one network run against one run per thread: how well tract's own
//! threads (tract-linalg's `multithread-mm` dispatch) split one tile, beside two tiles run
//! side by side, for a temc model at one window size. Measures the lever of docs/speed.md,
//! "Threads inside one tile": many-core hosts, whose memory budget caps how many tiles
//! can run at once.
//!
//! ```sh
//! cargo run --release --features tract-threads --example tract_threads -- \
//!     onnx/temc2-balanced.onnx 544 1056 2
//! ```
//! (model, window height, window width, threads; pause other work while it runs). It ends
//! with the tile plans of a 1920x1080 image under the default budget for 2 to 16 threads,
//! one tile per thread as the filter runs them (`temc::filter::tile_plan`).

use std::time::Instant;
use temc::engine::{Model, NetInput};
use temc::filter::{tile_plan, DEFAULT_MAX_MEMORY_MB};
use tract_linalg::multithread::{multithread_tract_scope, Executor};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 5 {
        return Err("usage: tract_threads MODEL.onnx HEIGHT WIDTH THREADS".into());
    }
    let model = Model::from_path(&args[1])?;
    let (h, w, threads): (usize, usize, usize) =
        (args[2].parse()?, args[3].parse()?, args[4].parse()?);
    let info = model.info();
    let hw = h * w;
    // Deterministic, image-like values: the timing does not depend on them.
    let plane = |n: usize, k: usize| -> Vec<f32> {
        (0..n).map(|i| ((i * k) % 101) as f32 / 101.0).collect()
    };
    let (chroma, luma, aux) = (
        plane(info.chroma_channels * hw, 7919),
        plane(hw, 31),
        plane(info.aux_channels * hw, 13),
    );
    let input = || NetInput {
        chroma: &chroma,
        luma: &luma,
        aux: &aux,
    };
    model.run(input(), h, w)?; // builds the plan
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    for round in 1..=3 {
        let t = Instant::now();
        model.run(input(), h, w)?;
        let one = t.elapsed().as_secs_f64();
        let t = Instant::now();
        multithread_tract_scope(Executor::multithread(threads), || model.run(input(), h, w))?;
        let inside = t.elapsed().as_secs_f64();
        let t = Instant::now();
        pool.install(|| {
            use rayon::prelude::*;
            (0..threads)
                .into_par_iter()
                .try_for_each(|_| model.run(input(), h, w).map(drop))
        })?;
        let side_by_side = t.elapsed().as_secs_f64() / threads as f64;
        println!(
            "round {round}: {h}x{w}, one thread {one:.3} s; tract's {threads} threads {inside:.3} s \
             ({:.2}x); {threads} tiles side by side {side_by_side:.3} s a tile ({:.2}x)",
            one / inside,
            one / side_by_side
        );
    }
    let (iw, ih) = (1920, 1080);
    for t in [2usize, 4, 8, 16] {
        let (p, _) = tile_plan(&model, iw, ih, t, DEFAULT_MAX_MEMORY_MB)?;
        println!(
            "{iw}x{ih} on {t} threads: {} tiles of {}x{}, {:.2}x the image's pixels",
            p.tiles.len(),
            p.window.0,
            p.window.1,
            p.cost_ratio()
        );
    }
    Ok(())
}
