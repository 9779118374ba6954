//! `temc-render compare-sampling`: how much noise each weak sampling mode
//! (`render --sampling`) makes, as RelMSE against a reference of the tracer's own sampler
//! at a few sample counts, on a few named scenes; a Markdown table (docs/render.md's).

use std::fmt::Write;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use temc_render::film::relmse;
use temc_render::scene::Scene;
use temc_render::{render_progressive, Sampling, Settings};

/// `temc-render compare-sampling`'s options.
#[derive(clap::Args)]
pub struct Args {
    /// Named scenes, comma-separated.
    #[arg(
        long,
        default_value = "cornell-spiky,many-lights,metals,firefly",
        value_delimiter = ','
    )]
    scenes: Vec<String>,
    /// Image width and height.
    #[arg(long, default_value_t = 64)]
    size: usize,
    /// Sample counts to measure, comma-separated (one progressive render per seed).
    #[arg(long, default_value = "4,64", value_delimiter = ',')]
    spp: Vec<u32>,
    /// Samples per pixel of the reference (default sampler, its own seed).
    #[arg(long, default_value_t = 4096)]
    ref_spp: u32,
    /// Seeds per mode; the table shows the mean RelMSE over them.
    #[arg(long, default_value_t = 4)]
    seeds: u64,
    /// Output Markdown file (default: standard output).
    #[arg(long)]
    out: Option<PathBuf>,
}

/// Measures every mode and writes the table.
pub fn main(a: Args, cancel: &AtomicBool) -> Result<(), String> {
    let mut spp = a.spp.clone();
    spp.sort_unstable();
    spp.dedup();
    if spp.first() == Some(&0) || spp.is_empty() || a.ref_spp == 0 || a.seeds == 0 {
        return Err("need --spp values > 0, --ref-spp > 0 and --seeds > 0".into());
    }
    if a.size == 0 {
        return Err("--size must be at least 1".into());
    }
    // Every name is checked before the first render, not after minutes of them.
    let scenes: Vec<Scene> = a
        .scenes
        .iter()
        .map(|n| crate::named_scene(n))
        .collect::<Result<_, _>>()?;
    let mut md = header(&a, &spp);
    for sc in &scenes {
        for row in scene_rows(sc, &a, &spp, cancel)? {
            let _ = writeln!(md, "{row}");
        }
        eprintln!("compare-sampling: {} done", sc.name);
    }
    match &a.out {
        Some(p) => temc_render::output::write_bytes_atomic(p, md.as_bytes()),
        None => {
            print!("{md}");
            Ok(())
        }
    }
}

/// The table's introduction and column heads.
fn header(a: &Args, spp: &[u32]) -> String {
    let (size, ref_spp, seeds, last) = (a.size, a.ref_spp, a.seeds, spp[spp.len() - 1]);
    let mut md = format!(
        "RelMSE against a {ref_spp} spp reference of the default sampler (another seed), \
         {size}x{size} pixels, mean over {seeds} seeds; `x default` is the ratio to the \
         default sampler's RelMSE at {last} spp. Regenerate: `temc-render compare-sampling \
         --size {size} --spp {} --ref-spp {ref_spp} --seeds {seeds} --scenes {}`.\n\n",
        join(spp),
        a.scenes.join(","),
    );
    let heads: Vec<String> = spp.iter().map(|s| format!("RelMSE {s} spp")).collect();
    let _ = writeln!(
        md,
        "| scene | sampling | {} | x default |",
        heads.join(" | ")
    );
    let _ = writeln!(md, "|---|---|{}---:|", "---:|".repeat(spp.len()));
    md
}

/// One table row per mode (the default first) for scene `sc`.
fn scene_rows(
    sc: &Scene,
    a: &Args,
    spp: &[u32],
    cancel: &AtomicBool,
) -> Result<Vec<String>, String> {
    let base = Settings {
        width: a.size,
        height: a.size,
        spp: a.ref_spp,
        seed: 99,
        max_depth: 12,
        ..Settings::default()
    };
    let reference = render_at(sc, &base, &[a.ref_spp], cancel)?.remove(0);
    let modes = std::iter::once(("default", Sampling::DEFAULT))
        .chain(Sampling::MODES.iter().map(|m| (m.0, m.1)));
    let mut rows = Vec::new();
    let mut default_last = 0.0;
    for (name, sampling) in modes {
        let mut e = vec![0.0; spp.len()];
        for seed in 0..a.seeds {
            let s = Settings {
                seed: 1000 + seed,
                sampling,
                ..base
            };
            for (k, img) in render_at(sc, &s, spp, cancel)?.iter().enumerate() {
                e[k] += relmse(img, &reference) / a.seeds as f64;
            }
        }
        let last = e[e.len() - 1];
        if sampling.is_default() {
            default_last = last;
        }
        let cells: Vec<String> = e.iter().map(|v| format!("{v:.2e}")).collect();
        rows.push(format!(
            "| {} | {name} | {} | {:.2}x |",
            sc.name,
            cells.join(" | "),
            last / default_last
        ));
    }
    Ok(rows)
}

/// The colour of `sc` rendered with `s` at each of `checkpoints`.
fn render_at(
    sc: &Scene,
    s: &Settings,
    checkpoints: &[u32],
    cancel: &AtomicBool,
) -> Result<Vec<Vec<[f32; 3]>>, String> {
    let imgs = render_progressive(sc, s, checkpoints, &|_| {}, cancel)
        .map_err(|_| "cancelled".to_string())?;
    Ok(imgs.into_iter().map(|l| l.color).collect())
}

fn join(v: &[u32]) -> String {
    v.iter().map(u32::to_string).collect::<Vec<_>>().join(",")
}
