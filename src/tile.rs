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

/// One axis: (window start, core start, core length) per segment, and the window length.
fn axis(
    n: usize,
    align: usize,
    overlap: usize,
    max_window: usize,
) -> (usize, Vec<(usize, usize, usize)>) {
    let canvas = n.div_ceil(align) * align;
    let max_window = (max_window / align) * align;
    if max_window >= canvas {
        return (canvas, vec![(0, 0, n)]);
    }
    let core = max_window - 2 * overlap;
    let mut segs = Vec::new();
    let mut s = 0;
    while s < n {
        let len = core.min(n - s);
        let start = s.saturating_sub(overlap).min(canvas - max_window);
        segs.push((start, s, len));
        s += core;
    }
    (max_window, segs)
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
        if width == 0 || height == 0 {
            return Err(Error::InvalidArgument(format!(
                "image size {width}x{height} has no pixels"
            )));
        }
        if alignment == 0 {
            return Err(Error::InvalidArgument("alignment must be positive".into()));
        }
        let overlap = overlap.div_ceil(alignment) * alignment;
        let max_window = max_window.max(2 * overlap + alignment);
        let (ww, xs) = axis(width, alignment, overlap, max_window);
        let (wh, ys) = axis(height, alignment, overlap, max_window);
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
        Ok(Self {
            image: (width, height),
            canvas: (
                width.div_ceil(alignment) * alignment,
                height.div_ceil(alignment) * alignment,
            ),
            window: (ww, wh),
            tiles,
        })
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
    fn empty_images_are_refused() {
        assert!(TilePlan::new(0, 10, 32, 0, 64).is_err());
        assert!(TilePlan::new(10, 0, 32, 0, 64).is_err());
    }
}
