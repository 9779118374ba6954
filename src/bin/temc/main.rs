//! The `temc` command line: `temc denoise` on PFM and EXR files, `temc info` on models.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use clap::{Args, Parser, Subcommand, ValueEnum};
use temc::engine::Model;
use temc::filter::{Device, ExecuteStats, Filter, ImageName, Quality};
use temc::io::{self, Buffers};

mod block_cache;

#[global_allocator]
static ALLOCATOR: block_cache::BlockCache = block_cache::BlockCache::new();

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

/// `--quality`: a name [`Quality::from_name`] knows.
fn parse_quality(s: &str) -> Result<Quality, String> {
    Quality::from_name(s)
        .filter(|q| *q != Quality::Default)
        .ok_or_else(|| format!("{s:?}: expected fast, balanced or high"))
}

/// `temc denoise`'s arguments.
#[derive(Args)]
struct DenoiseArgs {
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
    #[arg(long, default_value = "balanced", value_parser = parse_quality)]
    quality: Quality,
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
    /// Network runs per tile, one per orientation of the tile, averaged: 1, 2 or 4, each
    /// about one run's time; more is a little cleaner (default: the model's own, 2 for
    /// the built-in high, 1 otherwise).
    #[arg(long, default_value_t = 0)]
    passes: usize,
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
    /// Default: temc-render's layer, 380,780.
    #[arg(long, value_parser = parse_range)]
    spectral_range: Option<(f32, f32)>,
}

#[derive(Subcommand)]
enum Command {
    /// Denoise an image (PFM or EXR; multi-layer EXR may carry the aux buffers too).
    Denoise(DenoiseArgs),
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
    exit_quietly_on_closed_pipe();
    let cli = Cli::parse();
    match &cli.command {
        Command::Denoise(args) => choose_heap_retention(args.max_memory_mb),
        Command::Bench { max_memory_mb, .. } => choose_heap_retention(*max_memory_mb),
        Command::Info { .. } => {}
    }
    let result = match cli.command {
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
        Command::Denoise(args) => denoise(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("temc: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Seconds spent in each stage of `temc denoise`, for `--json`.
struct Timings {
    read: f64,
    commit: f64,
    denoise: f64,
    write: f64,
}

/// `temc denoise`: read the inputs, configure the filter, run it, write, report.
fn denoise(args: &DenoiseArgs) -> temc::Result<()> {
    let t0 = Instant::now();
    let inputs = read_inputs(args)?;
    let read = t0.elapsed().as_secs_f64();
    let device = Device::new();
    device.set_num_threads(args.threads);
    device.commit()?;
    let t1 = Instant::now();
    // Parsed once: the filter takes its type from the model and commits it as it is.
    let model = args
        .model
        .as_ref()
        .map(|m| Model::from_path(m).map(Arc::new))
        .transpose()?;
    let (out, stats, commit) = run_filter(&device, model, &inputs, args)?;
    let denoise = t1.elapsed().as_secs_f64();
    let t2 = Instant::now();
    io::write_rgb(&args.output, inputs.width, inputs.height, &out)?;
    let times = Timings {
        read,
        commit,
        denoise,
        write: t2.elapsed().as_secs_f64(),
    };
    report(args, &inputs, &stats, &times);
    Ok(())
}

/// The noisy colour a denoise reads: RGB, or spectral bands the filter converts.
enum Colour {
    /// Linear RGB, interleaved.
    Rgb(Vec<f32>),
    /// `bands` values per pixel, splitting `range` (nm) evenly.
    Spectral {
        values: Vec<f32>,
        bands: usize,
        range: (f32, f32),
    },
}

/// The images a denoise reads: colour as f32, the aux buffers as half floats (they are
/// noise-free guides: half the memory, and the network sees half precision anyway).
struct Inputs {
    width: usize,
    height: usize,
    color: Colour,
    albedo: Option<Vec<half::f16>>,
    normal: Option<Vec<half::f16>>,
    depth: Option<Vec<half::f16>>,
}

impl Inputs {
    fn bytes(&self) -> usize {
        let half = |b: &Option<Vec<half::f16>>| b.as_ref().map_or(0, |v| v.len() * 2);
        let color = match &self.color {
            Colour::Rgb(v) | Colour::Spectral { values: v, .. } => v.len() * 4,
        };
        color + half(&self.albedo) + half(&self.normal) + half(&self.depth)
    }
}

/// This process's resident memory in bytes (Linux: /proc/self/statm), or None where the
/// system does not say.
fn resident_bytes() -> Option<usize> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: usize = statm.split_whitespace().nth(1)?.parse().ok()?;
    // SAFETY: sysconf only reads a system constant.
    let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
    usize::try_from(page).ok().map(|p| pages * p)
}

/// The aux buffers a separate file can supply.
#[derive(Clone, Copy)]
enum AuxKind {
    Albedo,
    Normal,
    Depth,
}

impl AuxKind {
    fn name(self) -> &'static str {
        match self {
            AuxKind::Albedo => "albedo",
            AuxKind::Normal => "normal",
            AuxKind::Depth => "depth",
        }
    }

    /// The buffer in `b` that holds this kind: its own layer, else (albedo, normal) the
    /// colour of a file written for that buffer alone.
    fn take(self, b: Buffers) -> Option<Vec<f32>> {
        match self {
            AuxKind::Albedo => b.albedo.or(b.color),
            AuxKind::Normal => b.normal.or(b.color),
            AuxKind::Depth => b.depth,
        }
    }

    fn slot(self, b: &mut Buffers) -> &mut Option<Vec<f32>> {
        match self {
            AuxKind::Albedo => &mut b.albedo,
            AuxKind::Normal => &mut b.normal,
            AuxKind::Depth => &mut b.depth,
        }
    }
}

/// Reads the colour file and the aux files `args` name, keeping the layers `--aux` asks for.
fn read_inputs(args: &DenoiseArgs) -> temc::Result<Inputs> {
    let mut bufs = io::read(&args.color)?;
    let range = args.spectral_range.unwrap_or((
        temc::color::layers::SPECTRAL_MIN_NM,
        temc::color::layers::SPECTRAL_MAX_NM,
    ));
    let spectral = spectral_colour(&mut bufs, &args.color, args.spectral, range)?;
    let aux = if args.color_only {
        AuxArg::None
    } else {
        args.aux
    };
    if aux != AuxArg::Full {
        (bufs.normal, bufs.depth) = (None, None);
    }
    if aux == AuxArg::None {
        bufs.albedo = None;
    }
    let Some(color) = spectral.or(bufs.color.take().map(Colour::Rgb)) else {
        return Err(temc::Error::InvalidArgument(format!(
            "{}: no colour channels found",
            args.color.display()
        )));
    };
    let files = [
        (AuxKind::Albedo, &args.albedo, aux != AuxArg::None),
        (AuxKind::Normal, &args.normal, aux == AuxArg::Full),
        (AuxKind::Depth, &args.depth, aux == AuxArg::Full),
    ];
    for (kind, path, wanted) in files {
        if let (Some(path), true) = (path, wanted) {
            *kind.slot(&mut bufs) = Some(read_aux(path, kind, (bufs.width, bufs.height))?);
        }
    }
    let to_half = |v: Option<Vec<f32>>| v.map(|v| v.into_iter().map(half::f16::from_f32).collect());
    Ok(Inputs {
        width: bufs.width,
        height: bufs.height,
        color,
        albedo: to_half(bufs.albedo),
        normal: to_half(bufs.normal),
        depth: to_half(bufs.depth),
    })
}

/// One aux buffer from its own file, which must match the colour's size.
fn read_aux(path: &Path, kind: AuxKind, size: (usize, usize)) -> temc::Result<Vec<f32>> {
    let b = io::read(path)?;
    if (b.width, b.height) != size {
        return Err(temc::Error::InvalidArgument(format!(
            "{}: {} is {}x{}, colour is {}x{}",
            path.display(),
            kind.name(),
            b.width,
            b.height,
            size.0,
            size.1
        )));
    }
    kind.take(b).ok_or_else(|| {
        temc::Error::InvalidArgument(format!(
            "{}: no {} channels found",
            path.display(),
            kind.name()
        ))
    })
}

/// Configures a filter for `inputs` (the model's own type, or the built-in TEMC-2 of
/// `--quality`), runs it, and returns the result, its statistics and the commit seconds.
fn run_filter(
    device: &Device,
    model: Option<Arc<Model>>,
    inputs: &Inputs,
    args: &DenoiseArgs,
) -> temc::Result<(Vec<f32>, ExecuteStats, f64)> {
    let t = Instant::now();
    let (w, h) = (inputs.width, inputs.height);
    let mut f = match model {
        Some(m) => Filter::with_model(device, m)?,
        None => Filter::new(device, "TEMC2")?,
    };
    match &inputs.color {
        Colour::Rgb(rgb) => f.set_input_f32(ImageName::Color, rgb, w, h)?,
        Colour::Spectral {
            values,
            bands,
            range,
        } => {
            f.set_spectral_bands(*bands)?;
            f.set_spectral_range(range.0, range.1)?;
            f.set_input_f32(ImageName::Spectral, values, w, h)?;
        }
    }
    let aux = [
        (ImageName::Albedo, &inputs.albedo),
        (ImageName::Normal, &inputs.normal),
        (ImageName::Depth, &inputs.depth),
    ];
    for (name, buf) in aux {
        if let Some(v) = buf {
            f.set_input_f16(name, v, w, h)?;
        }
    }
    f.set_quality(args.quality);
    if let Some(s) = args.input_scale {
        f.set_input_scale(s)?;
    }
    // --max-memory-mb bounds the whole run: the filter gets what this process already
    // holds (the input buffers, and the program, its libraries and heap: 7-25 MB more,
    // which the buffers alone left 4K runs under 512 MB peaking up to 0.6 MB over) leaves.
    let held = resident_bytes().unwrap_or(0).max(inputs.bytes());
    f.set_max_memory_mb(args.max_memory_mb.saturating_sub(held >> 20).max(64));
    f.set_tile_size(args.tile_size);
    f.set_passes(args.passes)?;
    let bar = progress_bar(args.json);
    if let Some(bar) = bar.clone() {
        f.set_progress_monitor(move |p| {
            bar.set_position((p * 1000.0) as u64);
            true
        });
    }
    f.commit()?;
    let commit = t.elapsed().as_secs_f64();
    let (out, stats) = f.execute_to_vec()?;
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    Ok((out, stats, commit))
}

/// One line on stderr, or with `--json` the whole record on stdout.
fn report(args: &DenoiseArgs, inputs: &Inputs, stats: &ExecuteStats, t: &Timings) {
    let (w, h) = (inputs.width, inputs.height);
    if !args.json {
        eprintln!(
            "temc: {} -> {} ({w}x{h}, {} tile(s), {:.2} s)",
            args.color.display(),
            args.output.display(),
            stats.tiles,
            t.denoise
        );
        return;
    }
    let model = args
        .model
        .clone()
        .unwrap_or_else(|| format!("built-in TEMC-2 {}", args.quality.name()));
    let report = serde_json::json!({
        "color": args.color, "output": args.output, "model": model,
        "width": w, "height": h,
        "aux": {"albedo": inputs.albedo.is_some(), "normal": inputs.normal.is_some(),
                "depth": inputs.depth.is_some()},
        "tiles": stats.tiles, "window": [stats.window.0, stats.window.1],
        "cost_ratio": stats.cost_ratio, "threads": stats.threads, "passes": stats.passes,
        "input_scale": stats.input_scale,
        "seconds": {"read": t.read, "denoise": t.denoise, "commit": t.commit,
                    "execute": t.denoise - t.commit, "write": t.write},
        "estimated_peak_mb": stats.estimated_peak_bytes / 1e6,
        "peak_rss_mb": peak_rss_mb(),
    });
    println!("{report}");
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

/// With `wanted` (or when the file has a spectral layer and no colour), the spectral layer
/// as the colour: the filter converts its bands (`range` split evenly) to linear sRGB.
fn spectral_colour(
    bufs: &mut Buffers,
    path: &Path,
    wanted: bool,
    range: (f32, f32),
) -> temc::Result<Option<Colour>> {
    if !(wanted || bufs.color.is_none()) {
        return Ok(None);
    }
    let Some(values) = bufs.spectral.take() else {
        if wanted {
            return Err(temc::Error::InvalidArgument(format!(
                "{}: --spectral: no spectral layer (spectral.b00, spectral.b01, ...)",
                path.display()
            )));
        }
        return Ok(None);
    };
    Ok(Some(Colour::Spectral {
        values,
        bands: bufs.spectral_bands,
        range,
    }))
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

/// A closed output pipe ends the program quietly, as it does other Unix tools (`temc info
/// m.onnx | head`): Rust ignores SIGPIPE, so a print to a closed pipe panicked instead.
fn exit_quietly_on_closed_pipe() {
    #[cfg(unix)]
    // SAFETY: restores the default action of one signal, before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// The default budget or above keeps up to an eighth of the budget in large freed blocks
/// for reuse (block_cache.rs: 0.92x the time of `temc bench` at 1080p, docs/speed.md); a
/// budget below it gives memory back as soon as it can instead. `TEMC_BLOCK_CACHE_MB`
/// sets the cache's size (0 turns it off), for measuring it.
fn choose_heap_retention(max_memory_mb: usize) {
    if max_memory_mb < temc::filter::DEFAULT_MAX_MEMORY_MB {
        limit_heap_retention();
        return;
    }
    let mb = std::env::var("TEMC_BLOCK_CACHE_MB")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(max_memory_mb / 8);
    ALLOCATOR.enable(mb << 20);
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

fn bench(
    path: &Path,
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
    let model = Arc::new(Model::from_path(path)?);
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
    let mut f = Filter::with_model(&device, model.clone())?;
    let kind = f.kind().name();
    f.set_input_f32(ImageName::Color, &color, w, h)?;
    if aux != AuxArg::None {
        f.set_input_f32(ImageName::Albedo, &albedo, w, h)?;
    }
    if aux == AuxArg::Full {
        f.set_input_f32(ImageName::Normal, &normal, w, h)?;
        f.set_input_f32(ImageName::Depth, &depth, w, h)?;
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
            "model": path, "architecture": kind, "width": w, "height": h,
            "threads": device.effective_threads(),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(target_os = "linux")]
    #[test]
    fn resident_bytes_counts_touched_memory() {
        // 16 MB of slack for what the block cache's tests, in other threads, free meanwhile.
        let before = resident_bytes().unwrap();
        let block = vec![1u8; 128 << 20];
        let after = resident_bytes().unwrap();
        assert!(after >= before + (112 << 20), "{before} -> {after}");
        drop(block);
    }
}
