//! `temc-render bench`: the throughput on the Cornell box, and what kernel specialisation
//! saves on every named scene, as a Markdown report (docs/render-bench.md).

use std::fmt::Write;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use temc_render::description::named;
use temc_render::film::{relmse, Layers};
use temc_render::integrator::Kernel;
use temc_render::output::write_bytes_atomic;
use temc_render::scene::Scene;
use temc_render::{render_progressive, Settings};

/// `temc-render bench`'s options.
#[derive(clap::Args)]
pub struct Args {
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
}

/// Runs the benchmark and writes the report.
pub fn main(a: Args, cancel: &AtomicBool) -> Result<(), String> {
    let threads = rayon::current_num_threads();
    let mut md = String::new();
    let _ = writeln!(md, "# temc-render benchmark\n");
    let _ = writeln!(
        md,
        "Regenerate: `cargo run --release -p temc-render -- bench --out docs/render-bench.md` \
         ({threads} threads; CPU: {}).\n",
        cpu_name()
    );
    throughput(&mut md, threads, cancel)?;
    specialisation(&mut md, &a, cancel)?;
    write_bytes_atomic(&a.out, md.as_bytes())?;
    eprintln!("temc-render: wrote {}", a.out.display());
    Ok(())
}

/// Renders `sc` at `s.spp`; returns the image and the seconds it took.
fn timed(sc: &Scene, s: &Settings, cancel: &AtomicBool) -> Result<(Layers, f64), String> {
    let t = Instant::now();
    let img = render_progressive(sc, s, &[s.spp], &|_| {}, cancel)
        .map_err(|_| "cancelled".to_string())?
        .pop()
        .unwrap();
    Ok((img, t.elapsed().as_secs_f64()))
}

/// The report's throughput section: camera paths per second on the Cornell box.
fn throughput(md: &mut String, threads: usize, cancel: &AtomicBool) -> Result<(), String> {
    let cornell = named::scene("cornell-spiky").unwrap();
    let s = Settings {
        width: 256,
        height: 256,
        spp: 16,
        seed: 7,
        max_depth: 12,
        specialise: true,
    };
    timed(&cornell, &Settings { spp: 1, ..s }, cancel)?; // warm-up
    let (_, secs) = timed(&cornell, &s, cancel)?;
    let paths = (256 * 256 * 16) as f64;
    let _ = writeln!(md, "## Throughput\n");
    let _ = writeln!(
        md,
        "`cornell-spiky`, 256x256 at 16 spp, {threads} threads: **{:.2} M camera paths/s** \
         ({:.2} s for {paths:.0} paths, up to 12 bounces with next-event estimation).\n",
        paths / secs / 1e6,
        secs
    );
    Ok(())
}

/// The report's table: each named scene with its own kernel and with the general one.
fn specialisation(md: &mut String, a: &Args, cancel: &AtomicBool) -> Result<(), String> {
    let (size, spp, ref_spp) = (a.size, a.spp, a.ref_spp);
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
    for (name, _, _) in named::NAMED {
        let sc = named::scene(name).unwrap();
        let base = Settings {
            width: size,
            height: size,
            spp,
            seed: 11,
            max_depth: 12,
            specialise: true,
        };
        let reference = Settings {
            spp: ref_spp,
            seed: 99,
            ..base
        };
        let (reference, _) = timed(&sc, &reference, cancel)?;
        let (a, ta) = timed(&sc, &base, cancel)?;
        let general = Settings {
            specialise: false,
            ..base
        };
        let (b, tb) = timed(&sc, &general, cancel)?;
        let (ea, eb) = (
            relmse(&a.color, &reference.color),
            relmse(&b.color, &reference.color),
        );
        let kernel = describe(temc_render::kernel_for(&sc, &base));
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
    Ok(())
}

/// A kernel in the report's words.
fn describe(k: Kernel) -> String {
    format!(
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
