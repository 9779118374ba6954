//! `temc-render demo`: the whole job on embedded defaults. Renders a named scene at low
//! spp and a reference at high spp (another seed, so their noise is independent),
//! denoises the low-spp render with temc's built-in model, and reports error and time.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use temc::filter::{Device, Filter, Quality};
use temc_render::film::{relmse, Layers};
use temc_render::output::write_atomic;
use temc_render::{render_progressive, Settings};

/// `temc-render demo`'s options.
#[derive(clap::Args)]
pub struct Args {
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
}

/// Runs the demo and prints what it measured.
pub fn main(a: Args) -> Result<(), String> {
    let quality = Quality::from_name(&a.quality)
        .filter(|q| *q != Quality::Default)
        .ok_or_else(|| format!("--quality {:?}: expected fast, balanced or high", a.quality))?;
    let o = Options {
        scene: a.scene,
        size: crate::parse_size(&a.size)?,
        spp: a.spp,
        ref_spp: a.ref_spp,
        quality,
        out: a.out,
    };
    let t = Instant::now();
    let r = run(&o, &|line| eprintln!("temc-render demo: {line}"))?;
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

/// What the demo renders and how it denoises.
#[derive(Clone, Debug)]
pub struct Options {
    /// Named scene.
    pub scene: String,
    /// Image width and height.
    pub size: (usize, usize),
    /// Samples per pixel of the noisy render.
    pub spp: u32,
    /// Samples per pixel of the reference.
    pub ref_spp: u32,
    /// Built-in model to run.
    pub quality: Quality,
    /// Output folder.
    pub out: PathBuf,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            scene: "cornell-spiky".into(),
            size: (192, 192),
            spp: 16,
            ref_spp: 256,
            quality: Quality::Balanced,
            out: "demo-out".into(),
        }
    }
}

/// The demo's measurements.
#[derive(Clone, Debug)]
pub struct Report {
    /// Seconds to render the noisy image.
    pub render_s: f64,
    /// Seconds to render the reference.
    pub reference_s: f64,
    /// Seconds to denoise (commit included: the model is loaded once per process).
    pub denoise_s: f64,
    /// RelMSE (eps 0.01) of the noisy render against the reference.
    pub noisy_relmse: f64,
    /// RelMSE of the denoised image against the reference.
    pub denoised_relmse: f64,
    /// Denoising threads.
    pub threads: usize,
    /// Files written.
    pub files: Vec<PathBuf>,
}

/// Runs the demo; `progress` gets a line per stage.
pub fn run(o: &Options, progress: &dyn Fn(&str)) -> Result<Report, String> {
    let sc = crate::named_scene(&o.scene)?;
    if o.spp == 0 || o.ref_spp == 0 {
        return Err("sample counts must be at least 1".into());
    }
    let (w, h) = o.size;
    let render = |spp: u32, seed: u64| -> Result<(Layers, f64), String> {
        let s = Settings {
            width: w,
            height: h,
            spp,
            seed,
            ..Settings::default()
        };
        let t = Instant::now();
        let mut layers = render_progressive(&sc, &s, &[spp], &|_| {}, &AtomicBool::new(false))
            .map_err(|_| "cancelled".to_string())?;
        Ok((
            layers.pop().expect("one checkpoint"),
            t.elapsed().as_secs_f64(),
        ))
    };
    progress(&format!("rendering {} {w}x{h} at {} spp", o.scene, o.spp));
    let (noisy, render_s) = render(o.spp, 1)?;
    progress(&format!("rendering the reference at {} spp", o.ref_spp));
    let (reference, reference_s) = render(o.ref_spp, 2)?;

    progress(&format!(
        "denoising with the built-in {:?} model",
        o.quality
    ));
    let (denoised, denoise_s, threads) =
        denoise(&noisy, o.quality).map_err(|e| format!("denoising: {e}"))?;

    std::fs::create_dir_all(&o.out).map_err(|e| format!("{}: {e}", o.out.display()))?;
    let mut files = Vec::new();
    let mut clean = noisy.clone();
    clean.color = denoised;
    for (name, layers) in [
        ("noisy.exr", &noisy),
        ("denoised.exr", &clean),
        ("reference.exr", &reference),
    ] {
        let p = o.out.join(name);
        layers.write_exr(&p)?;
        files.push(p);
    }
    let png = o.out.join("demo.png");
    write_strip(
        &png,
        w,
        h,
        &[&noisy.color, &clean.color, &reference.color],
        // The denoiser's automatic exposure, so the picture is exposed as temc sees it.
        temc::color::auto_input_scale(reference.color.iter().copied()),
    )?;
    files.push(png);
    Ok(Report {
        render_s,
        reference_s,
        denoise_s,
        noisy_relmse: relmse(&noisy.color, &reference.color),
        denoised_relmse: relmse(&clean.color, &reference.color),
        threads,
        files,
    })
}

/// Denoises colour with albedo, normal and depth through temc's Rust API.
fn denoise(l: &Layers, quality: Quality) -> temc::Result<(Vec<[f32; 3]>, f64, usize)> {
    let (w, h) = (l.width, l.height);
    let flat = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
    let (color, albedo, normal) = (flat(&l.color), flat(&l.albedo), flat(&l.normal));
    let device = Device::new();
    device.commit()?;
    let t = Instant::now();
    let mut f = Filter::new(&device, "TEMC2")?;
    f.set_quality(quality);
    f.set_input_f32("color", &color, w, h)?;
    f.set_input_f32("albedo", &albedo, w, h)?;
    f.set_input_f32("normal", &normal, w, h)?;
    f.set_input_f32("depth", &l.depth, w, h)?;
    f.commit()?;
    let (out, stats) = f.execute_to_vec()?;
    let secs = t.elapsed().as_secs_f64();
    Ok((
        out.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect(),
        secs,
        stats.threads,
    ))
}

/// Writes the images side by side as an 8-bit sRGB PNG (Reinhard tone mapping).
fn write_strip(
    path: &Path,
    w: usize,
    h: usize,
    images: &[&Vec<[f32; 3]>],
    scale: f32,
) -> Result<(), String> {
    let srgb = |v: f32| {
        let x = (v * scale).max(0.0);
        let x = if x.is_finite() { x / (1.0 + x) } else { 1.0 };
        let e = if x <= 0.003_130_8 {
            12.92 * x
        } else {
            1.055 * x.powf(1.0 / 2.4) - 0.055
        };
        (e.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
    };
    let n = images.len();
    let mut px = Vec::with_capacity(w * n * h * 3);
    for y in 0..h {
        for img in images {
            for p in &img[y * w..(y + 1) * w] {
                px.extend(p.iter().map(|&v| srgb(v)));
            }
        }
    }
    write_atomic(path, |tmp| -> Result<(), Box<dyn std::error::Error>> {
        let file = std::io::BufWriter::new(std::fs::File::create(tmp)?);
        let mut enc = png::Encoder::new(file, (w * n) as u32, h as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        enc.write_header()?.write_image_data(&px)?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny(name: &str) -> (Options, PathBuf) {
        let out = std::env::temp_dir().join(format!("temc-demo-{name}-{}", std::process::id()));
        let o = Options {
            size: (64, 64),
            spp: 8,
            ref_spp: 128,
            out: out.clone(),
            ..Options::default()
        };
        (o, out)
    }

    /// A tiny demo end to end: every file is written and the errors are finite.
    #[test]
    fn demo_runs_and_writes_its_files() {
        let (o, out) = tiny("files");
        let r = run(&o, &|_| {}).unwrap();
        assert_eq!(r.files.len(), 4);
        for f in &r.files {
            assert!(f.metadata().unwrap().len() > 0, "{}", f.display());
        }
        assert!(r.noisy_relmse.is_finite() && r.denoised_relmse.is_finite());
        std::fs::remove_dir_all(&out).ok();
    }

    /// The built-in model lowers the demo's error: the shipped model does its job on the
    /// README's first command (docs/accuracy-vs-time.md has the full measurements).
    #[test]
    fn demo_lowers_the_error() {
        let (o, out) = tiny("quality");
        let r = run(&o, &|_| {}).unwrap();
        assert!(
            r.denoised_relmse < r.noisy_relmse,
            "denoised {} vs noisy {}",
            r.denoised_relmse,
            r.noisy_relmse
        );
        std::fs::remove_dir_all(&out).ok();
    }
}
