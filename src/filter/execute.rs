//! One execution: validate, per-image statistics, tiles in parallel, staged output.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use rayon::prelude::*;

use super::{ExecuteStats, ImageName, Monitor, RawImage};
use crate::color::{self, features, Exposure};
use crate::engine::{Model, NetInput};
use crate::image::{read3, Layout};
use crate::tile::{Tile, TilePlan};
use crate::Error;

pub(super) struct Job<'m> {
    pub model: &'m Arc<Model>,
    pub images: [Option<RawImage>; 5],
    pub hdr: bool,
    pub input_scale: Option<f32>,
    pub max_memory_bytes: usize,
    pub tile_size: usize,
    pub verbose: i32,
}

/// Floats per window pixel that a tile allocates besides tract: chroma 2, luma 1, aux 7,
/// excess 1, network output 3.
const TILE_PLANES: f64 = 14.0;

/// tract's scratch beyond the live tensors the engine's estimate counts (packing panels,
/// direct-convolution buffers, allocator slack): one 832x832 TEMC-2 tile peaked about 1.4
/// times above its estimate (`MALLOC_MMAP_THRESHOLD_=1048576 /usr/bin/time -v` on
/// `benches/tract_vs_ort.rs --size 832`); `scripts/memory-4k` checks the budget end to end.
const TRACT_SCRATCH: f64 = 1.5;

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

/// Runs the job. With an "output" image the result is written there and `None` returned;
/// without one, the packed RGB result is returned instead.
pub(super) fn run(
    job: Job<'_>,
    pool: &rayon::ThreadPool,
    monitor: Option<&mut Monitor<'_>>,
) -> Result<(ExecuteStats, Option<Vec<f32>>), Error> {
    let model = job.model.as_ref();
    let info = model.info();
    let color = job.images[ImageName::Color as usize]
        .ok_or_else(|| Error::InvalidOperation("image \"color\" is not set".into()))?;
    let output = job.images[ImageName::Output as usize];
    let (w, h) = (color.layout.width, color.layout.height);
    for (i, img) in job.images.iter().enumerate() {
        let Some(img) = img else { continue };
        let name = [
            ImageName::Color,
            ImageName::Albedo,
            ImageName::Normal,
            ImageName::Depth,
            ImageName::Output,
        ][i];
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

    // In-place: inputs that share bytes with the output are copied first, because tiles
    // write while others still read.
    let mut snapshot_bytes = 0usize;
    let source = |i: ImageName, snapshot_bytes: &mut usize| -> Result<Option<Source>, Error> {
        let Some(img) = job.images[i as usize] else {
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
        *snapshot_bytes += img.span;
        let img = RawImage {
            ptr: copy.as_mut_ptr(),
            ..img
        };
        Ok(Some(Source {
            img,
            _copy: Some(copy),
        }))
    };
    let color = source(ImageName::Color, &mut snapshot_bytes)?.expect("color is set");
    let albedo = source(ImageName::Albedo, &mut snapshot_bytes)?;
    let normal = source(ImageName::Normal, &mut snapshot_bytes)?;
    let depth = source(ImageName::Depth, &mut snapshot_bytes)?;

    // Per-image statistics, once, before tiling.
    let ldr = |p: [f32; 3]| p.map(|c| if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) });
    let input_scale = match (job.hdr, job.input_scale) {
        (_, Some(s)) => s,
        (false, None) => 1.0,
        (true, None) => color::auto_input_scale(
            (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .map(|(x, y)| color.px(x, y)),
        ),
    };
    let exposure = Exposure::new(input_scale, info.pq_nits_per_unit)?;
    let depth_scale = depth.as_ref().and_then(|d| {
        features::depth_scale(
            (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .map(|(x, y)| d.px(x, y)[0]),
        )
    });

    // Tile size from the memory budget.
    let threads = pool.current_num_threads().max(1);
    let (weights, per_px) = model.memory_estimate()?;
    let per_px = per_px * TRACT_SCRATCH + TILE_PLANES * 4.0;
    let staging = (w * h * 12 + snapshot_bytes) as f64;
    let per_thread = (job.max_memory_bytes as f64 - staging - weights) / threads as f64;
    let overlap = info.tile_overlap.div_ceil(info.alignment) * info.alignment;
    let side = if job.tile_size > 0 {
        job.tile_size.div_ceil(info.alignment) * info.alignment + 2 * overlap
    } else if per_thread > 0.0 {
        (per_thread / per_px).sqrt() as usize
    } else {
        0
    };
    let plan = TilePlan::new(w, h, info.alignment, info.tile_overlap, side)?;
    let concurrent = threads.min(plan.tiles.len());
    let (tw, th) = plan.window;
    let estimated_peak = staging + weights + concurrent as f64 * per_px * (tw * th) as f64;
    if job.verbose > 0 {
        eprintln!(
            "temc: {w}x{h}, {} tile(s) of {tw}x{th} (cost x{:.2}), {threads} thread(s), input scale {input_scale}, ~{:.0} MB",
            plan.tiles.len(),
            plan.cost_ratio(),
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
    let hdr = job.hdr;

    let run_tile = |tile: &Tile| -> Result<(), Error> {
        if stop.load(Ordering::Relaxed) {
            return Err(Error::Cancelled);
        }
        let win = tile.window;
        let n = win.w * win.h;
        let mut chroma = vec![0f32; 2 * n];
        let mut luma = vec![0f32; n];
        let mut aux = vec![0f32; 7 * n];
        let mut excess = vec![1f32; n];
        for wy in 0..win.h {
            let y = reflect(win.y + wy, h);
            for wx in 0..win.w {
                let x = reflect(win.x + wx, w);
                let i = wy * win.w + wx;
                let mut c = color.px(x, y);
                if !hdr {
                    c = ldr(c);
                }
                let e = color::encode(c, exposure);
                chroma[i] = e.hsv[0];
                chroma[n + i] = e.hsv[1];
                luma[i] = e.hsv[2];
                excess[i] = e.excess;
                let a = albedo
                    .as_ref()
                    .map_or([0.0; 3], |s| features::albedo(s.px(x, y)));
                let nm = normal
                    .as_ref()
                    .map_or([0.5; 3], |s| features::normal(s.px(x, y)));
                let d = depth
                    .as_ref()
                    .map_or(0.0, |s| features::depth(s.px(x, y)[0], depth_scale));
                for k in 0..3 {
                    aux[k * n + i] = a[k];
                    aux[(3 + k) * n + i] = nm[k];
                }
                aux[6 * n + i] = d;
            }
        }
        let hsv = model.run(
            NetInput {
                chroma: &chroma,
                luma: &luma,
                aux: &aux,
            },
            win.h,
            win.w,
        )?;
        let core = tile.core;
        for y in core.y..core.y + core.h {
            for x in core.x..core.x + core.w {
                let i = (y - win.y) * win.w + (x - win.x);
                let mut rgb =
                    color::decode([hsv[i], hsv[n + i], hsv[2 * n + i]], excess[i], exposure);
                if !hdr {
                    rgb = ldr(rgb);
                }
                let o = (y * w + x) * 3;
                // SAFETY: cores partition the image, so no two tiles write the same pixel,
                // and `o + 2 < w * h * 3`.
                unsafe {
                    for (k, v) in rgb.into_iter().enumerate() {
                        *out_ptr.get().add(o + k) = v;
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

    let stats = ExecuteStats {
        tiles: n_tiles,
        window: plan.window,
        cost_ratio: plan.cost_ratio(),
        input_scale,
        threads,
        estimated_peak_bytes: estimated_peak,
    };
    let Some(output) = output else {
        return Ok((stats, Some(staged)));
    };
    // Every tile succeeded: now, and only now, write the caller's output.
    let layout: Layout = output.layout;
    for y in 0..h {
        for x in 0..w {
            let o = (y * w + x) * 3;
            // SAFETY: the output layout was validated against its buffer when set.
            unsafe {
                crate::image::write3(
                    output.ptr,
                    &layout,
                    x,
                    y,
                    [staged[o], staged[o + 1], staged[o + 2]],
                )
            };
        }
    }
    Ok((stats, None))
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
