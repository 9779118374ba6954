//! The `temc` command line: `temc denoise` on PFM and EXR files, `temc info` on models.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use clap::{Parser, Subcommand, ValueEnum};
use temc::engine::Model;
use temc::filter::{Device, Filter, Quality};
use temc::image::{Format, Layout};
use temc::io::{self, Buffers};

#[derive(Parser)]
#[command(
    name = "temc",
    version,
    about = "Neural denoiser for spectral Monte Carlo renders"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, ValueEnum, PartialEq)]
enum AuxArg {
    /// Colour only.
    None,
    /// Colour and albedo.
    Albedo,
    /// Colour, albedo, normal and depth.
    Full,
}

#[derive(Clone, Copy, ValueEnum)]
enum QualityArg {
    Fast,
    Balanced,
    High,
}

impl QualityArg {
    fn quality(self) -> Quality {
        match self {
            QualityArg::Fast => Quality::Fast,
            QualityArg::Balanced => Quality::Balanced,
            QualityArg::High => Quality::High,
        }
    }
}

#[derive(Subcommand)]
enum Command {
    /// Denoise an image (PFM or EXR; multi-layer EXR may carry the aux buffers too).
    Denoise {
        /// Noisy colour: PFM, single-layer EXR, or multi-layer EXR (temc-render or Blender).
        #[arg(long)]
        color: PathBuf,
        /// Albedo (overrides one found in the colour file).
        #[arg(long)]
        albedo: Option<PathBuf>,
        /// Shading normal (overrides one found in the colour file).
        #[arg(long)]
        normal: Option<PathBuf>,
        /// Depth, a one-channel file (overrides one found in the colour file).
        #[arg(long)]
        depth: Option<PathBuf>,
        /// Output file, .pfm or .exr; written atomically.
        #[arg(short, long)]
        output: PathBuf,
        /// A temc ONNX model file (default: the built-in TEMC-2 of --quality).
        #[arg(long)]
        model: Option<String>,
        /// Quality mode: which built-in TEMC-2 runs; ignored with --model.
        #[arg(long, value_enum, default_value = "balanced")]
        quality: QualityArg,
        /// Input scale (default: automatic exposure).
        #[arg(long)]
        input_scale: Option<f32>,
        /// Worker threads (default: all cores).
        #[arg(long, default_value_t = 0)]
        threads: usize,
        /// Memory budget in MB for the whole run (input buffers included).
        #[arg(long, default_value_t = temc::filter::DEFAULT_MAX_MEMORY_MB)]
        max_memory_mb: usize,
        /// Tile core size in pixels (default: from the memory budget).
        #[arg(long, default_value_t = 0)]
        tile_size: usize,
        /// Print timings, tiles and peak memory as JSON on stdout.
        #[arg(long)]
        json: bool,
        /// Denoise from the colour alone, ignoring aux layers in the colour file (the
        /// same as `--aux none`).
        #[arg(long, conflicts_with_all = ["albedo", "normal", "depth", "aux"])]
        color_only: bool,
        /// Which aux layers to use: none, albedo, or full (albedo, normal, depth: those
        /// present). Layers left out are not read from the colour file.
        #[arg(long, value_enum, default_value = "full")]
        aux: AuxArg,
        /// Make the colour from the colour file's spectral layer (temc-render's
        /// `spectral.b00`.. channels) through the CIE 1931 observer, instead of its RGB
        /// layer. Used without asking when a file has a spectral layer and no colour.
        #[arg(long)]
        spectral: bool,
        /// The spectral layer's wavelength range in nm, MIN,MAX, split into equal bands.
        #[arg(long, default_value = "380,780", value_parser = parse_range)]
        spectral_range: (f32, f32),
    },
    /// Time the filter on a synthetic image: one warm-up run (which builds the plan), then
    /// `--repeat` timed runs, like OIDN's oidnBenchmark.
    Bench {
        /// A temc ONNX model file.
        #[arg(long)]
        model: PathBuf,
        /// Image size, WxH.
        #[arg(long, default_value = "1920x1080")]
        size: String,
        /// Worker threads (default: all cores).
        #[arg(long, default_value_t = 0)]
        threads: usize,
        /// Timed runs after the warm-up.
        #[arg(long, default_value_t = 3)]
        repeat: usize,
        /// Which aux buffers to pass.
        #[arg(long, value_enum, default_value = "full")]
        aux: AuxArg,
        /// Memory budget in MB for the filter.
        #[arg(long, default_value_t = temc::filter::DEFAULT_MAX_MEMORY_MB)]
        max_memory_mb: usize,
        /// Print the result as JSON on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Print the metadata (model card) of a temc ONNX model.
    Info {
        /// Path to the .onnx file.
        model: PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Command::Denoise { max_memory_mb, .. } = &cli.command {
        if *max_memory_mb < temc::filter::DEFAULT_MAX_MEMORY_MB {
            limit_heap_retention();
        }
    }
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("temc: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> temc::Result<()> {
    match cli.command {
        Command::Info { model, json } => info(&model, json),
        Command::Bench {
            model,
            size,
            threads,
            repeat,
            aux,
            max_memory_mb,
            json,
        } => bench(&model, &size, threads, repeat, aux, max_memory_mb, json),
        Command::Denoise {
            color,
            albedo,
            normal,
            depth,
            output,
            model,
            quality,
            input_scale,
            threads,
            max_memory_mb,
            tile_size,
            json,
            color_only,
            aux: aux_arg,
            spectral,
            spectral_range,
        } => {
            let t0 = Instant::now();
            let mut bufs = io::read(&color)?;
            colour_from_spectral(&mut bufs, &color, spectral, spectral_range)?;
            let aux_arg = if color_only { AuxArg::None } else { aux_arg };
            if aux_arg != AuxArg::Full {
                (bufs.normal, bufs.depth) = (None, None);
            }
            if aux_arg == AuxArg::None {
                bufs.albedo = None;
            }
            if bufs.color.is_none() {
                return Err(temc::Error::InvalidArgument(format!(
                    "{}: no colour channels found",
                    color.display()
                )));
            }
            let mut aux = |path: &Option<PathBuf>,
                           pick: fn(Buffers) -> Option<Vec<f32>>,
                           what: &str|
             -> temc::Result<()> {
                let Some(p) = path else { return Ok(()) };
                let b = io::read(p)?;
                if (b.width, b.height) != (bufs.width, bufs.height) {
                    return Err(temc::Error::InvalidArgument(format!(
                        "{}: {what} is {}x{}, colour is {}x{}",
                        p.display(),
                        b.width,
                        b.height,
                        bufs.width,
                        bufs.height
                    )));
                }
                let v = pick(b).ok_or_else(|| {
                    temc::Error::InvalidArgument(format!(
                        "{}: no {what} channels found",
                        p.display()
                    ))
                })?;
                match what {
                    "albedo" => bufs.albedo = Some(v),
                    "normal" => bufs.normal = Some(v),
                    _ => bufs.depth = Some(v),
                }
                Ok(())
            };
            if aux_arg != AuxArg::None {
                aux(&albedo, |b| b.albedo.or(b.color), "albedo")?;
            }
            if aux_arg == AuxArg::Full {
                aux(&normal, |b| b.normal.or(b.color), "normal")?;
                aux(&depth, |b| b.depth, "depth")?;
            }
            let read_s = t0.elapsed().as_secs_f64();

            // No --model: the built-in TEMC-2 that --quality picks.
            let (weights, kind) = match &model {
                Some(m) => {
                    let (w, k) = read_model(Path::new(m))?;
                    (Some(w), k)
                }
                None => (None, "TEMC2".to_string()),
            };

            let device = Device::new();
            device.set_num_threads(threads);
            device.commit()?;
            let (w, h) = (bufs.width, bufs.height);
            // Aux buffers are noise-free guides: half floats keep them at half the memory.
            let to_half = |v: Option<Vec<f32>>| {
                v.map(|v| v.into_iter().map(half::f16::from_f32).collect::<Vec<_>>())
            };
            let color_buf = bufs.color.take().unwrap_or_default();
            let (albedo_h, normal_h, depth_h) = (
                to_half(bufs.albedo.take()),
                to_half(bufs.normal.take()),
                to_half(bufs.depth.take()),
            );
            let held = color_buf.len() * 4
                + [&albedo_h, &normal_h, &depth_h]
                    .iter()
                    .map(|b| b.as_ref().map_or(0, |v| v.len() * 2))
                    .sum::<usize>();
            // --max-memory-mb bounds the whole run: the filter gets what the buffers held
            // here leave of it.
            let filter_mb = max_memory_mb.saturating_sub(held >> 20).max(64);
            let t1 = Instant::now();
            let commit_s;
            let (out, stats) = {
                let mut f = Filter::new(&device, &kind)?;
                if let Some(w) = &weights {
                    f.set_weights(w);
                }
                f.set_input_f32("color", &color_buf, w, h)?;
                for (name, buf, format) in [
                    ("albedo", &albedo_h, Format::Half3),
                    ("normal", &normal_h, Format::Half3),
                    ("depth", &depth_h, Format::Half),
                ] {
                    if let Some(v) = buf {
                        // SAFETY: f16 is two plain bytes; the view lives as long as `v`.
                        let bytes = unsafe {
                            std::slice::from_raw_parts(v.as_ptr() as *const u8, v.len() * 2)
                        };
                        f.set_input(name, bytes, Layout::packed(format, w, h))?;
                    }
                }
                f.set_quality(quality.quality());
                if let Some(s) = input_scale {
                    f.set_input_scale(s)?;
                }
                f.set_max_memory_mb(filter_mb);
                f.set_tile_size(tile_size);
                let bar = progress_bar(json);
                if let Some(bar) = bar.clone() {
                    f.set_progress_monitor(move |p| {
                        bar.set_position((p * 1000.0) as u64);
                        true
                    });
                }
                f.commit()?;
                commit_s = t1.elapsed().as_secs_f64();
                let result = f.execute_to_vec()?;
                if let Some(bar) = bar {
                    bar.finish_and_clear();
                }
                result
            };
            let denoise_s = t1.elapsed().as_secs_f64();
            let t2 = Instant::now();
            io::write_rgb(&output, w, h, &out)?;
            let write_s = t2.elapsed().as_secs_f64();
            if json {
                let report = serde_json::json!({
                    "color": color, "output": output,
                    "model": model.clone().unwrap_or_else(|| format!("built-in TEMC-2 {}",
                        quality.to_possible_value().map_or_else(String::new, |v| v.get_name().to_string()))),
                    "width": w, "height": h,
                    "aux": {"albedo": albedo_h.is_some(), "normal": normal_h.is_some(), "depth": depth_h.is_some()},
                    "tiles": stats.tiles, "window": [stats.window.0, stats.window.1],
                    "cost_ratio": stats.cost_ratio, "threads": stats.threads,
                    "input_scale": stats.input_scale,
                    "seconds": {"read": read_s, "denoise": denoise_s, "commit": commit_s,
                                "execute": denoise_s - commit_s, "write": write_s},
                    "estimated_peak_mb": stats.estimated_peak_bytes / 1e6,
                    "peak_rss_mb": peak_rss_mb(),
                });
                println!("{report}");
            } else {
                eprintln!(
                    "temc: {} -> {} ({w}x{h}, {} tile(s), {denoise_s:.2} s)",
                    color.display(),
                    output.display(),
                    stats.tiles
                );
            }
            Ok(())
        }
    }
}

/// `MIN,MAX` in nm.
fn parse_range(s: &str) -> Result<(f32, f32), String> {
    let bad = || format!("{s:?}: expected MIN,MAX in nm, e.g. 380,780");
    let (a, b) = s.split_once(',').ok_or_else(bad)?;
    let (a, b) = (
        a.trim().parse().map_err(|_| bad())?,
        b.trim().parse().map_err(|_| bad())?,
    );
    Ok((a, b))
}

/// With `wanted` (or when the file has a spectral layer and no colour), replaces the colour
/// by the spectral layer's linear sRGB over `range` split into equal bands.
fn colour_from_spectral(
    bufs: &mut Buffers,
    path: &Path,
    wanted: bool,
    range: (f32, f32),
) -> temc::Result<()> {
    if !(wanted || bufs.color.is_none()) {
        return Ok(());
    }
    let Some(values) = bufs.spectral.take() else {
        if wanted {
            return Err(temc::Error::InvalidArgument(format!(
                "{}: --spectral: no spectral layer (spectral.b00, spectral.b01, ...)",
                path.display()
            )));
        }
        return Ok(());
    };
    let bands = temc::color::SpectralBands::uniform(bufs.spectral_bands, range.0, range.1)?;
    bufs.color = Some(bands.image_to_linear_srgb(&values));
    Ok(())
}

fn progress_bar(json: bool) -> Option<indicatif::ProgressBar> {
    use std::io::IsTerminal;
    if json || !std::io::stderr().is_terminal() {
        return None;
    }
    let bar = indicatif::ProgressBar::new(1000);
    bar.set_style(
        indicatif::ProgressStyle::with_template("denoising {bar:40} {percent}% ({elapsed})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    Some(bar)
}

/// Used when a budget below the default is asked for. glibc raises its mmap threshold
/// each time a large block is freed, after which tract's per-op tensors come from the heap
/// and stay resident: one 832x832 TEMC-2 tile peaked at 423 MB with glibc's default and
/// at 175 MB with a fixed 1 MB threshold, which costs about 1.6x in time (page faults on
/// fresh mappings). The library leaves this process-wide choice to its host.
fn limit_heap_retention() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only tunes the allocator; called before any thread starts.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 1 << 20);
    }
}

/// Peak resident memory of this process (VmHWM), where the OS reports it.
fn peak_rss_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn info(model: &Path, json: bool) -> temc::Result<()> {
    let m = Model::from_path(model)?;
    let info = m.info();
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&info.raw).expect("string map")
        );
    } else {
        println!("{}", model.display());
        for (k, v) in &info.raw {
            println!("  {k:<24} {v}");
        }
        if info.is_untrained() {
            println!("  (untrained weights: for tests and benchmarks only)");
        }
    }
    Ok(())
}

/// A model file's bytes and the filter type its architecture needs.
fn read_model(path: &Path) -> temc::Result<(Vec<u8>, String)> {
    let weights = std::fs::read(path).map_err(|source| temc::Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let kind = Model::from_bytes(&weights)?
        .info()
        .architecture
        .to_ascii_uppercase();
    Ok((weights, kind))
}

fn bench(
    model: &Path,
    size: &str,
    threads: usize,
    repeat: usize,
    aux: AuxArg,
    max_memory_mb: usize,
    json: bool,
) -> temc::Result<()> {
    let (w, h) = size
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse::<usize>().ok()?, h.parse::<usize>().ok()?)))
        .filter(|&(w, h)| w > 0 && h > 0)
        .ok_or_else(|| temc::Error::InvalidArgument(format!("--size {size:?}: expected WxH")))?;
    let (weights, kind) = read_model(model)?;
    // A deterministic noisy gradient; the timing does not depend on the content.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let color: Vec<f32> = (0..w * h * 3)
        .map(|i| (i % (w * 3)) as f32 / (w * 3) as f32 * 2.0 * noise())
        .collect();
    let albedo = vec![0.5f32; w * h * 3];
    let normal: Vec<f32> = (0..w * h).flat_map(|_| [0.0f32, 0.0, 1.0]).collect();
    let depth = vec![1.0f32; w * h];
    let device = Device::new();
    device.set_num_threads(threads);
    device.commit()?;
    let mut f = Filter::new(&device, &kind)?;
    f.set_weights(&weights);
    f.set_input_f32("color", &color, w, h)?;
    if aux != AuxArg::None {
        f.set_input_f32("albedo", &albedo, w, h)?;
    }
    if aux == AuxArg::Full {
        f.set_input_f32("normal", &normal, w, h)?;
        let bytes = unsafe {
            // SAFETY: f32 is four plain bytes; the view lives as long as `depth`.
            std::slice::from_raw_parts(depth.as_ptr() as *const u8, depth.len() * 4)
        };
        f.set_input("depth", bytes, Layout::packed(Format::Float, w, h))?;
    }
    f.set_max_memory_mb(max_memory_mb);
    let t = Instant::now();
    f.commit()?;
    f.execute_to_vec()?;
    let warmup_s = t.elapsed().as_secs_f64();
    let mut times = Vec::with_capacity(repeat);
    for _ in 0..repeat.max(1) {
        let t = Instant::now();
        f.execute_to_vec()?;
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    let (min, median) = (times[0], times[times.len() / 2]);
    if json {
        let report = serde_json::json!({
            "model": model, "architecture": kind, "width": w, "height": h,
            "threads": if threads == 0 {
                std::thread::available_parallelism().map_or(1, |n| n.get())
            } else {
                threads
            },
            "aux": match aux { AuxArg::None => "none", AuxArg::Albedo => "albedo", AuxArg::Full => "full" },
            "warmup_seconds": warmup_s, "seconds": times, "min_seconds": min,
            "median_seconds": median,
            "megapixels_per_second": (w * h) as f64 / median / 1e6,
        });
        println!("{report}");
    } else {
        println!(
            "{kind} {w}x{h}: median {median:.3} s, min {min:.3} s over {} runs ({:.2} MP/s; warm-up with plan build {warmup_s:.2} s)",
            times.len(),
            (w * h) as f64 / median / 1e6
        );
    }
    Ok(())
}
