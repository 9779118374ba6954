//! `temc-render`: render scenes to multi-layer EXR, generate random scenes, render data
//! sets, and benchmark the renderer.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use clap::{Parser, Subcommand};
use temc_render::{dataset, demo, format, generate, render_progressive, scene, Settings};

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
    Render {
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
        /// Longest path, in bounces.
        #[arg(long, default_value_t = 12)]
        max_depth: u32,
        /// Run the general kernel instead of the one specialised for the scene.
        #[arg(long)]
        general: bool,
        /// Output EXR.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// The whole job on defaults: render a spectral scene at low spp and a reference,
    /// denoise with temc's built-in model, write EXR + PNG, print error and time.
    Demo {
        /// Named scene.
        #[arg(long, default_value = "cornell-spiky")]
        scene: String,
        /// Image size, WxH.
        #[arg(long, default_value = "192x192")]
        size: String,
        /// Paths per pixel of the noisy render.
        #[arg(long, default_value_t = 16)]
        spp: u32,
        /// Paths per pixel of the reference.
        #[arg(long, default_value_t = 256)]
        ref_spp: u32,
        /// Built-in model: fast, balanced or high.
        #[arg(long, default_value = "balanced")]
        quality: String,
        /// Output folder.
        #[arg(long, default_value = "demo-out")]
        out: PathBuf,
    },
    /// List the named scenes.
    Scenes,
    /// Print a random scene file.
    Generate {
        /// Seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
    /// Render a data set of noisy/reference pairs (resumable).
    Dataset {
        /// Generated scenes.
        #[arg(long, default_value_t = 100)]
        count: usize,
        /// Image width and height.
        #[arg(long, default_value_t = 256)]
        size: usize,
        /// Noisy sample counts, comma-separated.
        #[arg(long, default_value = "4,16,64,256", value_delimiter = ',')]
        spp: Vec<u32>,
        /// Reference sample count.
        #[arg(long, default_value_t = 4096)]
        ref_spp: u32,
        /// Also write the reference render at these sample counts (noisy targets for
        /// Noise2Noise training), comma-separated.
        #[arg(long, value_delimiter = ',')]
        ref_prefix_spp: Vec<u32>,
        /// Base seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Leave out the named stress scenes (otherwise rendered into the test split).
        #[arg(long)]
        no_named: bool,
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
    },
    /// Time the specialised kernels against the general one on every named scene, and
    /// the throughput on the Cornell box; writes a Markdown report.
    Bench {
        /// Image width and height.
        #[arg(long, default_value_t = 96)]
        size: usize,
        /// Samples per pixel of the timed renders.
        #[arg(long, default_value_t = 32)]
        spp: u32,
        /// Samples per pixel of the references.
        #[arg(long, default_value_t = 1024)]
        ref_spp: u32,
        /// Output Markdown file.
        #[arg(long)]
        out: PathBuf,
    },
}

fn main() -> ExitCode {
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
    match run(cli, &cancel) {
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

fn load_scene(name: Option<String>, file: Option<PathBuf>) -> Result<scene::Scene, String> {
    match (name, file) {
        (_, Some(f)) => format::load(&f),
        (n, None) => {
            let n = n.unwrap_or_else(|| "cornell-spiky".into());
            scene::named(&n).ok_or_else(|| {
                format!("unknown scene {n:?} (known: {})", scene::names().join(", "))
            })
        }
    }
}

fn run(cli: Cli, cancel: &AtomicBool) -> Result<(), String> {
    match cli.command {
        Command::Scenes => {
            for (n, what, _) in scene::NAMED {
                println!("{n:14} {what}");
            }
            Ok(())
        }
        Command::Demo {
            scene,
            size,
            spp,
            ref_spp,
            quality,
            out,
        } => {
            let quality = match quality.as_str() {
                "fast" => temc::filter::Quality::Fast,
                "balanced" => temc::filter::Quality::Balanced,
                "high" => temc::filter::Quality::High,
                q => return Err(format!("--quality {q:?}: expected fast, balanced or high")),
            };
            let o = demo::Options {
                scene,
                size: parse_size(&size)?,
                spp,
                ref_spp,
                quality,
                out,
            };
            let t = Instant::now();
            let r = demo::run(&o, &|line| eprintln!("temc-render demo: {line}"))?;
            println!(
                "{} {}x{}: rendered {} spp in {:.2} s, reference {} spp in {:.1} s",
                o.scene, o.size.0, o.size.1, o.spp, r.render_s, o.ref_spp, r.reference_s
            );
            println!(
                "denoised with the built-in TEMC-2 ({:?}) in {:.3} s on {} threads",
                o.quality, r.denoise_s, r.threads
            );
            let ratio = r.noisy_relmse / r.denoised_relmse.max(1e-30);
            println!(
                "RelMSE against the reference: noisy {:.4e}, denoised {:.4e} ({})",
                r.noisy_relmse,
                r.denoised_relmse,
                if ratio >= 1.0 {
                    format!("{ratio:.1}x lower")
                } else {
                    format!("{:.1}x higher: the denoiser made it worse", 1.0 / ratio)
                }
            );
            for f in &r.files {
                println!("wrote {}", f.display());
            }
            eprintln!(
                "temc-render demo: done in {:.1} s",
                t.elapsed().as_secs_f64()
            );
            Ok(())
        }
        Command::Generate { seed } => {
            print!("{}", generate::scene_text(seed));
            Ok(())
        }
        Command::Render {
            scene: name,
            file,
            spp,
            size,
            seed,
            max_depth,
            general,
            output,
        } => {
            let sc = load_scene(name, file)?;
            let (w, h) = parse_size(&size)?;
            if spp == 0 {
                return Err("--spp must be at least 1".into());
            }
            let settings = Settings {
                width: w,
                height: h,
                spp,
                seed,
                max_depth,
                specialise: !general,
            };
            let kernel = temc_render::kernel_for(&sc, &settings);
            let b = bar(h as u64);
            let t = Instant::now();
            let layers = render_progressive(
                &sc,
                &settings,
                &[spp],
                &|rows| b.set_position(rows as u64),
                cancel,
            )
            .map_err(|_| "cancelled".to_string())?
            .pop()
            .expect("one checkpoint");
            b.finish_and_clear();
            let secs = t.elapsed().as_secs_f64();
            layers.write_exr(&output)?;
            eprintln!(
                "temc-render: {} {w}x{h} at {spp} spp in {secs:.2} s ({:.2} M paths/s, {kernel:?}) -> {}",
                sc.name,
                (w * h) as f64 * spp as f64 / secs / 1e6,
                output.display()
            );
            Ok(())
        }
        Command::Dataset {
            count,
            size,
            spp,
            ref_spp,
            ref_prefix_spp,
            seed,
            no_named,
            out,
        } => {
            let opts = dataset::Options {
                count,
                size,
                spp,
                ref_spp,
                seed,
                named: !no_named,
                ref_prefix_spp,
            };
            let t = Instant::now();
            let b = bar(size as u64);
            let m = dataset::run(
                &opts,
                &out,
                &|line| {
                    if b.is_hidden() {
                        eprintln!("{line}");
                    } else {
                        b.println(line);
                    }
                },
                &|rows| b.set_position(rows as u64 % (size as u64 + 1)),
                cancel,
            )?;
            b.finish_and_clear();
            let n = m.scenes.len().max(1) as f64;
            eprintln!(
                "temc-render: {} scenes in {} ({:.0} s this run). Render cost: noisy {:.0} s ({:.1} s/scene), references {:.0} s ({:.1} s/scene).",
                m.scenes.len(),
                out.display(),
                t.elapsed().as_secs_f64(),
                m.seconds_noisy,
                m.seconds_noisy / n,
                m.seconds_reference,
                m.seconds_reference / n
            );
            Ok(())
        }
        Command::Bench {
            size,
            spp,
            ref_spp,
            out,
        } => bench(size, spp, ref_spp, &out, cancel),
    }
}

fn relmse(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    let mut e = 0.0;
    for (x, r) in a.iter().zip(b) {
        for k in 0..3 {
            e += ((x[k] - r[k]) as f64).powi(2) / ((r[k] as f64).powi(2) + 0.01);
        }
    }
    e / (3 * a.len()) as f64
}

fn bench(
    size: usize,
    spp: u32,
    ref_spp: u32,
    out: &PathBuf,
    cancel: &AtomicBool,
) -> Result<(), String> {
    use std::fmt::Write;
    let threads = rayon::current_num_threads();
    let mut md = String::new();
    let timed =
        |sc: &scene::Scene, s: &Settings| -> Result<(temc_render::film::Layers, f64), String> {
            let t = Instant::now();
            let img = render_progressive(sc, s, &[s.spp], &|_| {}, cancel)
                .map_err(|_| "cancelled".to_string())?
                .pop()
                .unwrap();
            Ok((img, t.elapsed().as_secs_f64()))
        };
    // Throughput on the Cornell box.
    let cornell = scene::named("cornell-spiky").unwrap();
    let s = Settings {
        width: 256,
        height: 256,
        spp: 16,
        seed: 7,
        max_depth: 12,
        specialise: true,
    };
    timed(&cornell, &Settings { spp: 1, ..s })?; // warm-up
    let (_, secs) = timed(&cornell, &s)?;
    let paths = (256 * 256 * 16) as f64;
    let _ = writeln!(md, "# temc-render benchmark\n");
    let _ = writeln!(
        md,
        "Regenerate: `cargo run --release -p temc-render -- bench --out docs/render-bench.md` \
         ({threads} threads; CPU: {}).\n",
        cpu_name()
    );
    let _ = writeln!(md, "## Throughput\n");
    let _ = writeln!(
        md,
        "`cornell-spiky`, 256x256 at 16 spp, {threads} threads: **{:.2} M camera paths/s** \
         ({:.2} s for {paths:.0} paths, up to 12 bounces with next-event estimation).\n",
        paths / secs / 1e6,
        secs
    );
    let _ = writeln!(md, "## What specialisation saves\n");
    let _ = writeln!(
        md,
        "Each named scene rendered at {size}x{size}, {spp} spp, with the kernel the scene \
         calls for and with the general kernel (one wavelength per path from the start, \
         emitter-spectrum wavelength sampling, every material branch). Error is RelMSE \
         against a {ref_spp} spp reference from the specialised kernel with another seed. \
         Both kernels are unbiased, so error falls as 1/time for each; *time to equal \
         error* is the ratio of time x RelMSE (general / specialised): how many times \
         longer the general kernel must run to match the specialised one's noise.\n"
    );
    let _ = writeln!(
        md,
        "| scene | kernel chosen | time spec. (s) | time general (s) | RelMSE spec. | RelMSE general | time to equal error |"
    );
    let _ = writeln!(md, "|---|---|---:|---:|---:|---:|---:|");
    for (name, _, _) in scene::NAMED {
        let sc = scene::named(name).unwrap();
        let base = Settings {
            width: size,
            height: size,
            spp,
            seed: 11,
            max_depth: 12,
            specialise: true,
        };
        let (reference, _) = timed(
            &sc,
            &Settings {
                spp: ref_spp,
                seed: 99,
                ..base
            },
        )?;
        let (a, ta) = timed(&sc, &base)?;
        let (b, tb) = timed(
            &sc,
            &Settings {
                specialise: false,
                ..base
            },
        )?;
        let (ea, eb) = (
            relmse(&a.color, &reference.color),
            relmse(&b.color, &reference.color),
        );
        let k = temc_render::kernel_for(&sc, &base);
        let kernel = format!(
            "{}{}{}",
            if k.dispersion {
                "split at dispersion"
            } else {
                "4 wavelengths"
            },
            if k.transmission { ", refraction" } else { "" },
            if k.emitter_wavelengths {
                ", emitter λ sampling"
            } else {
                ""
            }
        );
        let _ = writeln!(
            md,
            "| {name} | {kernel} | {ta:.2} | {tb:.2} | {ea:.2e} | {eb:.2e} | {:.2}x |",
            (tb * eb) / (ta * ea)
        );
        eprintln!("bench: {name} done");
    }
    let _ = writeln!(
        md,
        "\nThe furnace has no path noise at all (every path returns exactly 1 per \
         wavelength), so its row isolates wavelength-sampling noise: four stratified \
         wavelengths per path against one. Timings are single runs on a shared machine; \
         read the last column as a factor, not to two digits."
    );
    let tmp = out.with_extension("tmp");
    std::fs::write(&tmp, md).map_err(|e| format!("{}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, out).map_err(|e| format!("{}: {e}", out.display()))?;
    eprintln!("temc-render: wrote {}", out.display());
    Ok(())
}

fn cpu_name() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|c| {
            c.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|s| s.trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into())
}
