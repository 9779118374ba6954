//! A lamp's light back to the lamp, before the blocks (docs/keep-mean.md, "A lamp's light
//! back to the lamp").
//!
//! Filters that dim a small lamp leave its block short of light, and the blocks then raise
//! every pixel around it to pay the lamp's debt. A lamp here is where the noisy input's
//! luminance stands above [`LAMP_ABOVE`] times its window mean over a whole 2x2 block (an
//! opening: a lone high sample of a noisy input is not a lamp, so picking the set by its
//! noise does not bias it) and the output's does too. The lamp gets one factor for its three
//! channels (it keeps its hue): the input's luminance less the output's, summed over the
//! lamp grown by [`LAMP_GROW`] pixels (where its filters put its light), over the output's
//! sum on the lamp, plus one, in [1, [`LAMP_MOST`]]. `restore_lamps` in
//! training/temc_train/keep_mean.py is the same function.

use std::collections::TryReserveError;

use ndarray::{ArrayView2, ArrayView3};

use super::{segment_means, WindowMeans, SPREAD_RADIUS};
use crate::color::LUMA_WEIGHTS;

/// A lamp stands above this many times its window mean (radius [`SPREAD_RADIUS`]), in the
/// input and in the output.
pub const LAMP_ABOVE: f64 = 8.0;
/// The lamp's deficit is summed over the lamp grown by this many pixels.
pub const LAMP_GROW: usize = 8;
/// The largest factor a lamp gets.
pub const LAMP_MOST: f64 = 1.5;

/// A pixel's luminance in float64.
pub(super) fn luma(p: [f32; 3]) -> f64 {
    p.iter()
        .zip(LUMA_WEIGHTS)
        .map(|(&v, k)| v as f64 * k as f64)
        .sum()
}

/// Scales the lamps of `out` (`w` x `h` interleaved RGB) by their factor; `input` is the
/// noisy input's luminance ([`luma`] of the sanitised radiance, row by row). Holds one
/// f32 and one byte per pixel beside `input`.
///
/// # Errors
/// When the scratch plane or the mask cannot be allocated.
pub(super) fn restore_lamps(
    out: &mut [f32],
    input: &[f32],
    (w, h): (usize, usize),
) -> Result<(), TryReserveError> {
    let mut scratch = Vec::new();
    scratch.try_reserve_exact(w * h)?;
    scratch.resize(w * h, 0.0);
    let mut lamp = Vec::new();
    lamp.try_reserve_exact(w * h)?;
    lamp.resize(w * h, false);
    let out_luma = |i: usize| luma([out[3 * i], out[3 * i + 1], out[3 * i + 2]]);
    above_window_mean(
        |i| input[i] as f64,
        (w, h),
        &mut scratch,
        |i, b| lamp[i] = b,
    );
    open(&mut lamp, (w, h));
    // Most images have no lamp: the output's pass is not needed then.
    if !lamp.contains(&true) {
        return Ok(());
    }
    above_window_mean(out_luma, (w, h), &mut scratch, |i, b| lamp[i] &= b);
    if !lamp.contains(&true) {
        return Ok(());
    }
    let (mut deficit, mut own) = (0.0, 0.0);
    near(&lamp, (w, h), LAMP_GROW, &mut scratch, |i| {
        deficit += input[i] as f64 - out_luma(i);
    });
    for (i, _) in lamp.iter().enumerate().filter(|(_, &l)| l) {
        own += out_luma(i);
    }
    let g = (1.0 + deficit / f64::max(own, 1e-30)).clamp(1.0, LAMP_MOST);
    for (p, _) in out.chunks_exact_mut(3).zip(&lamp).filter(|(_, &l)| l) {
        for v in p {
            *v = (*v as f64 * g) as f32;
        }
    }
    Ok(())
}

/// Calls `mark(i, v > LAMP_ABOVE * mean)` for every pixel i, row by row, where v is
/// `value(i)` (as f32, like the spread's row means) and mean its mean over the
/// (2 [`SPREAD_RADIUS`] + 1)^2 window inside the image. `rows` (w * h) is scratch.
fn above_window_mean(
    value: impl Fn(usize) -> f64,
    (w, h): (usize, usize),
    rows: &mut [f32],
    mut mark: impl FnMut(usize, bool),
) {
    let plane = |y: usize, line: &mut [f32]| {
        for (x, v) in line.iter_mut().enumerate() {
            *v = value(y * w + x) as f32;
        }
    };
    window_means(plane, (w, h), SPREAD_RADIUS, rows, |y, line, means| {
        for (x, (&v, m)) in line.iter().zip(means).enumerate() {
            mark(y * w + x, v as f64 > LAMP_ABOVE * m);
        }
    });
}

/// Calls `each(y, line, means)` for every row y in order: `line` the row of a one-channel
/// plane that `fill(y, line)` writes, `means` its (2r + 1)^2 window means inside the
/// image, by the spread's own [`segment_means`] and [`WindowMeans`]. `rows` (w * h) is
/// scratch for the row segments' means.
fn window_means(
    fill: impl Fn(usize, &mut [f32]),
    (w, h): (usize, usize),
    r: usize,
    rows: &mut [f32],
    mut each: impl FnMut(usize, &[f32], ArrayView2<'_, f64>),
) {
    let (mut line, mut prefix) = (vec![0f32; w], vec![[0f64; 1]; w + 1]);
    for (y, dst) in rows.chunks_exact_mut(w).enumerate() {
        fill(y, &mut line);
        segment_means(&line, r, &mut prefix, dst);
    }
    let rows = ArrayView3::from_shape((h, w, 1), &*rows).expect("one mean per pixel");
    let mut means = WindowMeans::new(rows, r);
    for y in 0..h {
        fill(y, &mut line);
        each(y, &line, means.next(rows, y));
    }
}

/// `mask`'s morphological opening by a 2x2 square, in place: the pixels of its 2x2-filled
/// blocks. The erosion (anchored at a block's top left) runs down the rows, each reading
/// only the rows below it; the dilation runs back up, each reading only the rows above it.
fn open(mask: &mut [bool], (w, h): (usize, usize)) {
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            mask[i] = y + 1 < h && x + 1 < w && {
                let (a, b) = (i + w, i + w + 1);
                mask[i] && mask[i + 1] && mask[a] && mask[b]
            };
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let i = y * w + x;
            let up = y > 0 && (mask[i - w] || (x > 0 && mask[i - w - 1]));
            mask[i] = mask[i] || up || (x > 0 && mask[i - 1]);
        }
    }
}

/// Calls `visit(i)` for every pixel i within `r` pixels (a (2r + 1)^2 square) of a pixel of
/// `mask`, row by row. `rows` (w * h) is scratch. A window's mean of the 0/1 mask is
/// positive exactly when it holds a mask pixel: the row means are 0 or f32 values of at
/// least 1 / (2r + 1), which float64 running sums add and take out without rounding, so an
/// empty window sums to exactly 0.
fn near(
    mask: &[bool],
    (w, h): (usize, usize),
    r: usize,
    rows: &mut [f32],
    mut visit: impl FnMut(usize),
) {
    let plane = |y: usize, line: &mut [f32]| {
        for (v, &m) in line.iter_mut().zip(&mask[y * w..(y + 1) * w]) {
            *v = m as u8 as f32;
        }
    };
    window_means(plane, (w, h), r, rows, |y, _, means| {
        for (x, _) in means.iter().enumerate().filter(|(_, &m)| m > 0.0) {
            visit(y * w + x);
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A firefly of the noisy input (one pixel) whose remnant the output kept is no lamp
    /// (the opening drops it): its light goes back over the block, not into the remnant. A
    /// 2x2 lamp beside it is one. Twin of training/tests/test_keep_mean.py's.
    #[test]
    fn a_lone_high_sample_is_not_a_lamp() {
        let w = 40;
        let lamp = |i: usize| (25..27).contains(&(i % w)) && (25..27).contains(&(i / w));
        let firefly = 10 * w + 10;
        let (input, out): (Vec<f32>, Vec<f32>) = (0..w * w)
            .map(|i| match i {
                _ if i == firefly => (400.0, 5.0),
                _ if lamp(i) => (400.0, 300.0),
                _ => (0.1, 0.1),
            })
            .unzip();
        let luma_in: Vec<f32> = input.iter().map(|&v| luma([v; 3]) as f32).collect();
        let mut out: Vec<f32> = out.into_iter().flat_map(|v| [v; 3]).collect();
        restore_lamps(&mut out, &luma_in, (w, w)).unwrap();
        for (i, p) in out.chunks_exact(3).enumerate() {
            match i {
                _ if i == firefly => assert_eq!(p, [5.0; 3]),
                _ if lamp(i) => assert!(p.iter().all(|&v| v > 300.0), "lamp {p:?}"),
                _ => assert_eq!(p, [0.1; 3], "pixel {i}"),
            }
        }
    }

    /// Tiny and thin images have no 2x2 lamp over a dark window and stay as they were; a
    /// lamp in a corner, whose windows the image's edges cut, gets its factor.
    #[test]
    fn tiny_images_and_a_lamp_in_the_corner() {
        for (w, h) in [(1, 1), (1, 7), (7, 1), (2, 2), (3, 5)] {
            let input: Vec<f32> = (0..w * h).map(|i| if i == 0 { 1e4 } else { 0.0 }).collect();
            let mut out: Vec<f32> = input.iter().flat_map(|&v| [0.5 * v; 3]).collect();
            let before = out.clone();
            restore_lamps(&mut out, &input, (w, h)).unwrap();
            assert_eq!(out, before, "{w}x{h}");
        }
        let (w, h) = (33, 20);
        let lamp = |i: usize| i % w < 2 && i / w < 2;
        let input: Vec<f32> = (0..w * h)
            .map(|i| if lamp(i) { 100.0 } else { 0.1 })
            .collect();
        let mut out: Vec<f32> = (0..w * h)
            .flat_map(|i| [if lamp(i) { 80.0f32 } else { 0.1 }; 3])
            .collect();
        let l = luma([1.0; 3]) as f32;
        let luma_in: Vec<f32> = input.iter().map(|&v| v * l).collect();
        restore_lamps(&mut out, &luma_in, (w, h)).unwrap();
        for (i, p) in out.chunks_exact(3).enumerate() {
            let want = if lamp(i) { 100.0 } else { 0.1 };
            assert!(
                p.iter().all(|&v| (v / want - 1.0).abs() < 1e-5),
                "{i}: {p:?}"
            );
        }
    }

    #[test]
    fn the_opening_keeps_blocks_and_drops_lone_pixels() {
        let (w, h) = (6, 5);
        let on = [(1, 1), (1, 2), (2, 1), (2, 2), (2, 3), (4, 4), (0, 5)];
        let mut mask = vec![false; w * h];
        for (y, x) in on {
            mask[y * w + x] = true;
        }
        open(&mut mask, (w, h));
        let kept: Vec<_> = (0..w * h)
            .filter(|&i| mask[i])
            .map(|i| (i / w, i % w))
            .collect();
        assert_eq!(kept, vec![(1, 1), (1, 2), (2, 1), (2, 2)]);
    }

    #[test]
    fn near_visits_the_grown_square_once_each() {
        let (w, h) = (9, 7);
        let mut mask = vec![false; w * h];
        mask[3 * w + 1] = true;
        let mut rows = vec![0.0; w * h];
        let mut seen = Vec::new();
        near(&mask, (w, h), 2, &mut rows, |i| seen.push((i / w, i % w)));
        let want: Vec<_> = (1..6).flat_map(|y| (0..4).map(move |x| (y, x))).collect();
        assert_eq!(seen, want);
    }
}
