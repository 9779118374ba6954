//! Tile planning: which windows of the image the network runs on, and which pixels each
//! window writes.
//!
//! The image is padded on the right and bottom to the model's alignment (the *canvas*).
//! Every tile runs the network on a window of one fixed size (one cached plan), placed at an
//! aligned offset so max-pooling grids line up with an untiled run. Each window writes only
//! its *core*; cores partition the image. A window reaches at least `overlap` pixels past its
//! core on every side, except where it meets the canvas edge, which an untiled run meets
//! too. With `overlap` at least half the receptive field, each output pixel therefore sees
//! the same inputs tiled as untiled.

use crate::Error;

/// A rectangle in pixels: origin (x, y) and size (w, h).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rect {
    /// Left column.
    pub x: usize,
    /// Top row.
    pub y: usize,
    /// Width in pixels.
    pub w: usize,
    /// Height in pixels.
    pub h: usize,
}

/// One tile: the window the network runs on (canvas coordinates) and the core it writes
/// (image coordinates, always inside the window).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tile {
    /// Network input region, `tile_w x tile_h` of the plan.
    pub window: Rect,
    /// Output region written by this tile.
    pub core: Rect,
}

/// The tiles of one image.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TilePlan {
    /// Image size (w, h).
    pub image: (usize, usize),
    /// Canvas size (w, h): the image padded to the alignment.
    pub canvas: (usize, usize),
    /// Window size (w, h) shared by every tile.
    pub window: (usize, usize),
    /// Row-major list of tiles.
    pub tiles: Vec<Tile>,
}

/// One axis of length `n`: (window start, core start, core length) per segment, for
/// windows of length `window` (aligned, at least `2 overlap + align` unless one window
/// covers the canvas). The first and last windows sit on the canvas edges and need context
/// on their inner side only, so their cores reach to `window - overlap`; a window in the
/// middle starts `overlap` before its core, rounded down to the alignment.
fn segments(n: usize, align: usize, overlap: usize, window: usize) -> Vec<(usize, usize, usize)> {
    let canvas = n.div_ceil(align) * align;
    if window >= canvas {
        return vec![(0, 0, n)];
    }
    let mut segs = Vec::new();
    let mut s = 0;
    loop {
        let start = if s == 0 {
            0
        } else {
            (s - overlap) / align * align
        };
        if start + window >= canvas {
            segs.push((canvas - window, s, n - s));
            return segs;
        }
        let end = (start + window - overlap).min(n);
        segs.push((start, s, end - s));
        if end == n {
            return segs; // the core reached the image's end inside the canvas padding
        }
        s = end;
    }
}

/// A plan's cost as the budget planner orders it: (rounds x window area, work, tiles).
type Cost = (usize, usize, usize);

/// The smallest window a tile may have: a core of one alignment step between overlaps.
fn min_window(align: usize, overlap: usize) -> usize {
    2 * overlap + align
}

/// One axis's choices for the budget planner: (window, segments) for each window length
/// that needs fewer segments than every shorter one, from the smallest window up to the
/// canvas (one segment).
fn axis_choices(n: usize, align: usize, overlap: usize) -> Vec<(usize, usize)> {
    let canvas = n.div_ceil(align) * align;
    let mut out: Vec<(usize, usize)> = Vec::new();
    let mut win = min_window(align, overlap).min(canvas);
    loop {
        let count = segments(n, align, overlap, win).len();
        if out.last().is_none_or(|&(_, c)| count < c) {
            out.push((win, count));
        }
        if win >= canvas {
            return out;
        }
        win += align;
    }
}

impl TilePlan {
    /// Plans tiles for a `width x height` image. `alignment` and `overlap` come from the model
    /// (overlap is rounded up to the alignment); `max_window` bounds the window side (e.g.
    /// from the memory budget). A window must leave a core of at least one alignment unit
    /// between its overlaps, so `max_window` is raised to `2 overlap + alignment` if needed;
    /// the caller decides whether that fits its budget.
    pub fn new(
        width: usize,
        height: usize,
        alignment: usize,
        overlap: usize,
        max_window: usize,
    ) -> Result<Self, Error> {
        Self::check(width, height, alignment)?;
        let overlap = overlap.div_ceil(alignment) * alignment;
        let fit = |n: usize| {
            let canvas = n.div_ceil(alignment) * alignment;
            (max_window / alignment * alignment)
                .max(min_window(alignment, overlap))
                .min(canvas)
        };
        Ok(Self::with_windows(
            width,
            height,
            alignment,
            overlap,
            (fit(width), fit(height)),
        ))
    }

    /// Plans tiles for a `width x height` image whose windows may hold at most
    /// `max_area` pixels each, for `threads` workers: of every window shape that fits, the
    /// one that finishes first (rounds of `threads` tiles, times the window's area), then
    /// the one with the least work in all. Square windows of the largest area that fits
    /// would cut 1080p into windows 1.75 times its size at a 4 GB budget, and 2.85 times
    /// at 1.5 GB (they overshoot on one axis and repeat overlap on the other). Where no
    /// shape fits, the smallest windows are planned, and the caller decides.
    pub fn for_budget(
        width: usize,
        height: usize,
        alignment: usize,
        overlap: usize,
        max_area: f64,
        threads: usize,
    ) -> Result<Self, Error> {
        Self::check(width, height, alignment)?;
        let overlap = overlap.div_ceil(alignment) * alignment;
        let xs = axis_choices(width, alignment, overlap);
        let ys = axis_choices(height, alignment, overlap);
        let threads = threads.max(1);
        let mut best: Option<(Cost, (usize, usize))> = None;
        for &(ww, nx) in &xs {
            for &(wh, ny) in &ys {
                let area = ww * wh;
                if area as f64 > max_area {
                    continue;
                }
                let tiles = nx * ny;
                let key = (tiles.div_ceil(threads) * area, tiles * area, tiles);
                if best.is_none_or(|(k, _)| key < k) {
                    best = Some((key, (ww, wh)));
                }
            }
        }
        let windows = best.map_or((xs[0].0, ys[0].0), |(_, w)| w);
        Ok(Self::with_windows(
            width, height, alignment, overlap, windows,
        ))
    }

    fn check(width: usize, height: usize, alignment: usize) -> Result<(), Error> {
        if width == 0 || height == 0 {
            return Err(Error::InvalidArgument(format!(
                "image size {width}x{height} has no pixels"
            )));
        }
        if alignment == 0 {
            return Err(Error::InvalidArgument("alignment must be positive".into()));
        }
        Ok(())
    }

    /// The plan for windows of `(ww, wh)` (aligned, within the canvas, at least the
    /// smallest window where more than one is needed); `overlap` is aligned.
    fn with_windows(
        width: usize,
        height: usize,
        alignment: usize,
        overlap: usize,
        (ww, wh): (usize, usize),
    ) -> Self {
        let xs = segments(width, alignment, overlap, ww);
        let ys = segments(height, alignment, overlap, wh);
        let mut tiles = Vec::with_capacity(xs.len() * ys.len());
        for &(wy, cy, ch) in &ys {
            for &(wx, cx, cw) in &xs {
                tiles.push(Tile {
                    window: Rect {
                        x: wx,
                        y: wy,
                        w: ww,
                        h: wh,
                    },
                    core: Rect {
                        x: cx,
                        y: cy,
                        w: cw,
                        h: ch,
                    },
                });
            }
        }
        Self {
            image: (width, height),
            canvas: (
                width.div_ceil(alignment) * alignment,
                height.div_ceil(alignment) * alignment,
            ),
            window: (ww, wh),
            tiles,
        }
    }

    /// Pixels the network processes in total, over pixels of the image (>= 1).
    pub fn cost_ratio(&self) -> f64 {
        let work = self.tiles.len() * self.window.0 * self.window.1;
        work as f64 / (self.image.0 * self.image.1) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check_invariants(p: &TilePlan, align: usize, overlap: usize) {
        let (w, h) = p.image;
        let mut covered = vec![0u8; w * h];
        for t in &p.tiles {
            let (win, core) = (t.window, t.core);
            assert_eq!((win.w, win.h), p.window);
            assert_eq!(win.x % align, 0);
            assert_eq!(win.y % align, 0);
            assert!(win.x + win.w <= p.canvas.0 && win.y + win.h <= p.canvas.1);
            // Core inside window, with `overlap` of context unless at the canvas edge.
            assert!(core.x >= win.x && core.x + core.w <= win.x + win.w);
            assert!(core.y >= win.y && core.y + core.h <= win.y + win.h);
            let ov = overlap.div_ceil(align) * align;
            assert!(win.x == 0 || core.x - win.x >= ov, "{t:?}");
            assert!(win.y == 0 || core.y - win.y >= ov, "{t:?}");
            assert!(win.x + win.w == p.canvas.0 || win.x + win.w - (core.x + core.w) >= ov);
            assert!(win.y + win.h == p.canvas.1 || win.y + win.h - (core.y + core.h) >= ov);
            for y in core.y..core.y + core.h {
                for x in core.x..core.x + core.w {
                    covered[y * w + x] += 1;
                }
            }
        }
        assert!(
            covered.iter().all(|&c| c == 1),
            "cores must partition the image"
        );
    }

    #[test]
    fn small_image_is_one_tile() {
        let p = TilePlan::new(100, 70, 32, 64, 4096).unwrap();
        assert_eq!(p.tiles.len(), 1);
        assert_eq!(p.window, (128, 96));
        assert_eq!(p.canvas, (128, 96));
        check_invariants(&p, 32, 64);
    }

    #[test]
    fn tiles_partition_odd_sizes() {
        for (w, h) in [(1000, 700), (1, 1), (33, 65), (513, 257), (4000, 31)] {
            for (ov, maxw) in [(0, 64), (32, 128), (64, 256), (224, 512), (200, 1000)] {
                let p = TilePlan::new(w, h, 32, ov, maxw).unwrap();
                check_invariants(&p, 32, ov);
            }
        }
    }

    #[test]
    fn window_grows_to_fit_the_overlap() {
        let p = TilePlan::new(1000, 1000, 32, 224, 128).unwrap();
        assert_eq!(p.window, (480, 480));
        check_invariants(&p, 32, 224);
        assert!(p.cost_ratio() > 1.0);
    }

    #[test]
    fn budget_plans_partition_and_fit() {
        for (w, h) in [
            (1920, 1080),
            (1, 1),
            (33, 65),
            (513, 257),
            (4000, 31),
            (3840, 2160),
        ] {
            for area in [0.0, 5e4, 3e5, 1e6, 4e6, 1e9] {
                for threads in [1, 2, 3, 16] {
                    let p = TilePlan::for_budget(w, h, 32, 96, area, threads).unwrap();
                    check_invariants(&p, 32, 96);
                    let (ww, wh) = p.window;
                    let smallest = min_window(32, 96);
                    // Windows fit the budget, or none could and they are the smallest.
                    let fits = (ww * wh) as f64 <= area;
                    assert!(fits || (ww <= smallest && wh <= smallest), "{p:?}");
                }
            }
        }
    }

    #[test]
    fn budget_plan_for_1080p_splits_once_on_the_long_axis() {
        // Two threads with room to spare: two windows of half the width plus one overlap
        // (edge windows need context on one side only), not one window or square ones.
        let p = TilePlan::for_budget(1920, 1080, 32, 96, 1e9, 2).unwrap();
        assert_eq!((p.tiles.len(), p.window), (2, (1056, 1088)));
        assert!(p.cost_ratio() < 1.11, "{}", p.cost_ratio());
        // One thread and room: one window, no repeated work beyond the canvas padding.
        let p = TilePlan::for_budget(1920, 1080, 32, 96, 1e9, 1).unwrap();
        assert_eq!((p.tiles.len(), p.window), (1, (1920, 1088)));
        // The budget of the old square plan's 992x992 windows (six of them, 2.85x): two
        // rounds of two 1056x640 windows beat three 768x1088 ones side by side.
        let p = TilePlan::for_budget(1920, 1080, 32, 96, 992.0 * 992.0, 2).unwrap();
        assert_eq!((p.tiles.len(), p.window), (4, (1056, 640)), "{p:?}");
        assert!(p.cost_ratio() < 1.35, "{p:?}");
    }

    #[test]
    fn more_budget_never_plans_slower() {
        for (w, h) in [(1920, 1080), (1000, 700), (4000, 31)] {
            for threads in [1, 2, 8] {
                let mut last = usize::MAX;
                for k in 1..40 {
                    let area = 2e4 * 1.3f64.powi(k);
                    let p = TilePlan::for_budget(w, h, 32, 96, area, threads).unwrap();
                    let (ww, wh) = p.window;
                    let makespan = p.tiles.len().div_ceil(threads) * ww * wh;
                    if (ww * wh) as f64 <= area {
                        assert!(makespan <= last, "{w}x{h} {threads} threads at {area}");
                        last = makespan;
                    }
                }
            }
        }
    }

    #[test]
    fn empty_images_are_refused() {
        assert!(TilePlan::new(0, 10, 32, 0, 64).is_err());
        assert!(TilePlan::new(10, 0, 32, 0, 64).is_err());
    }
}
