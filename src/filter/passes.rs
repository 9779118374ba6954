//! The flip ensemble: a tile run once per orientation of its window, each output turned
//! back and averaged. A kernel-predicting network's residual noise differs between a window
//! and its mirror image, so their mean is cleaner: on the Cycles family, two passes (the
//! window and its half turn) cut the 3-level model's RelMSE by 2-5 %, four by 3.5-5 %
//! (docs/reconstruction.md, "A flip ensemble"). Every orientation keeps the window's shape,
//! so one network plan serves them all; the planes flip in place, so the passes cost no
//! memory beyond one output sum.

use ndarray::Array3;

use crate::engine::PASS_COUNTS;

/// Whether `passes` is one of [`PASS_COUNTS`].
pub fn is_allowed(passes: usize) -> bool {
    PASS_COUNTS.contains(&passes)
}

/// An orientation of the window: rows reversed, columns reversed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Orientation {
    /// Rows reversed (a vertical flip).
    pub rows: bool,
    /// Columns reversed (a horizontal flip).
    pub cols: bool,
}

/// The orientations of `passes` passes, in the order they run. Two passes take the half
/// turn (both flips): it differs from the window in both directions. Four take the
/// orientations in an order where each step flips one axis, one pass over the planes.
pub fn orientations(passes: usize) -> &'static [Orientation] {
    const fn turned(rows: bool, cols: bool) -> Orientation {
        Orientation { rows, cols }
    }
    const ALL: [Orientation; 4] = [
        turned(false, false),
        turned(false, true),
        turned(true, true),
        turned(true, false),
    ];
    const HALF_TURN: [Orientation; 2] = [ALL[0], ALL[2]];
    match passes {
        ..=1 => &ALL[..1],
        2 => &HALF_TURN,
        _ => &ALL,
    }
}

/// Reverses the rows and/or columns of every plane of `a` ([planes, h, w], standard
/// layout, as the network and the reconstruction read it) in place.
pub fn flip(a: &mut Array3<f32>, rows: bool, cols: bool) {
    let (_, h, w) = a.dim();
    if h * w == 0 {
        return;
    }
    let data = a
        .as_slice_mut()
        .expect("packed planes are in standard layout");
    for plane in data.chunks_exact_mut(h * w) {
        if cols {
            plane.chunks_exact_mut(w).for_each(<[f32]>::reverse);
        }
        if rows {
            for y in 0..h / 2 {
                let (top, bottom) = plane.split_at_mut((h - 1 - y) * w);
                top[y * w..(y + 1) * w].swap_with_slice(&mut bottom[..w]);
            }
        }
    }
}

/// Mirrors the unit normal that a feature plane pair holds ((n + 1) / 2 per component):
/// reversed columns negate its x, reversed rows its y, as the training's flips do
/// (temc_train/data.py). "No normal" (0.5) stays.
pub fn mirror_normal(aux: &mut Array3<f32>, first: usize, rows: bool, cols: bool) {
    for (plane, on) in [(first, cols), (first + 1, rows)] {
        if on {
            aux.index_axis_mut(ndarray::Axis(0), plane)
                .mapv_inplace(|v| 1.0 - v);
        }
    }
}

/// Adds `out` ([planes, h, w] as a flat slice, in orientation `o`) to `sum` in the window's
/// own orientation.
pub fn accumulate(sum: &mut [f32], out: &[f32], (h, w): (usize, usize), o: Orientation) {
    let n = h * w;
    for (k, plane) in out.chunks_exact(n).enumerate() {
        for y in 0..h {
            let sy = if o.rows { h - 1 - y } else { y };
            let src = &plane[sy * w..(sy + 1) * w];
            let dst = &mut sum[k * n + y * w..k * n + (y + 1) * w];
            if o.cols {
                dst.iter_mut()
                    .zip(src.iter().rev())
                    .for_each(|(d, s)| *d += s);
            } else {
                dst.iter_mut().zip(src).for_each(|(d, s)| *d += s);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(h: usize, w: usize) -> Array3<f32> {
        Array3::from_shape_fn((2, h, w), |(k, y, x)| (k * 100 + y * 10 + x) as f32)
    }

    /// Flipping the planes and turning the output back returns every value to its pixel,
    /// for each orientation of four passes, walked in order as the tile loop walks them.
    #[test]
    fn each_orientation_turns_back_exactly() {
        let (h, w) = (3, 5);
        let original = ramp(h, w);
        let mut a = original.clone();
        let mut at = Orientation::default();
        for &o in orientations(4) {
            flip(&mut a, at.rows != o.rows, at.cols != o.cols);
            at = o;
            let mut sum = vec![0.0; 2 * h * w];
            accumulate(&mut sum, a.as_slice().unwrap(), (h, w), o);
            assert_eq!(sum, original.as_slice().unwrap(), "{o:?}");
        }
    }

    #[test]
    fn pass_counts() {
        assert_eq!(orientations(1).len(), 1);
        assert_eq!(
            orientations(2)[1],
            Orientation {
                rows: true,
                cols: true
            }
        );
        assert_eq!(orientations(4).len(), 4);
        assert!(is_allowed(2) && !is_allowed(3) && !is_allowed(0));
    }

    #[test]
    fn mirrored_normals_negate_one_axis_and_keep_no_normal() {
        let mut aux = Array3::from_elem((4, 1, 2), 0.5f32);
        aux[[1, 0, 0]] = 1.0; // x = +1
        aux[[2, 0, 0]] = 0.25; // y = -0.5
        mirror_normal(&mut aux, 1, true, true);
        assert_eq!(aux[[1, 0, 0]], 0.0);
        assert_eq!(aux[[2, 0, 0]], 0.75);
        assert_eq!(aux[[1, 0, 1]], 0.5);
        assert_eq!(aux[[0, 0, 0]], 0.5, "other planes untouched");
        assert_eq!(aux[[3, 0, 0]], 0.5, "z untouched");
    }
}
