//! Keep-mean: after every tile is reconstructed, each block of the output is rescaled to
//! the noisy input's mean over that block (docs/keep-mean.md).
//!
//! The reconstruction's weights sum to one per *output* pixel, so nothing bounds how much
//! a bright pixel gives away (a thin bright line spread into its neighbours) or keeps (a firefly
//! the filters drop), and the image's mean drifts. The noisy input's block mean is
//! unbiased; the ratio of the input's and the output's block sums, per channel, clamped and
//! interpolated bilinearly between block centres, restores it without moving detail. It
//! runs on the whole image, so it is the same whatever the tiling or thread count.
//! `training/temc_train/keep_mean.py` is the same function; `tests/data/keep_mean_vectors.json`
//! pins the two together.

/// Block side in pixels of the stage's first pass (docs/keep-mean-measured.md).
pub const BLOCK: usize = 64;
/// The largest factor a block may be scaled by, up or down, in the first pass.
pub const CLAMP: f64 = 4.0;
/// The largest factor of the second pass, over the whole image: what the block clamp left
/// (a dark room the filters darkened tenfold) without letting a nearly black output explode.
pub const GLOBAL_CLAMP: f64 = 16.0;

/// The core's keep-mean stage: [`keep_mean`] over [`BLOCK`]-pixel blocks (energy stays
/// near where it was rendered), then over the whole image (its mean follows the input's
/// within [`GLOBAL_CLAMP`]). `input` is the sanitised noisy radiance, read once: the whole
/// image's sum is the sum of its block sums. `max` is the output ceiling.
pub fn stage(
    out: &mut [f32],
    input: impl Iterator<Item = [f32; 3]>,
    (w, h): (usize, usize),
    max: f32,
) {
    let blocks = block_sums(input, (w, h), BLOCK);
    rescale(out, &blocks, (w, h), BLOCK, CLAMP, max);
    let total = blocks
        .2
        .iter()
        .fold([0f64; 3], |t, b| std::array::from_fn(|k| t[k] + b[k]));
    rescale(
        out,
        &(1, 1, vec![total]),
        (w, h),
        w.max(h),
        GLOBAL_CLAMP,
        max,
    );
}

/// Per-channel sums over `block` x `block` blocks of `w` x `h` interleaved RGB pixels, row by
/// row (edge blocks partial); returns (grid width, grid height, sums).
fn block_sums(
    pixels: impl Iterator<Item = [f32; 3]>,
    (w, h): (usize, usize),
    block: usize,
) -> (usize, usize, Vec<[f64; 3]>) {
    let (gw, gh) = (w.div_ceil(block), h.div_ceil(block));
    let mut sums = vec![[0f64; 3]; gw * gh];
    for (i, p) in pixels.enumerate() {
        let (x, y) = (i % w, i / w);
        let s = &mut sums[(y / block) * gw + x / block];
        for k in 0..3 {
            s[k] += p[k] as f64;
        }
    }
    (gw, gh, sums)
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
/// black), and the result is clamped to [0, `max`].
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
) {
    let block = if block == 0 { w.max(h) } else { block };
    // Every input pixel counts, a capped Inf too: the filters spread its value into its
    // neighbours, so leaving it out of the input's sum would darken its block and the image.
    let sums = block_sums(input, (w, h), block);
    rescale(out, &sums, (w, h), block, clamp, max);
}

/// [`keep_mean`] from the input's block sums `(gw, gh, si)` (of [`block_sums`] at `block`).
fn rescale(
    out: &mut [f32],
    (gw, gh, si): &(usize, usize, Vec<[f64; 3]>),
    (w, h): (usize, usize),
    block: usize,
    clamp: f64,
    max: f32,
) {
    assert!(out.len() == w * h * 3 && w > 0 && h > 0 && clamp >= 1.0);
    let (gw, gh) = (*gw, *gh);
    let pixels = out.chunks_exact(3).map(|p| [p[0], p[1], p[2]]);
    let (_, _, so) = block_sums(pixels, (w, h), block);
    let ratio: Vec<[f64; 3]> = si
        .iter()
        .zip(&so)
        .map(|(i, o)| {
            std::array::from_fn(|k| {
                let r = if o[k] > 0.0 { i[k] / o[k] } else { 1.0 };
                r.clamp(1.0 / clamp, clamp)
            })
        })
        .collect();
    let (xs, ys) = (axis(w, gw, block), axis(h, gh, block));
    for (y, &(y0, y1, fy)) in ys.iter().enumerate() {
        for (x, &(x0, x1, fx)) in xs.iter().enumerate() {
            let at = |gy: usize, gx: usize| &ratio[gy * gw + gx];
            let o = (y * w + x) * 3;
            for k in 0..3 {
                let top = at(y0, x0)[k] * (1.0 - fx) + at(y0, x1)[k] * fx;
                let bottom = at(y1, x0)[k] * (1.0 - fx) + at(y1, x1)[k] * fx;
                let f = top * (1.0 - fy) + bottom * fy;
                out[o + k] = ((out[o + k] as f64 * f) as f32).clamp(0.0, max);
            }
        }
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
        keep_mean(&mut out, input.iter().copied(), (w, h), 16, CLAMP, f32::MAX);
        let flat: Vec<f32> = input.iter().flatten().copied().collect();
        for k in 0..3 {
            let ratio = mean(&out, k) / mean(&flat, k);
            assert!((ratio - 1.0).abs() < 1e-6, "channel {k}: {ratio}");
        }
    }

    #[test]
    fn factors_are_clamped_and_black_blocks_stay_black() {
        let (w, h) = (8, 8);
        // Input bright everywhere; output black in the left half, dim in the right.
        let input = vec![[10.0f32; 3]; w * h];
        let mut out: Vec<f32> = (0..w * h)
            .flat_map(|i| if i % w < 4 { [0.0; 3] } else { [1.0; 3] })
            .collect();
        keep_mean(&mut out, input.into_iter(), (w, h), 4, 2.0, f32::MAX);
        for (i, v) in out.chunks_exact(3).enumerate() {
            // Right blocks want 10x, clamped to 2; the black blocks' factor 1 blends in
            // over the two columns between the block centres.
            let want = match i % w {
                0..4 => 0.0,
                4 => 1.625,
                5 => 1.875,
                _ => 2.0,
            };
            assert!(v.iter().all(|&c| c == want), "pixel {i}: {v:?}");
        }
    }

    #[test]
    fn one_pixel_images_and_limits() {
        let mut out = vec![1.0f32, 0.0, 3.0];
        keep_mean(&mut out, [[3.0, 5.0, 1e9]].into_iter(), (1, 1), 0, 4.0, 1.0);
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
}
