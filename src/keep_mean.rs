//! Keep-mean: after every tile is reconstructed, each block of the output is rescaled to
//! the noisy input's mean over that block (docs/keep-mean.md).
//!
//! The reconstruction's weights sum to one per *output* pixel, so nothing bounds how much
//! a bright pixel gives away (a thin bright line spread into its neighbours) or keeps (a firefly
//! the filters drop), and the image's mean drifts. The noisy input's block mean is
//! unbiased; the ratio of the input's and the output's block sums, per channel, clamped and
//! interpolated bilinearly between block centres, restores it without moving detail. It
//! runs on the whole image, so it is the same whatever the tiling or thread count. A
//! factor's part above [`SPREAD_ABOVE`] multiplies the output's local mean instead of the
//! pixel, so a block whose filters dropped most of its energy gets it back as smooth light,
//! not as its few remnants multiplied tenfold; that mean is over the output clipped at
//! [`SPREAD_CLIP`] times its own window mean, so a lamp's light stays out of the black
//! beside it.
//! `training/temc_train/keep_mean.py` is the same function; `tests/data/keep_mean_vectors.json`
//! pins the two together.

use std::collections::TryReserveError;

use ndarray::{Array2, Array3, ArrayView2, ArrayView3, Axis, Zip};

mod lamps;
pub use lamps::{LAMP_ABOVE, LAMP_GROW, LAMP_MOST};

/// Block side in pixels of the stage's first pass (docs/keep-mean-measured.md).
pub const BLOCK: usize = 128;
/// The largest factor a block may be scaled by, up or down, in the first pass.
pub const CLAMP: f64 = 4.0;
/// The largest factor of the second pass, over the whole image: what the block clamp left
/// (a dark room the filters darkened tenfold) without letting a nearly black output explode.
pub const GLOBAL_CLAMP: f64 = 16.0;
/// The largest factor applied to a pixel itself; the rest of a larger factor multiplies the
/// output's mean over the pixel's [`SPREAD_RADIUS`] window (docs/keep-mean.md, "Spread").
pub const SPREAD_ABOVE: f64 = 1.25;
/// Radius of that window: (2 r + 1)^2 pixels, the part inside the image.
pub const SPREAD_RADIUS: usize = 16;
/// The window mean a spread multiplies is over the output clipped at this many times its
/// own window mean, so a lamp's light stays out of its dark neighbours' share.
pub const SPREAD_CLIP: f64 = 4.0;

/// The core's keep-mean stage: first a lamp's own factor (the `lamps` module: filters that
/// dim a lamp do not make the blocks raise its neighbours), then [`keep_mean`] over
/// [`BLOCK`]-pixel blocks (energy stays near where it was rendered), then over the whole
/// image (its mean follows the input's within [`GLOBAL_CLAMP`]), then over the whole image
/// once more, scaling only: window means do not keep sums near the image's edges and the
/// spread's clip holds back a lamp's excess, so a spread leaves the mean off, and this pass
/// makes it exact. `input` is the sanitised noisy radiance, read once (its luminance is
/// kept for the lamps; the whole image's sum is the sum of its block sums). `max` is the
/// output ceiling.
///
/// # Errors
/// When the lamps' planes (two f32 and a byte per pixel, freed before the blocks) or the
/// spread's one image-sized buffer cannot be allocated.
///
/// # Panics
/// If `out` is not `w * h * 3` long or `w` or `h` is 0.
pub fn stage(
    out: &mut [f32],
    input: impl Iterator<Item = [f32; 3]>,
    (w, h): (usize, usize),
    max: f32,
) -> Result<(), TryReserveError> {
    check(out, (w, h));
    let mut luma = Vec::new();
    luma.try_reserve_exact(w * h)?;
    let input = input.inspect(|&p| luma.push(lamps::luma(p) as f32));
    let blocks = block_sums(input, (w, h), BLOCK);
    lamps::restore_lamps(out, &luma, (w, h))?;
    drop(luma);
    blocks_then_whole(out, (w, h), &blocks, max)
}

/// The stage's three passes after the lamps: blocks, whole image, whole image scaling
/// only; `blocks` are the input's [`block_sums`] at [`BLOCK`].
fn blocks_then_whole(
    out: &mut [f32],
    (w, h): (usize, usize),
    blocks: &Array3<f64>,
    max: f32,
) -> Result<(), TryReserveError> {
    rescale(out, (w, h), blocks, BLOCK, CLAMP, max, SPREAD_ABOVE)?;
    let whole = blocks
        .sum_axis(Axis(0))
        .sum_axis(Axis(0))
        .into_shape_with_order((1, 1, 3))
        .expect("three channels");
    let global =
        |out: &mut [f32], above| rescale(out, (w, h), &whole, w.max(h), GLOBAL_CLAMP, max, above);
    global(out, SPREAD_ABOVE)?;
    global(out, f64::INFINITY)
}

/// Checks that `out` holds `w` x `h` interleaved RGB pixels, at least one.
fn check(out: &[f32], (w, h): (usize, usize)) {
    assert!(w > 0 && h > 0, "keep-mean of an empty image");
    assert_eq!(out.len(), w * h * 3, "out holds w * h RGB pixels");
}

/// Per-channel sums over `block` x `block` blocks of `w` x `h` RGB pixels given row by
/// row (edge blocks partial), as (block row, block column, channel).
fn block_sums(
    pixels: impl Iterator<Item = [f32; 3]>,
    (w, h): (usize, usize),
    block: usize,
) -> Array3<f64> {
    let gw = w.div_ceil(block);
    let mut sums = Array3::zeros((h.div_ceil(block), gw, 3));
    let flat = sums.as_slice_mut().expect("a fresh array is contiguous");
    // Position as counters, not i % w and divisions: this runs per pixel, three times a
    // denoise. `at` is the current block's first sum, `left` the pixels left in it.
    let (mut x, mut y, mut at, mut left) = (0, 0, 0, block);
    for p in pixels {
        for (a, v) in flat[at..at + 3].iter_mut().zip(p) {
            *a += v as f64;
        }
        (x, left) = (x + 1, left - 1);
        if x == w {
            (x, y, left) = (0, y + 1, block);
            at = (y / block) * gw * 3;
        } else if left == 0 {
            (at, left) = (at + 3, block);
        }
    }
    sums
}

/// Bilinear taps along one axis of `n` pixels over `g` block centres: pixel i sits at grid
/// coordinate (i + 0.5) / block - 0.5, clamped to the outermost centres.
fn axis(n: usize, g: usize, block: usize) -> Vec<(usize, usize, f64)> {
    (0..n)
        .map(|i| {
            let t = ((i as f64 + 0.5) / block as f64 - 0.5).clamp(0.0, (g - 1) as f64);
            let i0 = t.floor() as usize;
            (i0, (i0 + 1).min(g - 1), t - i0 as f64)
        })
        .collect()
}

/// Rescales `out` (`w` x `h` interleaved RGB, the reconstruction's result) so that each
/// block's per-channel mean follows `input` (the sanitised noisy radiance the
/// reconstruction filtered, same size and order). `block` 0 is one block for the whole
/// image. Every factor is finite and in [1 / `clamp`, `clamp`] (1 where the output block is
/// black); its part above [`SPREAD_ABOVE`] spreads; the result is clamped to [0, `max`].
///
/// # Errors
/// When the spread's one image-sized buffer cannot be allocated.
///
/// # Panics
/// If `out` is not `w * h * 3` long, `w` or `h` is 0, or `clamp` < 1.
pub fn keep_mean(
    out: &mut [f32],
    input: impl Iterator<Item = [f32; 3]>,
    (w, h): (usize, usize),
    block: usize,
    clamp: f64,
    max: f32,
) -> Result<(), TryReserveError> {
    let block = if block == 0 { w.max(h) } else { block };
    // Every input pixel counts, a capped Inf too: the filters spread its value into its
    // neighbours, so leaving it out of the input's sum would darken its block and the image.
    check(out, (w, h));
    let sums = block_sums(input, (w, h), block);
    rescale(out, (w, h), &sums, block, clamp, max, SPREAD_ABOVE)
}

/// [`keep_mean`] from the input's block sums (of [`block_sums`] at `block`); factors above
/// `above` spread (infinity: pure scaling).
fn rescale(
    out: &mut [f32],
    (w, h): (usize, usize),
    input_sums: &Array3<f64>,
    block: usize,
    clamp: f64,
    max: f32,
    above: f64,
) -> Result<(), TryReserveError> {
    assert!(clamp >= 1.0);
    let pixels = out.chunks_exact(3).map(|p| [p[0], p[1], p[2]]);
    let output_sums = block_sums(pixels, (w, h), block);
    let ratio = Zip::from(input_sums)
        .and(&output_sums)
        .map_collect(|&i, &o| (if o > 0.0 { i / o } else { 1.0 }).clamp(1.0 / clamp, clamp));
    let mut factors = Factors::new(&ratio, (w, h), block);
    // A pixel's factor is a convex mix of block factors: none above `above`, no spread.
    if !ratio.iter().any(|&r| r > above) {
        for (y, row) in out.chunks_exact_mut(3 * w).enumerate() {
            for (v, f) in row.iter_mut().zip(factors.row(y)) {
                *v = ((*v as f64 * f) as f32).clamp(0.0, max);
            }
        }
        return Ok(());
    }
    let mut rows = row_means(out, (w, h), SPREAD_RADIUS)?;
    clip_to_window_means(out, &mut rows);
    let mut means = WindowMeans::new(rows.view(), SPREAD_RADIUS);
    for (y, row) in out.chunks_exact_mut(3 * w).enumerate() {
        let mean = means.next(rows.view(), y);
        let mean = mean.as_slice().expect("a fresh array is contiguous");
        for ((v, f), m) in row.iter_mut().zip(factors.row(y)).zip(mean) {
            let scale = f.min(above);
            let o = *v as f64 * scale + (f - scale) * m;
            *v = (o as f32).clamp(0.0, max);
        }
    }
    Ok(())
}

/// Turns `rows`, the [`row_means`] of `img`, into the row means of `img` clipped at
/// [`SPREAD_CLIP`] times its window mean (radius [`SPREAD_RADIUS`]): the spread's source,
/// so that a lamp among dark pixels lights its window's share no more than a few ordinary
/// pixels would (docs/keep-mean.md, "Spread"). In place, to keep the spread at one
/// image-sized buffer: a clipped row waits in a ring of r + 1 rows until the window has
/// passed the row it replaces.
fn clip_to_window_means(img: &[f32], rows: &mut Array3<f32>) {
    let (h, w, _) = rows.dim();
    let span = SPREAD_RADIUS + 1;
    let mut ring = Array3::<f32>::zeros((span.min(h), w, 3));
    let (mut prefix, mut clipped) = (vec![[0f64; 3]; w + 1], vec![0f32; 3 * w]);
    let mut means = WindowMeans::new(rows.view(), SPREAD_RADIUS);
    for (y, line) in img.chunks_exact(3 * w).enumerate() {
        let mean = means.next(rows.view(), y);
        for ((c, &v), &m) in clipped.iter_mut().zip(line).zip(mean.iter()) {
            *c = (v as f64).min(SPREAD_CLIP * m) as f32;
        }
        // `next(y)` took row y - span out of the window for good: its slot is free.
        let mut slot = ring.index_axis_mut(Axis(0), y % span);
        if y >= span {
            rows.index_axis_mut(Axis(0), y - span).assign(&slot);
        }
        let dst = slot.as_slice_mut().expect("a fresh array is contiguous");
        segment_means(&clipped, SPREAD_RADIUS, &mut prefix, dst);
    }
    for y in h.saturating_sub(span)..h {
        let slot = ring.index_axis(Axis(0), y % span);
        rows.index_axis_mut(Axis(0), y).assign(&slot);
    }
}

/// The factor at each pixel and channel: bilinear between the block centres, horizontally
/// first. The two horizontal mixes of a row (its upper and lower block row) change only
/// every `block` rows, so they are kept.
struct Factors<'a> {
    ratio: &'a Array3<f64>,
    xs: Vec<(usize, usize, f64)>,
    ys: Vec<(usize, usize, f64)>,
    /// The block rows `top` and `bottom` hold the mixes of.
    mixed: Option<(usize, usize)>,
    top: Vec<f64>,
    bottom: Vec<f64>,
    row: Vec<f64>,
}

impl<'a> Factors<'a> {
    fn new(ratio: &'a Array3<f64>, (w, h): (usize, usize), block: usize) -> Self {
        let (gh, gw, _) = ratio.dim();
        Factors {
            ratio,
            xs: axis(w, gw, block),
            ys: axis(h, gh, block),
            mixed: None,
            top: vec![0.0; 3 * w],
            bottom: vec![0.0; 3 * w],
            row: vec![0.0; 3 * w],
        }
    }

    /// Row y's factors, interleaved like the image.
    fn row(&mut self, y: usize) -> &[f64] {
        let (y0, y1, fy) = self.ys[y];
        if self.mixed != Some((y0, y1)) {
            let r = self.ratio;
            let mix = |yb: usize, dst: &mut [f64]| {
                for (d, &(x0, x1, fx)) in dst.chunks_exact_mut(3).zip(&self.xs) {
                    for (k, v) in d.iter_mut().enumerate() {
                        *v = r[[yb, x0, k]] * (1.0 - fx) + r[[yb, x1, k]] * fx;
                    }
                }
            };
            mix(y0, &mut self.top);
            mix(y1, &mut self.bottom);
            self.mixed = Some((y0, y1));
        }
        for ((f, t), b) in self.row.iter_mut().zip(&self.top).zip(&self.bottom) {
            *f = t * (1.0 - fy) + b * fy;
        }
        &self.row
    }
}

/// The window of radius `r` around `i` along an axis of `n`, clipped to it: [lo, hi).
fn window(i: usize, n: usize, r: usize) -> (usize, usize) {
    (i.saturating_sub(r), (i + r + 1).min(n))
}

/// Each pixel's per-channel mean over its row segment of radius `r` (inside the image), for
/// [`WindowMeans`]: the window is a product of segments, so its mean is separable.
fn row_means(
    img: &[f32],
    (w, h): (usize, usize),
    r: usize,
) -> Result<Array3<f32>, TryReserveError> {
    let mut rows = Vec::new();
    rows.try_reserve_exact(w * h * 3)?;
    rows.resize(w * h * 3, 0.0);
    let mut prefix = vec![[0f64; 3]; w + 1];
    for (line, dst) in img.chunks_exact(3 * w).zip(rows.chunks_exact_mut(3 * w)) {
        segment_means(line, r, &mut prefix, dst);
    }
    Ok(Array3::from_shape_vec((h, w, 3), rows).expect("one mean per pixel and channel"))
}

/// One row of [`row_means`] (or of a plane of `C` channels, the lamps' one):
/// `dst` (interleaved like `line`) gets each pixel's per-channel mean over its segment of
/// radius `r`; `prefix` (w + 1 long) is scratch.
fn segment_means<const C: usize>(line: &[f32], r: usize, prefix: &mut [[f64; C]], dst: &mut [f32]) {
    let w = line.len() / C;
    for (x, p) in line.chunks_exact(C).enumerate() {
        for k in 0..C {
            prefix[x + 1][k] = prefix[x][k] + p[k] as f64;
        }
    }
    for (x, d) in dst.chunks_exact_mut(C).enumerate() {
        let (lo, hi) = window(x, w, r);
        let n = (hi - lo) as f64;
        for (k, v) in d.iter_mut().enumerate() {
            *v = ((prefix[hi][k] - prefix[lo][k]) / n) as f32;
        }
    }
}

/// The (2r + 1)^2 window means of an image row by row, in order: the [`row_means`]
/// averaged over the window's rows, in float64 running sums, for any number of channels
/// (the lamps' planes have one). The rows are passed to every step, not held, so a caller
/// may rewrite rows the window has passed.
struct WindowMeans {
    r: usize,
    acc: Array2<f64>,
    mean: Array2<f64>,
}

impl WindowMeans {
    fn new(rows: ArrayView3<'_, f32>, r: usize) -> Self {
        let (h, w, c) = rows.dim();
        let mut means = WindowMeans {
            r,
            acc: Array2::zeros((w, c)),
            mean: Array2::zeros((w, c)),
        };
        for y in 0..r.min(h) {
            means.add(rows, y, 1.0);
        }
        means
    }

    fn add(&mut self, rows: ArrayView3<'_, f32>, y: usize, sign: f64) {
        Zip::from(&mut self.acc)
            .and(rows.index_axis(Axis(0), y))
            .for_each(|a, &v| *a += sign * v as f64);
    }

    /// Row y's means, (x, channel); y counts up from 0 by one.
    fn next(&mut self, rows: ArrayView3<'_, f32>, y: usize) -> ArrayView2<'_, f64> {
        let (h, r) = (rows.dim().0, self.r);
        if y + r < h {
            self.add(rows, y + r, 1.0);
        }
        if y > r {
            self.add(rows, y - r - 1, -1.0);
        }
        let (lo, hi) = window(y, h, r);
        let n = (hi - lo) as f64;
        Zip::from(&mut self.mean)
            .and(&self.acc)
            .for_each(|m, &a| *m = a / n);
        self.mean.view()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mean(img: &[f32], k: usize) -> f64 {
        img.iter()
            .skip(k)
            .step_by(3)
            .map(|&v| v as f64)
            .sum::<f64>()
            / (img.len() / 3) as f64
    }

    #[test]
    fn a_uniformly_darkened_image_gets_its_mean_back() {
        let (w, h) = (70, 45);
        let input: Vec<[f32; 3]> = (0..w * h)
            .map(|i| [(i % 7) as f32, 0.5 + (i % 3) as f32, 0.01])
            .collect();
        let mut out: Vec<f32> = input.iter().flat_map(|p| p.map(|v| 0.8 * v)).collect();
        keep_mean(&mut out, input.iter().copied(), (w, h), 16, CLAMP, f32::MAX).unwrap();
        let flat: Vec<f32> = input.iter().flatten().copied().collect();
        for k in 0..3 {
            let ratio = mean(&out, k) / mean(&flat, k);
            assert!((ratio - 1.0).abs() < 1e-6, "channel {k}: {ratio}");
        }
    }

    #[test]
    fn factors_are_clamped_and_black_blocks_stay_black() {
        let (w, h) = (8, 8);
        // Input bright everywhere; output black in the left half, dim in the right. The
        // clamp stays below SPREAD_ABOVE, so every factor scales its own pixel.
        let input = vec![[10.0f32; 3]; w * h];
        let mut out: Vec<f32> = (0..w * h)
            .flat_map(|i| if i % w < 4 { [0.0; 3] } else { [1.0; 3] })
            .collect();
        keep_mean(&mut out, input.into_iter(), (w, h), 4, 1.2, f32::MAX).unwrap();
        for (i, v) in out.chunks_exact(3).enumerate() {
            // Right blocks want 10x, clamped to 1.2; the black blocks' factor 1 blends in
            // over the two columns between the block centres.
            let want = match i % w {
                0..4 => 0.0,
                4 => 1.125,
                5 => 1.175,
                _ => 1.2,
            };
            assert!(
                v.iter().all(|&c| (c - want).abs() < 1e-6),
                "pixel {i}: {v:?}"
            );
        }
    }

    /// A block whose filter dropped most of its energy keeps one remnant (a firefly it
    /// half-kept): the missing light comes back over the block, not in the remnant. Scaling
    /// alone (the stage before the spread) made it 3.3x brighter.
    #[test]
    fn missing_energy_comes_back_smooth_not_in_the_remnants() {
        let (w, h) = (64, 64);
        let input = vec![[0.1f32; 3]; w * h];
        let remnant = 40 * w + 23;
        let mut out: Vec<f32> = (0..w * h)
            .flat_map(|i| [if i == remnant { 0.5 } else { 0.03 }; 3])
            .collect();
        stage(&mut out, input.iter().copied(), (w, h), f32::MAX).unwrap();
        for k in 0..3 {
            let ratio = mean(&out, k) / 0.1;
            assert!(
                (ratio - 1.0).abs() < 1e-5,
                "channel {k}: mean ratio {ratio}"
            );
            let r = out[remnant * 3 + k];
            assert!(r < 2.0 * 0.5 && r > 0.5, "channel {k}: remnant became {r}");
        }
        // The dark pixels carry the light: all of them near 0.1 (the window mean of a
        // pixel near the remnant holds a little of it).
        let dark = out
            .chunks_exact(3)
            .enumerate()
            .filter(|(i, _)| *i != remnant);
        assert!(dark
            .flat_map(|(_, p)| p)
            .all(|&v| (0.095..0.105).contains(&v)));
    }

    /// A 2x2 lamp of 1000 on black the filters dimmed to `lit`, over a dim floor:
    /// (input, output, whether pixel i is black).
    fn lamp_on_black(lit: f32) -> (Vec<[f32; 3]>, Vec<f32>, impl Fn(usize) -> bool) {
        let w = 64;
        let lamp = |x: usize, y: usize| (30..32).contains(&x) && (30..32).contains(&y);
        let value = move |i: usize, lit: f32| match (i % w, i / w) {
            (x, y) if lamp(x, y) => lit,
            (_, y) if y >= 40 => 0.05,
            _ => 0.0,
        };
        let input = (0..w * w).map(|i| [value(i, 1000.0); 3]).collect();
        let out = (0..w * w).flat_map(|i| [value(i, lit); 3]).collect();
        (input, out, move |i| value(i, 1.0) == 0.0)
    }

    /// The brightest channel of the pixels `which` picks.
    fn brightest(out: &[f32], which: impl Fn(usize) -> bool) -> f32 {
        (0..out.len() / 3)
            .filter(|&i| which(i))
            .flat_map(|i| &out[3 * i..3 * i + 3])
            .fold(0f32, |a, &v| a.max(v))
    }

    /// The lamp dimmed to 60 %, through the blocks alone (the lamp's own factor, which
    /// would give it back before them, left out): the spread's window mean beside it would
    /// be the lamp's light (about 1.8 on the black sky before [`SPREAD_CLIP`]); the black
    /// stays nearly black, the lamp gets its light back and the image's mean is exact.
    #[test]
    fn a_dimmed_lamp_does_not_light_the_black_beside_it() {
        let (w, h) = (64, 64);
        let (input, mut out, black) = lamp_on_black(600.0);
        let blocks = block_sums(input.iter().copied(), (w, h), BLOCK);
        blocks_then_whole(&mut out, (w, h), &blocks, f32::MAX).unwrap();
        let lit = brightest(&out, &black);
        assert!(lit <= 0.05, "black sky lit to {lit}");
        let at = 3 * (30 * w + 30);
        assert!((out[at] / 1000.0 - 1.0).abs() < 0.05, "lamp {}", out[at]);
        let flat: Vec<f32> = input.iter().flatten().copied().collect();
        assert!((mean(&out, 0) / mean(&flat, 0) - 1.0).abs() < 1e-5);
        // With its own factor first, the lamp is 900 before the blocks, which then only
        // scale: the black stays exactly black.
        let (input, mut out, black) = lamp_on_black(600.0);
        stage(&mut out, input.into_iter(), (w, h), f32::MAX).unwrap();
        assert_eq!(brightest(&out, black), 0.0);
    }

    /// A 2x2 lamp the filters dimmed to 80 % over a lit floor: without its own factor the
    /// blocks would raise the floor 22 % to pay for it; with it the lamp gets its light
    /// back and the floor stays as it was.
    #[test]
    fn a_dimmed_lamp_takes_its_own_light_back() {
        let (w, h) = (64, 64);
        let lamp = |i: usize| (30..32).contains(&(i % w)) && (30..32).contains(&(i / w));
        let value = |i: usize, lit: f32| if lamp(i) { lit } else { 0.1 };
        let input: Vec<[f32; 3]> = (0..w * h).map(|i| [value(i, 1000.0); 3]).collect();
        let mut out: Vec<f32> = (0..w * h).flat_map(|i| [value(i, 800.0); 3]).collect();
        stage(&mut out, input.into_iter(), (w, h), f32::MAX).unwrap();
        for (i, p) in out.chunks_exact(3).enumerate() {
            let want = value(i, 1000.0);
            assert!(
                p.iter().all(|&v| (v / want - 1.0).abs() < 1e-4),
                "pixel {i}: {p:?} against {want}"
            );
        }
    }

    /// The in-place clip (a ring of rows) against the plain one: the clipped image
    /// written out whole, then its row means; taller and shorter than the ring.
    #[test]
    fn the_in_place_clip_matches_the_plain_one() {
        for (w, h) in [(23, 41), (9, 5), (4, 17), (6, 18)] {
            let img: Vec<f32> = (0..w * h * 3)
                .map(|i| {
                    if i % 97 == 5 {
                        500.0
                    } else {
                        (i % 13) as f32 * 0.1
                    }
                })
                .collect();
            let mut rows = row_means(&img, (w, h), SPREAD_RADIUS).unwrap();
            let mut means = WindowMeans::new(rows.view(), SPREAD_RADIUS);
            let mut clipped = Vec::new();
            for (y, line) in img.chunks_exact(3 * w).enumerate() {
                let mean = means.next(rows.view(), y);
                clipped.extend(
                    line.iter()
                        .zip(mean.iter())
                        .map(|(&v, &m)| (v as f64).min(SPREAD_CLIP * m) as f32),
                );
            }
            let want = row_means(&clipped, (w, h), SPREAD_RADIUS).unwrap();
            clip_to_window_means(&img, &mut rows);
            assert_eq!(rows, want, "{w}x{h}");
        }
    }

    #[test]
    fn one_pixel_images_and_limits() {
        let mut out = vec![1.0f32, 0.0, 3.0];
        keep_mean(&mut out, [[3.0, 5.0, 1e9]].into_iter(), (1, 1), 0, 4.0, 1.0).unwrap();
        assert_eq!(out, vec![1.0, 0.0, 1.0]);
    }

    /// The float64 reference of training/temc_train/keep_mean.py.
    #[test]
    fn matches_the_python_vectors() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/keep_mean_vectors.json"
        );
        let text = std::fs::read_to_string(path).expect("tests/data/keep_mean_vectors.json");
        let cases: serde_json::Value = serde_json::from_str(&text).unwrap();
        let floats = |v: &serde_json::Value| -> Vec<f32> {
            v.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap() as f32)
                .collect()
        };
        for c in cases.as_array().unwrap() {
            let (w, h) = (
                c["w"].as_u64().unwrap() as usize,
                c["h"].as_u64().unwrap() as usize,
            );
            let input = floats(&c["input"]);
            let pixels = || input.chunks_exact(3).map(|p| [p[0], p[1], p[2]]);
            let mut out = floats(&c["output"]);
            let max = if c["ldr"].as_bool().unwrap() {
                1.0
            } else {
                crate::color::LINEAR_MAX
            };
            match c["block"].as_u64() {
                Some(block) => {
                    let clamp = c["clamp"].as_f64().unwrap();
                    keep_mean(&mut out, pixels(), (w, h), block as usize, clamp, max)
                }
                None => stage(&mut out, pixels(), (w, h), max),
            }
            .unwrap();
            for (i, (got, want)) in out.iter().zip(floats(&c["want"])).enumerate() {
                let tol = 1e-5 * want.abs().max(1.0);
                assert!(
                    (got - want).abs() <= tol,
                    "{} [{i}]: {got} against {want}",
                    c["name"]
                );
            }
        }
    }

    /// The stage's time at 1080p with a spread, and without its lamps' factor (the blocks
    /// alone), in one run, for refactors that must keep its speed: `cargo test --release
    /// --lib keep_mean::tests::bench -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn bench() {
        let (w, h) = (1920, 1080);
        let input: Vec<[f32; 3]> = (0..w * h)
            .map(|i| [(i % 7) as f32 * 0.1, 0.5, 0.01 + (i % 13) as f32])
            .collect();
        let dark: Vec<f32> = input
            .iter()
            .enumerate()
            .flat_map(|(i, p)| p.map(|v| v * if (i / w) % 200 < 50 { 0.1 } else { 0.9 }))
            .collect();
        let time = |run: &dyn Fn(&mut Vec<f32>)| {
            let mut best = f64::MAX;
            for _ in 0..5 {
                let mut out = dark.clone();
                let t = std::time::Instant::now();
                run(&mut out);
                best = best.min(t.elapsed().as_secs_f64());
                assert!(out.iter().all(|v| v.is_finite()));
            }
            best * 1e3
        };
        let whole = time(&|out| stage(out, input.iter().copied(), (w, h), f32::MAX).unwrap());
        let blocks = time(&|out| {
            let sums = block_sums(input.iter().copied(), (w, h), BLOCK);
            blocks_then_whole(out, (w, h), &sums, f32::MAX).unwrap()
        });
        println!(
            "keep-mean stage, 1920x1080 with spread, best of 5: {whole:.1} ms; without the lamps' factor {blocks:.1} ms"
        );
    }
}
