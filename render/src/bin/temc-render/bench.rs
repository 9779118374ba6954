//! `temc-render bench`: throughput and equal-error efficiency on the benchmark scenes
//! (optionally beside another build of temc-render, run as a subprocess in the same run),
//! and what kernel specialisation saves on every named scene against the fair general
//! kernel, as a Markdown report (docs/render-bench.md).

use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use temc_render::description::named;
use temc_render::film::relmse;
use temc_render::integrator::Kernel;
use temc_render::output::write_bytes_atomic;
use temc_render::scene::Scene;
use temc_render::{render_progressive, Settings};

/// The scenes of the throughput and efficiency table.
const BENCH_SCENES: [&str; 4] = ["cornell-spiky", "metals", "textured", "many-lights"];

/// `temc-render bench`'s options.
#[derive(clap::Args)]
pub struct Args {
    /// Image width and height of the specialisation table.
    #[arg(long, default_value_t = 96)]
    size: usize,
    /// Samples per pixel of the specialisation table's timed renders.
    #[arg(long, default_value_t = 32)]
    spp: u32,
    /// Samples per pixel of the references (both tables).
    #[arg(long, default_value_t = 1024)]
    ref_spp: u32,
    /// Samples per pixel of the efficiency table's timed renders (at 256x256).
    #[arg(long, default_value_t = 16)]
    eff_spp: u32,
    /// Another temc-render binary (e.g. an earlier commit's) to measure beside this one:
    /// it renders the same scene files through its `render` command.
    #[arg(long)]
    baseline: Option<PathBuf>,
    /// What the baseline is, for the report (e.g. the commit it was built from).
    #[arg(long, requires = "baseline")]
    baseline_label: Option<String>,
    /// Output Markdown file.
    #[arg(long)]
    out: PathBuf,
}

/// Runs the benchmark and writes the report.
pub fn main(a: Args, cancel: &AtomicBool) -> Result<(), String> {
    let threads = rayon::current_num_threads();
    let mut md = String::new();
    let _ = writeln!(md, "# temc-render benchmark\n");
    let _ = writeln!(
        md,
        "Regenerate: `cargo run --release -p temc-render -- bench --out docs/render-bench.md \
         [--baseline OLD-temc-render --baseline-label COMMIT]` ({threads} threads; CPU: {}).\n",
        cpu_name()
    );
    efficiency(&mut md, &a, cancel)?;
    specialisation(&mut md, &a, cancel)?;
    write_bytes_atomic(&a.out, md.as_bytes())?;
    eprintln!("temc-render: wrote {}", a.out.display());
    Ok(())
}

/// A `size` x `size` render at `spp` with the scene's own kernel and max depth 12 (the
/// baseline's `render` command is given the same).
fn square(size: usize, spp: u32, seed: u64) -> Settings {
    Settings {
        width: size,
        height: size,
        spp,
        seed,
        max_depth: 12,
        kernel: None,
        sampling: temc_render::Sampling::DEFAULT,
    }
}

/// One measured render: colour and the seconds the render itself took.
struct Timed {
    color: Vec<[f32; 3]>,
    secs: f64,
}

/// Renders `sc` at `s.spp` with this build.
fn timed(sc: &Scene, s: &Settings, cancel: &AtomicBool) -> Result<Timed, String> {
    let t = Instant::now();
    let img = render_progressive(sc, s, &[s.spp], &|_| {}, cancel)
        .map_err(|_| "cancelled".to_string())?
        .pop()
        .expect("one checkpoint");
    Ok(Timed {
        color: img.color,
        secs: t.elapsed().as_secs_f64(),
    })
}

/// Renders a scene file with another temc-render binary; the time is the render time it
/// reports (without start-up and EXR writing).
fn timed_external(
    bin: &Path,
    file: &Path,
    size: usize,
    spp: u32,
    seed: u64,
) -> Result<Timed, String> {
    let out = file.with_extension(format!("{spp}-{seed}.exr"));
    let res = Command::new(bin)
        .args([
            "--threads",
            &rayon::current_num_threads().to_string(),
            "render",
        ])
        .arg("--file")
        .arg(file)
        .args([
            "--size",
            &format!("{size}x{size}"),
            "--spp",
            &spp.to_string(),
        ])
        .args(["--seed", &seed.to_string(), "--max-depth", "12", "-o"])
        .arg(&out)
        .output()
        .map_err(|e| format!("{}: {e}", bin.display()))?;
    let stderr = String::from_utf8_lossy(&res.stderr);
    if !res.status.success() {
        return Err(format!("{} failed: {stderr}", bin.display()));
    }
    let secs = stderr
        .split(" spp in ")
        .nth(1)
        .and_then(|t| t.split(" s ").next())
        .and_then(|t| t.trim().parse::<f64>().ok())
        .ok_or_else(|| format!("no render time in {}'s output: {stderr}", bin.display()))?;
    let img = temc::io::read(&out).map_err(|e| e.to_string())?;
    let _ = std::fs::remove_file(&out);
    let rgb = img.color.ok_or("the baseline's EXR has no colour")?;
    Ok(Timed {
        color: rgb.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        secs,
    })
}

/// Paths per second and time x RelMSE of one build on one scene.
struct Efficiency {
    mpaths: f64,
    secs: f64,
    relmse: f64,
}

impl Efficiency {
    fn product(&self) -> f64 {
        self.secs * self.relmse
    }
}

/// The throughput and efficiency table: 256x256, `eff_spp` against a `ref_spp` reference
/// of the same build, for this build and the baseline.
fn efficiency(md: &mut String, a: &Args, cancel: &AtomicBool) -> Result<(), String> {
    let (size, spp) = (256usize, a.eff_spp);
    let paths = (size * size) as f64 * spp as f64;
    let dir = std::env::temp_dir().join(format!("temc-render-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let _ = writeln!(md, "## Throughput and efficiency\n");
    let _ = writeln!(
        md,
        "Each scene at {size}x{size}, {spp} spp, max depth 12, timed once after a warm-up; \
         error is RelMSE against a {} spp reference **of the same build** (another seed). \
         *Efficiency* is 1 / (time x RelMSE): the ratio column is how many times less time \
         this build needs for the same error.{}\n",
        a.ref_spp,
        match (&a.baseline, &a.baseline_label) {
            (Some(_), label) => format!(
                " The baseline ({}) renders the same scene files through its own `render` \
                 command in the same run (its reported render time, without start-up or EXR \
                 writing).",
                label.as_deref().unwrap_or("another build")
            ),
            (None, _) => String::new(),
        }
    );
    let base = a.baseline.is_some();
    let _ = writeln!(
        md,
        "| scene | M paths/s | time (s) | RelMSE | time x RelMSE |{}",
        if base {
            " baseline M paths/s | baseline time x RelMSE | paths/s ratio | efficiency ratio |"
        } else {
            ""
        }
    );
    let _ = writeln!(
        md,
        "|---|---:|---:|---:|---:|{}",
        if base { "---:|---:|---:|---:|" } else { "" }
    );
    for name in BENCH_SCENES {
        let sc = named::scene(name).expect("a named scene");
        let s = square(size, spp, 7);
        timed(&sc, &Settings { spp: 1, ..s }, cancel)?; // warm-up
        let reference = timed(
            &sc,
            &Settings {
                spp: a.ref_spp,
                seed: 99,
                ..s
            },
            cancel,
        )?;
        let t = timed(&sc, &s, cancel)?;
        let ours = Efficiency {
            mpaths: paths / t.secs / 1e6,
            secs: t.secs,
            relmse: relmse(&t.color, &reference.color),
        };
        let mut row = format!(
            "| {name} | {:.2} | {:.2} | {:.2e} | {:.2e} |",
            ours.mpaths,
            ours.secs,
            ours.relmse,
            ours.product()
        );
        if let Some(bin) = &a.baseline {
            let file = dir.join(format!("{name}.scene"));
            let text = named::NAMED.iter().find(|n| n.0 == name).expect("named").2;
            std::fs::write(&file, text).map_err(|e| e.to_string())?;
            timed_external(bin, &file, size, 1, 7)?; // warm-up
            let r = timed_external(bin, &file, size, a.ref_spp, 99)?;
            let b = timed_external(bin, &file, size, spp, 7)?;
            let theirs = Efficiency {
                mpaths: paths / b.secs / 1e6,
                secs: b.secs,
                relmse: relmse(&b.color, &r.color),
            };
            let _ = write!(
                row,
                " {:.2} | {:.2e} | {:.2}x | {:.2}x |",
                theirs.mpaths,
                theirs.product(),
                ours.mpaths / theirs.mpaths,
                theirs.product() / ours.product()
            );
        }
        let _ = writeln!(md, "{row}");
        eprintln!("bench: {name} done");
    }
    let _ = std::fs::remove_dir_all(&dir);
    let _ = writeln!(
        md,
        "\nA scene's RelMSE at {spp} spp includes the reference's own noise (about {:.0} % \
         of it at {} spp); both builds carry the same share. Images differ between builds \
         where a fix changes them on purpose (camera handedness, one-sided emitters, the \
         RGB uplift), which is why each build is measured against its own reference.\n",
        100.0 * spp as f64 / a.ref_spp as f64,
        a.ref_spp
    );
    Ok(())
}

/// The report's table: each named scene with its own kernel, the fair general kernel and
/// the one-wavelength kernel.
fn specialisation(md: &mut String, a: &Args, cancel: &AtomicBool) -> Result<(), String> {
    let (size, spp, ref_spp) = (a.size, a.spp, a.ref_spp);
    let _ = writeln!(md, "## What specialisation saves\n");
    let _ = writeln!(
        md,
        "Each named scene rendered at {size}x{size}, {spp} spp, with the kernel the scene \
         calls for, with the **general kernel** (what a general spectral renderer runs on \
         every scene: four hero wavelengths, split only at dispersive refraction; \
         emitter-spectrum wavelength sampling; every material branch) and, as an extra \
         baseline, the **one-wavelength kernel** (one wavelength per path from the start). \
         Error is RelMSE against a {ref_spp} spp reference from the specialised kernel with \
         another seed. All kernels are unbiased, so error falls as 1/time for each; *time to \
         equal error* is the ratio of time x RelMSE (other kernel / specialised): how many \
         times longer the other kernel must run to match the specialised one's noise.\n"
    );
    let _ = writeln!(
        md,
        "| scene | kernel chosen | time spec. (s) | time general (s) | RelMSE spec. | RelMSE general | time to equal error vs general | one-wavelength: time to equal error |"
    );
    let _ = writeln!(md, "|---|---|---:|---:|---:|---:|---:|---:|");
    for (name, _, _) in named::NAMED {
        let sc = named::scene(name).expect("a named scene");
        let base = square(size, spp, 11);
        let reference = timed(
            &sc,
            &Settings {
                spp: ref_spp,
                seed: 99,
                ..base
            },
            cancel,
        )?;
        let run = |kernel: Option<Kernel>| -> Result<(f64, f64), String> {
            let t = timed(&sc, &Settings { kernel, ..base }, cancel)?;
            Ok((t.secs, relmse(&t.color, &reference.color)))
        };
        let (ts, es) = run(None)?;
        let (tg, eg) = run(Some(Kernel::GENERAL))?;
        let (t1, e1) = run(Some(Kernel::ONE_WAVELENGTH))?;
        let kernel = describe(temc_render::kernel_for(&sc, &base));
        let _ = writeln!(
            md,
            "| {name} | {kernel} | {ts:.2} | {tg:.2} | {es:.2e} | {eg:.2e} | {:.2}x | {:.2}x |",
            (tg * eg) / (ts * es),
            (t1 * e1) / (ts * es)
        );
        eprintln!("bench: {name} done");
    }
    let _ = writeln!(
        md,
        "\nThe specialised and the general kernel trace the same paths from the same seeds \
         (both sample wavelengths from the emitters' spectra), so their RelMSE agree and the \
         ratio is their time ratio: what leaving code out of the loop saves, here within the \
         timing noise of single runs on a shared machine (about 10 %). The furnace has no \
         path noise at all (every path returns exactly 1 per wavelength), so its \
         one-wavelength ratio isolates wavelength-sampling noise. Read the ratios as \
         factors, not to two digits."
    );
    Ok(())
}

/// A kernel in the report's words.
fn describe(k: Kernel) -> String {
    format!(
        "{}{}, emitter λ sampling",
        if k.dispersion {
            "split at dispersion"
        } else {
            "4 wavelengths"
        },
        if k.transmission { ", refraction" } else { "" }
    )
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
