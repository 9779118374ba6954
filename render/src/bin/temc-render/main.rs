//! `temc-render`: render scenes to multi-layer EXR, generate random scenes, render data
//! sets, run the denoising demo, and benchmark the renderer.
//!
//! The applications are modules of this binary, not of the tracer library: [`dataset`]
//! (with [`part`], the partition for clusters, and [`merge`], which joins the parts),
//! [`compare_sampling`] (the noise of the weak sampling modes),
//! `demo` and `bench` (the two that need the denoiser, temc: feature `denoise`, on by
//! default).

#[cfg(feature = "denoise")]
mod bench;
mod compare_sampling;
mod dataset;
#[cfg(feature = "denoise")]
mod demo;
mod merge;
mod part;

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use clap::{Args, Parser, Subcommand};
use temc_render::description::families::{self, Families};
use temc_render::description::{format, held_out, named};
use temc_render::scene::Scene;
use temc_render::{render_progressive, Sampling, Settings};

#[derive(Parser)]
#[command(
    name = "temc-render",
    version,
    about = "Spectral path tracer for temc's data"
)]
struct Cli {
    /// Worker threads (default: all cores).
    #[arg(long, global = true)]
    threads: Option<usize>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a named scene or a scene file to one multi-layer EXR.
    Render(RenderArgs),
    /// The whole job on defaults: render a spectral scene at low spp and a reference,
    /// denoise with temc's built-in model, write EXR + PNG, print error and time.
    #[cfg(feature = "denoise")]
    Demo(demo::Args),
    /// List the named scenes.
    Scenes,
    /// Print a random scene file.
    Generate {
        /// Seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// The generated families to draw from, as `dataset --families`: v2 (a room or an
        /// open floor, the spectral-v2 set's scenes) or all (one family per seed).
        #[arg(long, default_value = "v2", conflicts_with = "family")]
        families: Families,
        /// One family instead: a generated one (room, open, sun-sky, small-lights,
        /// glossy-interior, caustic-fireflies, fine-texture) or one held out of training
        /// (window, corridor: the data set's `holdout-*` test scenes).
        #[arg(long)]
        family: Option<String>,
    },
    /// Render a data set of noisy/reference pairs (resumable), or with --part I/N one part
    /// of it, for a cluster.
    Dataset(dataset::Args),
    /// Join the manifests of a data set's parts (dataset --part I/N) into its
    /// manifest.json, once every part has finished.
    MergeManifests(merge::Args),
    /// Time the specialised kernels against the general one on every named scene, and
    /// the throughput on the Cornell box; writes a Markdown report.
    #[cfg(feature = "denoise")]
    Bench(bench::Args),
    /// Measure the noise of each weak sampling mode (render --sampling) against the
    /// default sampler's reference on named scenes; writes a Markdown table.
    CompareSampling(compare_sampling::Args),
}

#[derive(Args)]
struct RenderArgs {
    /// Named scene (see `temc-render scenes`).
    #[arg(long, conflicts_with = "file")]
    scene: Option<String>,
    /// Scene file (format: docs/render.md).
    #[arg(long)]
    file: Option<PathBuf>,
    /// Paths per pixel.
    #[arg(long, default_value_t = 16)]
    spp: u32,
    /// Image size, WxH.
    #[arg(long, default_value = "256x256")]
    size: String,
    /// Seed: the same seed gives the same image.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Longest path, in scattering events (0: emitters seen directly; 1: direct lighting).
    #[arg(long, default_value_t = 12)]
    max_depth: u32,
    /// Run the general kernel instead of the one specialised for the scene.
    #[arg(long)]
    general: bool,
    /// Weaker sampling that imitates other renderers' noise, comma-separated: bsdf-only,
    /// uniform-lights, no-mis, uniform-wavelength, early-roulette (docs/render.md); every
    /// mode converges to the same image. "default" is the tracer's own sampler.
    #[arg(long, default_value = "default", value_name = "MODES")]
    sampling: Sampling,
    /// Output EXR.
    #[arg(short, long)]
    output: PathBuf,
}

/// A closed output pipe ends the program quietly, as it does other Unix tools
/// (`temc-render generate --seed 1 | head`): Rust ignores SIGPIPE, so a print to a closed
/// pipe panicked instead.
fn exit_quietly_on_closed_pipe() {
    #[cfg(unix)]
    // SAFETY: restores the default action of one signal, before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn main() -> ExitCode {
    exit_quietly_on_closed_pipe();
    let cli = Cli::parse();
    if let Some(n) = cli.threads {
        if let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build_global()
        {
            eprintln!("temc-render: {e}");
            return ExitCode::FAILURE;
        }
    }
    // Ctrl-C stops the render between rows; outputs are written atomically, so nothing
    // partial is left behind.
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let c = cancel.clone();
        let _ = ctrlc::set_handler(move || {
            if c.swap(true, Ordering::SeqCst) {
                std::process::exit(130); // second Ctrl-C: leave now
            }
        });
    }
    match run(cli.command, &cancel) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if cancel.load(Ordering::SeqCst) => {
            eprintln!("temc-render: interrupted ({e}); no partial output written");
            ExitCode::from(130)
        }
        Err(e) => {
            eprintln!("temc-render: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(command: Command, cancel: &AtomicBool) -> Result<(), String> {
    match command {
        Command::Scenes => {
            for (n, what, _) in named::NAMED {
                println!("{n:14} {what}");
            }
            Ok(())
        }
        Command::Generate {
            seed,
            families,
            family: None,
        } => {
            print!("{}", families::scene(families, seed).1);
            Ok(())
        }
        Command::Generate {
            seed,
            family: Some(f),
            ..
        } => {
            let text = families::family_text(&f, seed)
                .or_else(|| held_out::scene_text(&f, seed))
                .ok_or_else(|| {
                    format!(
                        "unknown family '{f}' (one of {}, {})",
                        families::FAMILIES.join(", "),
                        held_out::FAMILIES.join(", ")
                    )
                })?;
            print!("{text}");
            Ok(())
        }
        Command::Render(args) => render(args, cancel),
        #[cfg(feature = "denoise")]
        Command::Demo(args) => demo::main(args),
        Command::Dataset(args) => dataset::main(args, cancel),
        Command::MergeManifests(args) => merge::main(args),
        #[cfg(feature = "denoise")]
        Command::Bench(args) => bench::main(args, cancel),
        Command::CompareSampling(args) => compare_sampling::main(args, cancel),
    }
}

/// `temc-render render`.
fn render(a: RenderArgs, cancel: &AtomicBool) -> Result<(), String> {
    let sc = load_scene(a.scene, a.file)?;
    let (w, h) = parse_size(&a.size)?;
    if a.spp == 0 {
        return Err("--spp must be at least 1".into());
    }
    let settings = Settings {
        width: w,
        height: h,
        spp: a.spp,
        seed: a.seed,
        max_depth: a.max_depth,
        kernel: a
            .general
            .then_some(temc_render::integrator::Kernel::GENERAL),
        sampling: a.sampling,
    };
    let kernel = temc_render::kernel_for(&sc, &settings);
    let b = bar(h as u64);
    let t = Instant::now();
    let layers = render_progressive(
        &sc,
        &settings,
        &[a.spp],
        &|rows| b.set_position(rows as u64),
        cancel,
    )
    .map_err(|_| "cancelled".to_string())?
    .pop()
    .expect("one checkpoint");
    b.finish_and_clear();
    let secs = t.elapsed().as_secs_f64();
    layers.write_exr(&a.output)?;
    eprintln!(
        "temc-render: {} {w}x{h} at {} spp in {secs:.2} s ({:.2} M paths/s, {kernel:?}, sampling {}) -> {}",
        sc.name,
        a.spp,
        (w * h) as f64 * a.spp as f64 / secs / 1e6,
        a.sampling,
        a.output.display()
    );
    Ok(())
}

/// A progress bar on stderr, hidden when stderr is not a terminal.
fn bar(len: u64) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len);
    if !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    bar
}

fn parse_size(size: &str) -> Result<(usize, usize), String> {
    size.split_once('x')
        .and_then(|(w, h)| Some((w.parse::<usize>().ok()?, h.parse::<usize>().ok()?)))
        .filter(|&(w, h)| w > 0 && h > 0 && w <= 16384 && h <= 16384)
        .ok_or_else(|| format!("--size {size:?}: expected WxH, e.g. 256x256"))
}

fn load_scene(name: Option<String>, file: Option<PathBuf>) -> Result<Scene, String> {
    match (name, file) {
        (_, Some(f)) => format::load(&f),
        (n, None) => named_scene(&n.unwrap_or_else(|| "cornell-spiky".into())),
    }
}

/// A named scene, or an error that lists the names.
fn named_scene(n: &str) -> Result<Scene, String> {
    named::scene(n)
        .ok_or_else(|| format!("unknown scene {n:?} (known: {})", named::names().join(", ")))
}
