//! One execution, in named stages: the colour [`input`](super::input) stage (linear, sRGB or
//! spectral colour to linear RGB), [`validate`] the images, [`snapshot`] inputs that share
//! bytes with the output, compute the [`image_statistics`] once, [`plan`] the tiles, then per
//! tile (in parallel) [`pack_tile`], run the network, [`reconstruct`](crate::reconstruct)
//! the tile's core from the predicted filters and the noisy linear radiance; then
//! [`keep_mean`](crate::keep_mean) on the whole image; finally [`write_output`], only when
//! every tile has succeeded, after the [`input::encode_output`] stage. The other execution
//! path, [`prefilter`], denoises a lone aux image.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use ndarray::Array3;
use rayon::prelude::*;

use super::input::{self, ColorInput};
use super::passes;
use super::{ExecuteStats, ImageName, Monitor, RawImage};
use crate::color::{self, features, Exposure, SpectralBands};
use crate::engine::{Model, ModelInfo, NetInput};
use crate::image::{read3, write3, Layout};
use crate::prefilter::{filter_aux, AuxKind};
use crate::tile::{Tile, TilePlan};
use crate::Error;
use crate::{keep_mean, reconstruct};

pub(super) struct Job<'m> {
    pub model: &'m Arc<Model>,
    pub images: [Option<RawImage>; 6],
    /// How the colour becomes linear RGB.
    pub color_input: ColorInput,
    /// The bands of a spectral colour input.
    pub bands: Option<&'m SpectralBands>,
    /// The staging buffer a converted colour input is written to (allocated at commit).
    pub staged: &'m mut [f32],
    pub hdr: bool,
    pub input_scale: Option<f32>,
    pub max_memory_bytes: usize,
    pub tile_size: usize,
    /// Runs per tile, one per orientation ([`passes`]), averaged: 1, 2 or 4.
    pub passes: usize,
    pub verbose: i32,
}
/// Floats per window pixel that a tile allocates besides tract: chroma 2, luma 1, aux 7,
/// noisy radiance 3, albedo 3, the reconstruction's output 3 and its scratch
/// ([`reconstruct::SCRATCH_PLANES`]).
const TILE_PLANES: f64 = 19.0 + reconstruct::SCRATCH_PLANES;

/// What a tile of several passes allocates besides: the output sum (3 planes; the planes
/// flip in place).
const PASS_PLANES: f64 = 3.0;

/// What tract holds per pixel, as a share of the live tensors the engine's estimate counts
/// (the count takes every node's output as a buffer of its own). One thread with glibc's
/// mmap threshold fixed, the slope of peak RSS over window area is 0.56-0.59 of the count
/// for the three built-in TEMC-2 models (the calibration table of `scripts/memory-4k`), but
/// two threads at 4K under `--max-memory-mb 512` peaked at 527 MiB with 0.8, 505 with 1.0
/// and 486 with 1.2 (2026-12-07). The 1.5 used before was measured on a one-level model and
/// cut 1080p into four tiles where two fit.
const TRACT_SHARE: f64 = 1.2;

/// Reads pixels of one input image.
struct Source {
    img: RawImage,
    /// Keeps a private copy alive when the caller's buffer is also the output.
    _copy: Option<Vec<u8>>,
}

impl Source {
    #[inline]
    fn px(&self, x: usize, y: usize) -> [f32; 3] {
        // SAFETY: the layout was validated against the buffer when the image was set, and
        // (x, y) is inside the image (callers clamp to it).
        unsafe { read3(self.img.ptr, &self.img.layout, x, y) }
    }

    /// Every pixel, row by row.
    fn pixels(&self) -> impl Iterator<Item = [f32; 3]> + '_ {
        self.rows(0..self.img.layout.height)
    }

    /// The pixels of band `b`'s rows ([`STAT_ROWS`] of them, fewer at the bottom).
    fn band(&self, b: usize) -> impl Iterator<Item = [f32; 3]> + '_ {
        self.rows(b * STAT_ROWS..((b + 1) * STAT_ROWS).min(self.img.layout.height))
    }

    /// The pixels of `rows`, row by row.
    fn rows(&self, rows: std::ops::Range<usize>) -> impl Iterator<Item = [f32; 3]> + '_ {
        let w = self.img.layout.width;
        rows.flat_map(move |y| (0..w).map(move |x| self.px(x, y)))
    }
}

/// Rows per band of the image statistics: bands are summed in parallel and merged in
/// order, so the input scale does not depend on the thread count.
const STAT_ROWS: usize = 64;

/// The inputs one execution reads: colour and the aux buffers the caller gave.
struct Sources {
    color: Source,
    albedo: Option<Source>,
    normal: Option<Source>,
    depth: Option<Source>,
    /// Bytes copied because they overlapped the output.
    snapshot_bytes: usize,
}

/// What is computed once per image, before tiling, so every tile sees the same numbers.
#[derive(Clone, Copy)]
struct Statistics {
    exposure: Exposure,
    depth_scale: Option<f32>,
}

fn overlaps(a: &RawImage, b: &RawImage) -> bool {
    let (a0, b0) = (a.ptr as usize, b.ptr as usize);
    a0 < b0.saturating_add(b.span) && b0 < a0.saturating_add(a.span)
}

/// Mirror padding for canvas pixels past the image edge (period 2n - 2, edge not repeated).
#[inline]
fn reflect(i: usize, n: usize) -> usize {
    if n == 1 {
        return 0;
    }
    let period = 2 * (n - 1);
    let m = i % period;
    if m < n {
        m
    } else {
        period - m
    }
}

struct SyncPtr(*mut f32);
// SAFETY: tiles write disjoint cores of the staging buffer.
unsafe impl Sync for SyncPtr {}

impl SyncPtr {
    /// A method, not a field access: closures then capture the Sync wrapper, not the pointer.
    fn get(&self) -> *mut f32 {
        self.0
    }
}

const NAMES: [ImageName; 5] = [
    ImageName::Color,
    ImageName::Albedo,
    ImageName::Normal,
    ImageName::Depth,
    ImageName::Output,
];

/// Stage 1: colour is set, every image has colour's size and enough channels. Returns
/// (width, height).
fn validate(images: &[Option<RawImage>; 6]) -> Result<(usize, usize), Error> {
    let color = images[ImageName::Color as usize]
        .ok_or_else(|| Error::InvalidOperation("image \"color\" is not set".into()))?;
    let (w, h) = (color.layout.width, color.layout.height);
    for (img, name) in images.iter().zip(NAMES) {
        let Some(img) = img else { continue };
        let l = &img.layout;
        if (l.width, l.height) != (w, h) {
            return Err(Error::InvalidArgument(format!(
                "image {:?} is {}x{}, but \"color\" is {w}x{h}",
                name.as_str(),
                l.width,
                l.height
            )));
        }
        let need = if name == ImageName::Depth { 1 } else { 3 };
        if l.format.channels() < need {
            return Err(Error::InvalidArgument(format!(
                "image {:?} needs {need} channel(s), its format {:?} has {}",
                name.as_str(),
                l.format,
                l.format.channels()
            )));
        }
    }
    Ok((w, h))
}

/// Stage 2: inputs that share bytes with the output are copied first, because tiles write
/// while others still read.
fn snapshot(images: &[Option<RawImage>; 6]) -> Result<Sources, Error> {
    let output = images[ImageName::Output as usize];
    let mut snapshot_bytes = 0usize;
    let mut source = |i: ImageName| -> Result<Option<Source>, Error> {
        let Some(img) = images[i as usize] else {
            return Ok(None);
        };
        if !output.as_ref().is_some_and(|o| overlaps(&img, o)) {
            return Ok(Some(Source { img, _copy: None }));
        }
        let mut copy = Vec::new();
        copy.try_reserve_exact(img.span)
            .map_err(|_| Error::OutOfMemory(format!("copying in-place image {:?}", i.as_str())))?;
        // SAFETY: the caller guaranteed `span` readable bytes at `ptr`.
        copy.extend_from_slice(unsafe { std::slice::from_raw_parts(img.ptr, img.span) });
        snapshot_bytes += img.span;
        let img = RawImage {
            ptr: copy.as_mut_ptr(),
            ..img
        };
        Ok(Some(Source {
            img,
            _copy: Some(copy),
        }))
    };
    let color = source(ImageName::Color)?.expect("validated: color is set");
    let albedo = source(ImageName::Albedo)?;
    let normal = source(ImageName::Normal)?;
    let depth = source(ImageName::Depth)?;
    Ok(Sources {
        color,
        albedo,
        normal,
        depth,
        snapshot_bytes,
    })
}

/// Stage 3: exposure (the caller's input scale, or automatic for HDR) and the depth scale,
/// band by band on the pool (about 0.1 s of one thread at 1080p otherwise).
fn image_statistics(
    job: &Job<'_>,
    src: &Sources,
    info: &ModelInfo,
    pool: &rayon::ThreadPool,
) -> Result<Statistics, Error> {
    let auto = job.hdr && job.input_scale.is_none();
    let bands = src.color.img.layout.height.div_ceil(STAT_ROWS);
    let parts: Vec<_> = pool.install(|| {
        (0..bands)
            .into_par_iter()
            .map(|b| {
                let log = auto.then(|| color::LogLuminance::of(src.color.band(b)));
                let depth = src
                    .depth
                    .as_ref()
                    .and_then(|d| features::depth_scale(d.band(b).map(|p| p[0])));
                (log.unwrap_or_default(), depth)
            })
            .collect()
    });
    let log = parts
        .iter()
        .fold(color::LogLuminance::default(), |log, p| log.merge(p.0));
    // The bands' scales are depths too: the image's is the largest of them.
    let depth_scale = features::depth_scale(parts.iter().filter_map(|p| p.1));
    let input_scale = match (job.hdr, job.input_scale) {
        (_, Some(s)) => s,
        (false, None) => 1.0,
        (true, None) => log.input_scale(),
    };
    Ok(Statistics {
        exposure: Exposure::new(input_scale, info.pq_nits_per_unit)?,
        depth_scale,
    })
}

/// Stage 4: the tile plan from the memory budget (or the caller's tile size, when not 0),
/// and the estimated peak in bytes. `snapshot_bytes` is the private copy of inputs the run
/// holds besides its staging; `passes` the network runs per tile.
pub(super) fn tile_plan(
    model: &Model,
    (w, h): (usize, usize),
    snapshot_bytes: usize,
    threads: usize,
    max_memory_bytes: usize,
    tile_size: usize,
    passes: usize,
) -> Result<(TilePlan, f64), Error> {
    let info = model.info();
    let (weights, per_px) = model.memory_estimate()?;
    let planes = TILE_PLANES + if passes > 1 { PASS_PLANES } else { 0.0 };
    let per_px = per_px * TRACT_SHARE + planes * 4.0;
    let staging = (w * h * 12 + snapshot_bytes) as f64;
    let per_thread = (max_memory_bytes as f64 - staging - weights) / threads as f64;
    let overlap = info.tile_overlap.div_ceil(info.alignment) * info.alignment;
    let plan = if tile_size > 0 {
        let side = tile_size.div_ceil(info.alignment) * info.alignment + 2 * overlap;
        TilePlan::new(w, h, info.alignment, info.tile_overlap, side)?
    } else {
        let max_area = per_thread.max(0.0) / per_px;
        TilePlan::for_budget(w, h, info.alignment, info.tile_overlap, max_area, threads)?
    };
    let concurrent = threads.min(plan.tiles.len());
    let (tw, th) = plan.window;
    let peak = staging + weights + concurrent as f64 * per_px * (tw * th) as f64;
    Ok((plan, peak))
}

/// One tile's planes: the network's inputs and what the reconstruction filters.
/// Each is (plane, y, x) over the tile's window, in the standard layout the network and the
/// reconstruction read as flat slices.
struct Packed {
    /// Hue and saturation.
    chroma: Array3<f32>,
    /// Value.
    luma: Array3<f32>,
    /// The aux planes in the model's `temc.aux_layout` order.
    aux: Array3<f32>,
    /// Noisy linear radiance, sanitised (and clamped to [0, 1] in LDR mode).
    rgb: Array3<f32>,
    /// The albedo feature (0 where not given) when the model demodulates; else no planes.
    albedo: Array3<f32>,
}

impl Packed {
    fn plane(a: &Array3<f32>) -> &[f32] {
        a.as_slice().expect("packed planes are in standard layout")
    }

    /// Reverses rows and/or columns of every plane, mirroring the normal feature with them
    /// (`normal`: its first aux plane, if the layout has one).
    fn flip(&mut self, rows: bool, cols: bool, normal: Option<usize>) {
        for a in [
            &mut self.chroma,
            &mut self.luma,
            &mut self.aux,
            &mut self.rgb,
            &mut self.albedo,
        ] {
            passes::flip(a, rows, cols);
        }
        if let Some(first) = normal {
            passes::mirror_normal(&mut self.aux, first, rows, cols);
        }
    }
}

/// Stage 5: packs a tile's window (mirror-padded past the image edge) into planes, the aux
/// planes in the order of the model's `temc.aux_layout`.
fn pack_tile(
    win: crate::tile::Rect,
    (w, h): (usize, usize),
    src: &Sources,
    stats: Statistics,
    hdr: bool,
    info: &ModelInfo,
) -> Packed {
    let planes = |count: usize| Array3::zeros((count, win.h, win.w));
    let mut p = Packed {
        chroma: planes(2),
        luma: planes(1),
        aux: planes(info.aux_channels),
        rgb: planes(3),
        // Only a demodulating reconstruction reads it.
        albedo: planes(if info.demodulate { 3 } else { 0 }),
    };
    // The layout resolved once, not per pixel: (buffer, channels, first plane).
    let mut first = 0;
    let layout: Vec<(AuxBuffer, usize, usize)> = info
        .aux_planes
        .iter()
        .map(|(name, channels)| {
            let buffer = match name.as_str() {
                "albedo" => AuxBuffer::Albedo,
                "normal" => AuxBuffer::Normal,
                _ => AuxBuffer::Depth, // metadata admits only AUX_BUFFERS
            };
            first += channels;
            (buffer, *channels, first - channels)
        })
        .collect();
    let mut row = Vec::with_capacity(win.w);
    for wy in 0..win.h {
        let y = reflect(win.y + wy, h);
        row.clear();
        row.extend((0..win.w).map(|wx| radiance(src.color.px(reflect(win.x + wx, w), y), hdr)));
        let encoded = color::encode_row(&row, stats.exposure);
        for (wx, (&c, e)) in row.iter().zip(encoded).enumerate() {
            let x = reflect(win.x + wx, w);
            p.chroma[[0, wy, wx]] = e.hsv[0];
            p.chroma[[1, wy, wx]] = e.hsv[1];
            p.luma[[0, wy, wx]] = e.hsv[2];
            let a = src
                .albedo
                .as_ref()
                .map_or([0.0; 3], |s| features::albedo(s.px(x, y)));
            let nm = src
                .normal
                .as_ref()
                .map_or([0.5; 3], |s| features::normal(s.px(x, y)));
            let d = src
                .depth
                .as_ref()
                .map_or(0.0, |s| features::depth(s.px(x, y)[0], stats.depth_scale));
            for (k, &v) in c.iter().enumerate() {
                p.rgb[[k, wy, wx]] = v;
            }
            if info.demodulate {
                for (k, &v) in a.iter().enumerate() {
                    p.albedo[[k, wy, wx]] = v;
                }
            }
            for &(buffer, channels, plane) in &layout {
                let v: &[f32] = match buffer {
                    AuxBuffer::Albedo => &a,
                    AuxBuffer::Normal => &nm,
                    AuxBuffer::Depth => std::slice::from_ref(&d),
                };
                for (k, &value) in v.iter().take(channels).enumerate() {
                    p.aux[[plane + k, wy, wx]] = value;
                }
            }
        }
    }
    p
}

/// The noisy linear radiance the reconstruction filters: sanitised, and in LDR mode first
/// clamped to [0, 1] (NaN to 0).
fn radiance(c: [f32; 3], hdr: bool) -> [f32; 3] {
    let ldr = |c: [f32; 3]| c.map(|v| if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) });
    color::sanitize_rgb(if hdr { c } else { ldr(c) })
}

/// The aux buffers a model's layout can name (engine::AUX_BUFFERS).
#[derive(Clone, Copy)]
enum AuxBuffer {
    Albedo,
    Normal,
    Depth,
}

/// Stage 6 and 7: the network, then the reconstruction; returns the window's output [3, n].
/// `exposure` is the image's input scale (the fixed range term reads it).
fn denoise_tile(
    model: &Model,
    p: &Packed,
    win: crate::tile::Rect,
    hdr: bool,
    exposure: f32,
) -> Result<Vec<f32>, Error> {
    let info = model.info();
    let filters = model.run(
        NetInput {
            chroma: Packed::plane(&p.chroma),
            luma: Packed::plane(&p.luma),
            aux: Packed::plane(&p.aux),
        },
        win.h,
        win.w,
    )?;
    let params = reconstruct::Params {
        levels: info.levels,
        kernel: info.kernel,
        demodulate: info.demodulate,
        eps: info.demod_eps,
        ldr: !hdr,
        guide: info.guide,
        fixed_range: info.fixed_range,
        exposure,
        upsample: info.upsample,
        range_opening: info.range_opening,
        coarse_clamp: info.coarse_clamp,
        coarse_gain: info.coarse_gain,
        coarse_radius: info.coarse_radius,
        coarse_sparse: info.coarse_sparse,
        range_noise: info.range_noise,
    };
    let refs = filters.levels()?;
    let albedo = info.demodulate.then_some(Packed::plane(&p.albedo));
    let aux = reconstruct::RangeAux {
        planes: Packed::plane(&p.aux),
        count: info.aux_channels,
        albedo: info.aux_plane("albedo"),
    };
    let rgb = Packed::plane(&p.rgb);
    reconstruct::reconstruct(&params, rgb, albedo, Some(aux), &refs, win.h, win.w)
}

/// Stage 6 and 7 over the flip ensemble: [`denoise_tile`] once per orientation of
/// `passes`, each output turned back, their mean returned. Leaves `p` flipped.
fn denoise_passes(
    model: &Model,
    p: &mut Packed,
    win: crate::tile::Rect,
    (hdr, exposure): (bool, f32),
    count: usize,
) -> Result<Vec<f32>, Error> {
    let orientations = passes::orientations(count);
    if orientations.len() == 1 {
        return denoise_tile(model, p, win, hdr, exposure);
    }
    let normal = model.info().aux_plane("normal");
    let mut sum = vec![0.0; 3 * win.w * win.h];
    let mut at = passes::Orientation::default();
    for &o in orientations {
        p.flip(at.rows != o.rows, at.cols != o.cols, normal);
        at = o;
        let out = denoise_tile(model, p, win, hdr, exposure)?;
        passes::accumulate(&mut sum, &out, (win.h, win.w), o);
    }
    let scale = 1.0 / orientations.len() as f32;
    sum.iter_mut().for_each(|v| *v *= scale);
    Ok(sum)
}

/// Runs the job. With an "output" image the result is written there and `None` returned;
/// without one, the packed RGB result is returned instead.
pub(super) fn run(
    job: Job<'_>,
    pool: &rayon::ThreadPool,
    monitor: Option<&mut Monitor<'_>>,
) -> Result<(ExecuteStats, Option<Vec<f32>>), Error> {
    let model = job.model.as_ref();
    let info = model.info();
    let mut images = job.images;
    let source = match job.color_input {
        ColorInput::Spectral => ImageName::Spectral,
        _ => ImageName::Color,
    };
    if let Some(staged) = input::stage(
        job.color_input,
        images[source as usize].as_ref(),
        job.bands,
        job.staged,
    ) {
        images[ImageName::Color as usize] = Some(staged);
    }
    images[ImageName::Spectral as usize] = None;
    let (w, h) = validate(&images)?;
    let src = snapshot(&images)?;
    let threads = pool.current_num_threads().max(1);
    // The tile plan's first call builds two measuring plans (Model::memory_estimate): they
    // and the image statistics share the pool's threads.
    let (stats, tile_plan) = pool.install(|| {
        rayon::join(
            || image_statistics(&job, &src, info, pool),
            || {
                tile_plan(
                    job.model,
                    (w, h),
                    src.snapshot_bytes,
                    threads,
                    job.max_memory_bytes,
                    job.tile_size,
                    job.passes,
                )
            },
        )
    });
    let (stats, (plan, estimated_peak)) = (stats?, tile_plan?);
    let (tw, th) = plan.window;
    if job.verbose > 0 {
        eprintln!(
            "temc: {w}x{h}, {} tile(s) of {tw}x{th} (cost x{:.2}), {threads} thread(s), input scale {}, ~{:.0} MB",
            plan.tiles.len(),
            plan.cost_ratio(),
            stats.exposure.input_scale(),
            estimated_peak / 1e6
        );
    }

    let mut staged: Vec<f32> = Vec::new();
    staged
        .try_reserve_exact(w * h * 3)
        .map_err(|_| Error::OutOfMemory(format!("output staging for {w}x{h}")))?;
    staged.resize(w * h * 3, 0.0);
    let out_ptr = SyncPtr(staged.as_mut_ptr());

    let done = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);
    let monitor = monitor.map(Mutex::new);
    let n_tiles = plan.tiles.len();

    let run_tile = |tile: &Tile| -> Result<(), Error> {
        if stop.load(Ordering::Relaxed) {
            return Err(Error::Cancelled);
        }
        let win = tile.window;
        let mut packed = pack_tile(win, (w, h), &src, stats, job.hdr, info);
        let exposure = stats.exposure.input_scale();
        let out = denoise_passes(model, &mut packed, win, (job.hdr, exposure), job.passes)?;
        let n = win.w * win.h;
        let core = tile.core;
        for y in core.y..core.y + core.h {
            for x in core.x..core.x + core.w {
                let i = (y - win.y) * win.w + (x - win.x);
                let o = (y * w + x) * 3;
                // SAFETY: cores partition the image, so no two tiles write the same pixel,
                // and `o + 2 < w * h * 3`.
                unsafe {
                    for k in 0..3 {
                        *out_ptr.get().add(o + k) = out[k * n + i];
                    }
                }
            }
        }
        let finished = done.fetch_add(1, Ordering::SeqCst) + 1;
        if let Some(m) = &monitor {
            let mut f = m.lock().unwrap_or_else(|e| e.into_inner());
            if !(f)(finished as f64 / n_tiles as f64) {
                stop.store(true, Ordering::SeqCst);
                return Err(Error::Cancelled);
            }
        }
        Ok(())
    };
    pool.install(|| plan.tiles.par_iter().try_for_each(run_tile))?;
    if stop.load(Ordering::SeqCst) {
        return Err(Error::Cancelled);
    }
    let limit = if job.hdr { color::LINEAR_MAX } else { 1.0 };
    let input = src.color.pixels().map(|c| radiance(c, job.hdr));
    keep_mean::stage(&mut staged, input, (w, h), limit)
        .map_err(|_| Error::OutOfMemory(format!("keep-mean stage for {w}x{h}")))?;
    input::encode_output(job.color_input, &mut staged);

    let stats = ExecuteStats {
        tiles: n_tiles,
        window: plan.window,
        cost_ratio: plan.cost_ratio(),
        input_scale: stats.exposure.input_scale(),
        threads,
        estimated_peak_bytes: estimated_peak,
        passes: job.passes,
    };
    match images[ImageName::Output as usize] {
        None => Ok((stats, Some(staged))),
        Some(output) => {
            write_output(&output, &staged, (w, h));
            Ok((stats, None))
        }
    }
}

/// Stage 8: every tile succeeded; now, and only now, the caller's output is written.
fn write_output(output: &RawImage, staged: &[f32], (w, h): (usize, usize)) {
    let layout: Layout = output.layout;
    for y in 0..h {
        for x in 0..w {
            let o = (y * w + x) * 3;
            // SAFETY: the output layout was validated against its buffer when set.
            unsafe {
                write3(
                    output.ptr,
                    &layout,
                    x,
                    y,
                    [staged[o], staged[o + 1], staged[o + 2]],
                )
            };
        }
    }
}

/// The prefilter path: denoises the aux image `src` and writes it to `output`, or
/// returns it (packed RGB) when there is none.
pub(super) fn prefilter(
    src: &RawImage,
    output: Option<&RawImage>,
    kind: AuxKind,
) -> Option<Vec<f32>> {
    let l = src.layout;
    let mut input = Vec::with_capacity(l.width * l.height * 3);
    for y in 0..l.height {
        for x in 0..l.width {
            // SAFETY: validated layout, caller-kept buffer.
            input.extend_from_slice(&unsafe { read3(src.ptr, &l, x, y) });
        }
    }
    let result = filter_aux(&input, l.width, l.height, kind);
    let Some(out) = output else {
        return Some(result);
    };
    // Sizes were checked at commit, and images cannot change without another commit.
    let o = out.layout;
    for y in 0..o.height.min(l.height) {
        for x in 0..o.width.min(l.width) {
            let i = (y * l.width + x) * 3;
            // SAFETY: validated layout; the input was copied first, so in-place works.
            unsafe { write3(out.ptr, &o, x, y, [result[i], result[i + 1], result[i + 2]]) };
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::reflect;

    #[test]
    fn reflect_pads_without_repeating_the_edge() {
        let v: Vec<usize> = (0..9).map(|i| reflect(i, 4)).collect();
        assert_eq!(v, vec![0, 1, 2, 3, 2, 1, 0, 1, 2]);
        assert_eq!(reflect(5, 1), 0);
    }
}
