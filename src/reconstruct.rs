//! Reconstruction: per-pixel multi-level kernels, predicted by the network, applied to the
//! noisy linear radiance (docs/reconstruction.md).
//!
//! The network outputs logits; this module turns them into normalised luma and chroma
//! kernels at each pyramid level, filters, composes the levels coarse to fine and
//! recombines luma and chroma. `training/temc_train/reconstruct.py` is the same function
//! in PyTorch; `tests/data/recon_vectors.json` (written by the Python side) pins the two
//! together to 1e-5.
//!
//! One call handles one tile window on one thread (tiles run in parallel elsewhere), so the
//! loops are row-major over contiguous slices, the per-pixel softmax weights of a block of
//! a row live in one reusable buffer, and `exp` is a branch-free polynomial that LLVM
//! vectorises (std `expf` is a libm call per tap and dominated the run time).

use ndarray::{Array2, Array3, ArrayView2, ArrayView3, Zip};

use crate::color::{LINEAR_MAX, LUMA_WEIGHTS};
use crate::Error;

/// Logits are clamped to +-this, NaN becomes 0 (docs/reconstruction.md, "Non-finite logits").
pub const LOGIT_MAX: f32 = 1.0e4;

/// Keeps the recombination's denominator positive where both filters give black.
const MIN_CHROMA_LUMA: f32 = 1.0e-30;

/// The recombination pulls the chroma colour toward grey by this fraction of the luminance,
/// so a chroma result far darker than the luma one (no colour to speak of) becomes grey
/// smoothly and training's gradients stay bounded by its inverse.
const GREY_PULL: f32 = 1.0e-6;

/// The most floats per window pixel that [`reconstruct`] holds besides its inputs and its
/// [3, H, W] output (for memory budgets): while filtering, the demodulated copy 3, the
/// level-0 luminance 1, fy and fc 4, the aux-guided opening's plane 1, the fixed range
/// term's guide 1 and its threshold from local noise 1 (while the opening is made, its
/// links, 6 bytes a pixel, and two planes stand in for fy and fc; while the threshold is
/// made, three): 11; coarser levels add a third of the last at most, after the luminance
/// plane is freed; the per-row weights are k^2 x 128 floats. While composing level 0
/// (multi-level models): fy and fc 4, the composed level 1 one, the three chroma
/// corrections 3, the sigmoid of a blend 1, the correction being made 1 and its coarse
/// detail a quarter, and with `temc.coarse_radius` the local mean it is capped against 1
/// (while that mean is made, it and two planes stand in for the last three): 11.25. With
/// `temc.coarse_sparse` each composed level's rise is kept from filtering to composing, a
/// third of a plane more than level 0's at most: 12.6.
pub const SCRATCH_PLANES: f64 = 12.6;

/// Pixels per row block: the weights of all taps of a block (k^2 x BLOCK) stay in L1/L2.
const BLOCK: usize = 128;

/// The fixed range term (docs/reconstruction.md, "Fixed range term") penalises log2
/// luminance steps beyond this (8x) between a tap and the centre.
pub const RANGE_TAU: f32 = 3.0;

/// Added to the opened luminance, at the exposure that puts the image's log-mean at 0.18,
/// before the log2: noise in the dark never reads as an edge.
pub const RANGE_FLOOR: f32 = 0.02;

/// The window (side, in a level's pixels) over which the fixed range term's threshold from
/// local noise (`temc.range_noise`) averages each pixel's relative deviation from its 3x3
/// median (docs/reconstruction.md, "Range threshold from local noise").
pub const RANGE_NOISE_BOX: usize = 7;

/// The aux-guided opening (docs/reconstruction.md, "Aux-guided opening"): two pixels lie on
/// one surface when the L1 distance of their aux planes is at most this.
pub const AUX_SAME: f32 = 0.3;

/// A pixel with no 3x3 neighbour on its own surface stays a feature of its own only with
/// an emitter's albedo, every channel at least this (temc-render writes 1 for emitters,
/// Blender's Cycles their emission, which the aux encoding clamps to 1).
pub const EMITTER_ALBEDO: f32 = 0.95;

/// With the coarse clamp (`temc.coarse_clamp`), a coarse level's correction may add at
/// most this multiple of the finer level's own value: a firefly a coarse level spreads
/// cannot raise its dark surroundings into a block. A model may name its own
/// (`temc.coarse_gain`, [`Params::coarse_gain`]).
pub const COARSE_GAIN: f32 = 1.0;

/// The largest window radius the coarse clamp may cap against (`temc.coarse_radius`).
pub const COARSE_RADIUS_MAX: usize = 8;

/// With `temc.coarse_sparse` = s the cap rises by max(1, s / max(d, this)), d the share of
/// the window's pixels lit at that level: the floor bounds the rise at s / 0.1.
pub const COARSE_SPARSE_FLOOR: f32 = 0.1;

/// The chroma composition's common cap (step 4): a coarse correction leaves every channel
/// at least this share of its fine value, so it cannot swing a pixel's hue to one primary.
pub const CHROMA_KEEP: f32 = 0.5;

/// Keeps the common cap's ratio finite where a channel has neither value nor correction
/// (the cap is then 1).
pub const CHROMA_EPS: f32 = 1e-12;

/// What the fixed range term opens (`temc.range_opening`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RangeOpening {
    /// Each level's own luminance, 3x3 grey opening (`plain` or absent).
    #[default]
    Plain,
    /// The full-resolution luminance, opened over each pixel's neighbours on its own
    /// surface as the aux planes tell it, and its 2x2 means at coarser levels (`aux`).
    Aux,
}

impl RangeOpening {
    /// The opening a `temc.range_opening` value names: `plain` or `aux`.
    pub fn from_name(name: &str) -> Option<RangeOpening> {
        match name {
            "plain" => Some(RangeOpening::Plain),
            "aux" => Some(RangeOpening::Aux),
            _ => None,
        }
    }
}

/// The aux planes the aux-guided opening reads: the network's, `count` planes of the
/// window's H x W, the albedo's three from plane `albedo` where the layout has one.
#[derive(Clone, Copy, Debug)]
pub struct RangeAux<'a> {
    /// [`count`, H, W] planar.
    pub planes: &'a [f32],
    /// How many planes.
    pub count: usize,
    /// The first of the albedo's three planes, if any.
    pub albedo: Option<usize>,
}

/// The model metadata the reconstruction needs (docs/contracts.md §2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// Pyramid levels L (`temc.levels`), at least 1.
    pub levels: usize,
    /// Kernel size k (`temc.kernel`), odd, the same at every level.
    pub kernel: usize,
    /// Filter `rgb / (albedo + eps)` and multiply back afterwards (`temc.demodulate`).
    pub demodulate: bool,
    /// Added to the albedo before dividing (`temc.demod_eps`), > 0 when demodulating.
    pub eps: f32,
    /// LDR mode: the output is clamped to [0, 1] instead of [0, `LINEAR_MAX`].
    pub ldr: bool,
    /// Each level also holds a luma and a chroma guide (`temc.guide`): tap t's logit gains
    /// the range term -(g(p + t) - g(p))^2 / 2.
    pub guide: bool,
    /// Every logit also gains the fixed range term on the level's opened log2 luminance
    /// (`temc.fixed_range`), which keeps lamps' energy out of their dark neighbours.
    pub fixed_range: bool,
    /// The input scale (exposure) of the image, read only by the fixed range term.
    pub exposure: f32,
    /// What the fixed range term opens (`temc.range_opening`); `Aux` needs the aux planes.
    pub range_opening: RangeOpening,
    /// Each coarse correction is capped at `coarse_gain` times the finer value it is added
    /// to (`temc.coarse_clamp`).
    pub coarse_clamp: bool,
    /// The coarse clamp's gain (`temc.coarse_gain`; [`COARSE_GAIN`] in files without it),
    /// finite and > 0.
    pub coarse_gain: f32,
    /// With the coarse clamp, cap against the mean of the finer values over the
    /// (2 r + 1)^2 window, edges replicated, instead of each pixel's own
    /// (`temc.coarse_radius`; 0 in files without it; at most [`COARSE_RADIUS_MAX`]). A
    /// sparse dark pixel beside lit ones is then filled, a firefly's dark surroundings
    /// stay capped.
    pub coarse_radius: usize,
    /// With the coarse clamp, where fewer than this share of the window's pixels (the
    /// level's input luminance above 0) are lit, the cap rises by `coarse_sparse / d`, at
    /// most `coarse_sparse /` [`COARSE_SPARSE_FLOOR`] (`temc.coarse_sparse`; 0, no rise, in
    /// files without it; in [0, 1]): there the black pixels are holes between samples, not
    /// a firefly's dark surroundings.
    pub coarse_sparse: f32,
    /// How the composition brings a coarse level's correction to the finer one
    /// (`temc.upsample`).
    pub upsample: Upsample,
    /// The fixed range term's threshold from local noise, K (`temc.range_noise`): each
    /// pixel's threshold is min([`RANGE_TAU`], K x its local noise); 0: [`RANGE_TAU`].
    pub range_noise: f32,
}

/// The 2x upsampling U of the level composition (docs/reconstruction.md, step 4).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Upsample {
    /// Each coarse value over its 2x2 block (`temc.upsample` = `nearest` or absent).
    #[default]
    Nearest,
    /// Per axis 3/4 of the nearer coarse value and 1/4 of the next (half-pixel centres,
    /// edges replicated), so no 2x2 steps show in flat regions; each coarse value still
    /// hands on exactly four fine pixels' worth (`temc.upsample` = `bilinear`).
    Bilinear,
}

impl Upsample {
    /// The composition a `temc.upsample` value names: `nearest` or `bilinear`.
    pub fn from_name(name: &str) -> Option<Upsample> {
        match name {
            "nearest" => Some(Upsample::Nearest),
            "bilinear" => Some(Upsample::Bilinear),
            _ => None,
        }
    }
}

/// A bound on how far (in pixels) `levels` levels of `kernel` x `kernel` kernels reach from
/// the centre: r (2^L - 1) + 2^(L-1) - 1 with r = kernel / 2 (the sum over levels), and with
/// bilinear composition one coarsest pixel more, 2^(L-1) - 1 (training's
/// tests/test_reconstruct.py measures both). The tile overlap must cover it.
pub fn reach(levels: usize, kernel: usize, upsample: Upsample) -> usize {
    if levels == 0 {
        return 0;
    }
    let blend = match upsample {
        Upsample::Nearest => 0,
        Upsample::Bilinear => (1usize << (levels - 1)) - 1,
    };
    (kernel / 2) * ((1usize << levels) - 1) + (1usize << (levels - 1)) - 1 + blend
}

/// The logit channels per level for a `kernel` x `kernel` kernel: two kernels, two blends,
/// and with `guide` two guides.
pub fn channels(kernel: usize, guide: bool) -> usize {
    2 * kernel * kernel + if guide { 4 } else { 2 }
}

/// Applies the predicted filters to one H x W window; returns the [3, H, W] planar result.
///
/// `rgb` and `albedo` are [3, H, W] planar (albedo is read only when demodulating); `aux`
/// is read only by the fixed range term's aux-guided opening (and required by it);
/// `filters[l]` is [`channels`(k, guide), H / 2^l, W / 2^l] planar. Every output value is finite and in
/// [0, `LINEAR_MAX`] (LDR: [0, 1]), whatever the logits hold.
///
/// # Panics
/// If `filters` is empty (a model has at least one level) or a slice is shorter than its
/// shape above.
pub fn reconstruct(
    p: &Params,
    rgb: &[f32],
    albedo: Option<&[f32]>,
    aux: Option<RangeAux<'_>>,
    filters: &[&[f32]],
    h: usize,
    w: usize,
) -> Result<Vec<f32>, Error> {
    validate(p, rgb, albedo, filters, h, w)?;
    let aux = validate_aux(p, aux, h * w)?;
    let hw = h * w;
    // d = albedo + eps is recomputed in `recombine` rather than kept: 3 planes less.
    let d = albedo.filter(|_| p.demodulate).map(|a| (a, p.eps));
    let mut x = rgb.to_vec();
    if let Some((a, eps)) = d {
        x.iter_mut().zip(a).for_each(|(v, a)| *v /= a + eps);
    }
    let mut scratch = Scratch::new(p.kernel, w);
    let mut opened = aux.map(|a| aux_opened(&luminance(&x, hw), a, h, w));
    let (mut hl, mut wl) = (h, w);
    let mut outs = Vec::with_capacity(p.levels);
    let mut rises = Vec::with_capacity(p.levels);
    for (l, f) in filters.iter().enumerate() {
        if l > 0 {
            x = downsample(&x, 3, hl, wl);
            opened = opened.map(|o| downsample(&o, 1, hl, wl));
            (hl, wl) = (hl / 2, wl / 2);
        }
        let composed = l + 1 < p.levels && p.coarse_clamp && p.coarse_sparse > 0.0;
        rises.push(composed.then(|| sparse_rise(&x, hl, wl, p.coarse_radius, p.coarse_sparse)));
        let level = Level {
            x: &x,
            f,
            opened: opened.as_deref(),
            h: hl,
            w: wl,
        };
        outs.push(filter_level(&level, p, &mut scratch));
    }
    let (mut cy, mut cc) = outs.pop().expect("levels >= 1");
    let k2 = p.kernel * p.kernel;
    for (l, (mut fy, mut fc)) in outs.into_iter().enumerate().rev() {
        let (hl, wl) = (h >> l, w >> l);
        let n = hl * wl;
        let f = filters[l];
        let rise = rises[l].take();
        let how = (
            p.upsample,
            p.coarse_clamp.then_some(Cap {
                gain: p.coarse_gain,
                radius: p.coarse_radius,
                rise: rise.as_deref(),
            }),
        );
        let dy = correction(&fy, &cy, &f[2 * k2 * n..][..n], hl, wl, how);
        fy.iter_mut().zip(&dy).for_each(|(v, d)| *v += d);
        let dc: Vec<Vec<f32>> = (0..3)
            .map(|c| {
                let (fine, coarse) = (&fc[c * n..][..n], &cc[c * n / 4..][..n / 4]);
                correction(fine, coarse, &f[(2 * k2 + 1) * n..][..n], hl, wl, how)
            })
            .collect();
        add_chroma_correction(&mut fc, &dc, n);
        (cy, cc) = (fy, fc);
    }
    Ok(recombine(&cy, &cc, d, hw, p.ldr))
}

/// Rejects every input the loops would index out of bounds or divide by zero with.
fn validate(
    p: &Params,
    rgb: &[f32],
    albedo: Option<&[f32]>,
    filters: &[&[f32]],
    h: usize,
    w: usize,
) -> Result<(), Error> {
    let bad = |m: String| Err(Error::InvalidArgument(format!("reconstruct: {m}")));
    if p.levels == 0 || p.levels > 16 {
        return bad(format!("levels must be in 1..=16, got {}", p.levels));
    }
    if p.kernel.is_multiple_of(2) || p.kernel > 63 {
        return bad(format!(
            "kernel must be odd and at most 63, got {}",
            p.kernel
        ));
    }
    let align = 1usize << (p.levels - 1);
    if h == 0 || w == 0 || !h.is_multiple_of(align) || !w.is_multiple_of(align) {
        return bad(format!("{w}x{h} is not a non-empty multiple of {align}"));
    }
    let hw = h
        .checked_mul(w)
        .filter(|n| n.checked_mul(channels(p.kernel, p.guide)).is_some());
    let Some(hw) = hw else {
        return bad(format!("{w}x{h} is too large"));
    };
    if rgb.len() != 3 * hw {
        return bad(format!("rgb has {} values, expected {}", rgb.len(), 3 * hw));
    }
    if p.demodulate {
        if !(p.eps.is_finite() && p.eps > 0.0) {
            return bad(format!("eps must be finite and > 0, got {}", p.eps));
        }
        match albedo {
            Some(a) if a.len() == 3 * hw => {}
            Some(a) => {
                return bad(format!(
                    "albedo has {} values, expected {}",
                    a.len(),
                    3 * hw
                ))
            }
            None => return bad("demodulation needs an albedo".into()),
        }
    }
    let gain_ok = p.coarse_gain.is_finite() && p.coarse_gain > 0.0;
    if p.coarse_clamp && !(gain_ok && p.coarse_radius <= COARSE_RADIUS_MAX) {
        return bad(format!(
            "coarse_gain must be finite and > 0 and coarse_radius at most {COARSE_RADIUS_MAX}, \
             got {} and {}",
            p.coarse_gain, p.coarse_radius
        ));
    }
    if p.coarse_clamp && !(0.0..=1.0).contains(&p.coarse_sparse) {
        return bad(format!(
            "coarse_sparse must be in [0, 1], got {}",
            p.coarse_sparse
        ));
    }
    if filters.len() != p.levels {
        return bad(format!(
            "{} filter levels, expected {}",
            filters.len(),
            p.levels
        ));
    }
    for (l, f) in filters.iter().enumerate() {
        let want = channels(p.kernel, p.guide) * (h >> l) * (w >> l);
        if f.len() != want {
            return bad(format!(
                "filters[{l}] has {} values, expected {want}",
                f.len()
            ));
        }
    }
    Ok(())
}

/// The aux planes the reconstruction reads: Some only where the fixed range term opens
/// with them; an error where it would but they are missing or short.
fn validate_aux<'a>(
    p: &Params,
    aux: Option<RangeAux<'a>>,
    hw: usize,
) -> Result<Option<RangeAux<'a>>, Error> {
    if !(p.fixed_range && p.range_opening == RangeOpening::Aux) {
        return Ok(None);
    }
    let bad = |m: String| Err(Error::InvalidArgument(format!("reconstruct: {m}")));
    let Some(a) = aux else {
        return bad("the aux-guided opening needs the aux planes".into());
    };
    if a.planes.len() != a.count * hw || a.albedo.is_some_and(|i| i + 3 > a.count) {
        return bad(format!(
            "aux has {} values in {} planes (albedo at {:?}), expected {} a plane",
            a.planes.len(),
            a.count,
            a.albedo,
            hw
        ));
    }
    Ok(Some(a))
}

/// The luminance plane of `n` planar RGB pixels.
fn luminance(x: &[f32], n: usize) -> Vec<f32> {
    let (r, gb) = x.split_at(n);
    let (g, b) = gb.split_at(n);
    r.iter()
        .zip(g)
        .zip(&b[..n])
        .map(|((r, g), b)| LUMA_WEIGHTS[0] * r + LUMA_WEIGHTS[1] * g + LUMA_WEIGHTS[2] * b)
        .collect()
}

/// The 3x3 grey opening of `luma` over each pixel's neighbours on its own surface: aux
/// planes within [`AUX_SAME`] (L1). A small lamp the aux buffers outline keeps its value,
/// a firefly on a surface drops to that surface's. A pixel with no neighbour on its surface
/// (a texel, a silhouette's tip) is linked to all its neighbours, and they to it, unless
/// its albedo is an emitter's ([`EMITTER_ALBEDO`]). Erosion and dilation over one symmetric
/// relation: an opening (idempotent, never above `luma`).
fn aux_opened(luma: &[f32], aux: RangeAux<'_>, h: usize, w: usize) -> Vec<f32> {
    let links = Links::new(aux, h, w);
    let eroded = links.window(luma, |a, b| if b < a { b } else { a });
    links.window(&eroded, |a, b| if b > a { b } else { a })
}

/// The four forward neighbours (dy, dx) of a pixel; each link is stored once, at the pixel
/// before it, and read from both ends (the relation is symmetric).
const FORWARD: [(usize, isize); 4] = [(0, 1), (1, -1), (1, 0), (1, 1)];

/// Which 3x3 neighbours the aux-guided opening links, per pixel and forward neighbour.
struct Links {
    h: usize,
    w: usize,
    /// `FORWARD[k]`'s link of pixel i at `k * n + i`; false where the neighbour is outside.
    fwd: Vec<bool>,
}

impl Links {
    /// Row by row, so the rows read stay in cache: the aux distance to each forward
    /// neighbour over all planes (vectorisable), then the loose pixels' links added.
    fn new(aux: RangeAux<'_>, h: usize, w: usize) -> Links {
        let n = h * w;
        let mut fwd = vec![false; 4 * n];
        let mut count = vec![0u8; n];
        let mut dist = vec![0.0f32; w];
        for y in 0..h {
            for (k, &off) in FORWARD.iter().enumerate() {
                let Some((i, q, len)) = row_span(h, w, y, off) else {
                    continue;
                };
                let d = &mut dist[..len];
                d.fill(0.0);
                for plane in aux.planes.chunks_exact(n).take(aux.count) {
                    for ((d, a), b) in d.iter_mut().zip(&plane[i..][..len]).zip(&plane[q..][..len])
                    {
                        *d += (b - a).abs();
                    }
                }
                for (j, &d) in d.iter().enumerate() {
                    let linked = d <= AUX_SAME;
                    fwd[k * n + i + j] = linked;
                    count[i + j] += linked as u8;
                    count[q + j] += linked as u8;
                }
            }
        }
        let loose: Vec<bool> = (0..n)
            .map(|i| count[i] == 0 && !is_emitter(aux, i, n))
            .collect();
        for y in 0..h {
            for (k, &off) in FORWARD.iter().enumerate() {
                if let Some((i, q, len)) = row_span(h, w, y, off) {
                    for j in 0..len {
                        fwd[k * n + i + j] |= loose[i + j] || loose[q + j];
                    }
                }
            }
        }
        Links { h, w, fwd }
    }

    /// `op` (min or max) of each pixel and its linked neighbours in `x`: row by row, per
    /// forward neighbour one pass for the pixel and one for the neighbour (branch-free;
    /// `op` a compare-and-select, which vectorises where f32::min does not: the values
    /// are finite).
    fn window(&self, x: &[f32], op: impl Fn(f32, f32) -> f32 + Copy) -> Vec<f32> {
        let n = self.h * self.w;
        let mut out = x.to_vec();
        for y in 0..self.h {
            for (k, &off) in FORWARD.iter().enumerate() {
                let Some((i, q, len)) = row_span(self.h, self.w, y, off) else {
                    continue;
                };
                let f = &self.fwd[k * n + i..][..len];
                let o = &mut out[i..][..len];
                for ((o, &v), &l) in o.iter_mut().zip(&x[q..][..len]).zip(f) {
                    *o = if l { op(*o, v) } else { *o };
                }
                let o = &mut out[q..][..len];
                for ((o, &v), &l) in o.iter_mut().zip(&x[i..][..len]).zip(f) {
                    *o = if l { op(*o, v) } else { *o };
                }
            }
        }
        out
    }
}

/// Row `y`'s span (first pixel, its neighbour at `(dy, dx)`, length) of the pixels of an
/// `h` x `w` image whose neighbour there lies inside, if any; dy >= 0.
fn row_span(
    h: usize,
    w: usize,
    y: usize,
    (dy, dx): (usize, isize),
) -> Option<(usize, usize, usize)> {
    let len = w.saturating_sub(dx.unsigned_abs());
    (y + dy < h && len > 0).then(|| {
        let i = y * w + dx.min(0).unsigned_abs();
        (i, (i + dy * w).wrapping_add_signed(dx), len)
    })
}

/// Whether pixel `i` (of `n`) has an emitter's albedo: every albedo channel at least
/// [`EMITTER_ALBEDO`]; never without albedo planes.
fn is_emitter(aux: RangeAux<'_>, i: usize, n: usize) -> bool {
    aux.albedo
        .is_some_and(|a| (a..a + 3).all(|c| aux.planes[c * n + i] >= EMITTER_ALBEDO))
}

/// The 2x2 mean of each of `planes` planes of `h` x `w` (D of the spec; keeps the mean).
fn downsample(x: &[f32], planes: usize, h: usize, w: usize) -> Vec<f32> {
    let x = ArrayView3::from_shape((planes, h, w), x).expect("planes of h x w");
    let mut out = Array3::zeros((planes, h / 2, w / 2));
    Zip::from(&mut out)
        .and(x.exact_chunks((1, 2, 2)))
        .for_each(|o, q| {
            *o = 0.25 * ((q[[0, 0, 0]] + q[[0, 0, 1]]) + (q[[0, 1, 0]] + q[[0, 1, 1]]))
        });
    out.into_raw_vec_and_offset().0
}

/// The fixed range term's guide of one level: log2(opened luminance x `exposure` +
/// RANGE_FLOOR), where the 3x3 grey opening (min, then max, over the pixels inside) drops
/// bright features smaller than 3x3 (fireflies, which must still spread) to their
/// surroundings and keeps larger ones (lamps) with exact edges; `opened`, where given, is
/// the aux-guided opening's plane for this level instead. Non-finite values cannot occur:
/// the luminance is finite and non-negative (sanitised radiance).
fn range_guide(
    luma: &[f32],
    opened: Option<&[f32]>,
    h: usize,
    w: usize,
    exposure: f32,
) -> Vec<f32> {
    let guide = |o: &[f32]| {
        o.iter()
            .map(|v| (v.max(0.0) * exposure + RANGE_FLOOR).log2())
            .collect()
    };
    match opened {
        Some(o) => guide(o),
        None => guide(&window3(&window3(luma, h, w, f32::min), h, w, f32::max)),
    }
}

/// `op` (min or max: exact, so the order does not matter) over each pixel's 3x3 window,
/// clipped to the image: along rows, then along columns, three reads a pixel each way.
fn window3(x: &[f32], h: usize, w: usize, op: impl Fn(f32, f32) -> f32 + Copy) -> Vec<f32> {
    let mut rows = vec![0.0; h * w];
    for (src, dst) in x.chunks_exact(w).zip(rows.chunks_exact_mut(w)) {
        for (i, o) in dst.iter_mut().enumerate() {
            *o = op(
                op(src[i.saturating_sub(1)], src[i]),
                src[(i + 1).min(w - 1)],
            );
        }
    }
    let mut out = vec![0.0; h * w];
    for (y, dst) in out.chunks_exact_mut(w).enumerate() {
        let row = |r: usize| &rows[r * w..][..w];
        let (up, mid, down) = (row(y.saturating_sub(1)), row(y), row((y + 1).min(h - 1)));
        for (((o, &a), &b), &c) in dst.iter_mut().zip(up).zip(mid).zip(down) {
            *o = op(op(a, b), c);
        }
    }
    out
}

/// The fixed range term's threshold in stops per pixel from local noise (`temc.range_noise`
/// = `k` > 0): min([`RANGE_TAU`], k x n), n the [`RANGE_NOISE_BOX`]^2 mean (edges
/// replicated) of the relative deviation |Y - median3(Y)| / (median3(Y) + [`RANGE_FLOOR`]),
/// Y the level's luminance at the image's exposure. Where the image is clean (n near 0) a
/// step of one stop, a shadow's edge, already counts; where it is noisy the threshold stays
/// [`RANGE_TAU`], so noise never reads as an edge. The same function as
/// `range_threshold` in training/temc_train/reconstruct.py.
fn range_threshold(luma: &[f32], h: usize, w: usize, exposure: f32, k: f32) -> Vec<f32> {
    let v: Vec<f32> = luma.iter().map(|y| y.max(0.0) * exposure).collect();
    let mut rel = vec![0.0; h * w];
    for (y, row) in rel.chunks_exact_mut(w).enumerate() {
        let rows = [y.saturating_sub(1), y, (y + 1).min(h - 1)].map(|r| &v[r * w..][..w]);
        for (x, o) in row.iter_mut().enumerate() {
            let cols = [x.saturating_sub(1), x, (x + 1).min(w - 1)];
            let mut taps = [0.0; 9];
            for (i, t) in taps.iter_mut().enumerate() {
                *t = rows[i / 3][cols[i % 3]];
            }
            let m = median9(taps);
            *o = (rows[1][x] - m).abs() / (m + RANGE_FLOOR);
        }
    }
    box_mean(&rel, h, w, RANGE_NOISE_BOX)
        .into_iter()
        .map(|n| (k * n).min(RANGE_TAU))
        .collect()
}

/// The median of nine values (all finite here): sorted, the middle one.
fn median9(mut v: [f32; 9]) -> f32 {
    v.sort_unstable_by(f32::total_cmp);
    v[4]
}

/// The mean over each pixel's `side` x `side` window, coordinates clamped to the image
/// (edges replicated, as PyTorch's replicate padding): along rows, then along columns.
/// Whole shifted rows are added tap by tap (a row padded by its edge values first), so the
/// loops vectorise; each sum still runs over its taps in order.
fn box_mean(x: &[f32], h: usize, w: usize, side: usize) -> Vec<f32> {
    let r = side / 2;
    let add = |acc: &mut [f32], src: &[f32]| acc.iter_mut().zip(src).for_each(|(a, v)| *a += v);
    let mut rows = vec![0.0; h * w];
    let mut padded = vec![0.0; w + 2 * r];
    for (src, dst) in x.chunks_exact(w).zip(rows.chunks_exact_mut(w)) {
        for (j, p) in padded.iter_mut().enumerate() {
            *p = src[j.saturating_sub(r).min(w - 1)];
        }
        (0..side).for_each(|d| add(dst, &padded[d..d + w]));
    }
    let mut out = vec![0.0; h * w];
    let scale = 1.0 / (side * side) as f32;
    for (y, dst) in out.chunks_exact_mut(w).enumerate() {
        for d in 0..side {
            add(dst, &rows[(y + d).saturating_sub(r).min(h - 1) * w..][..w]);
        }
        dst.iter_mut().for_each(|o| *o *= scale);
    }
    out
}

/// max(0, |tap - centre| - tau)^2 / 2 into `pen`, pixel by pixel (the fixed range term's
/// penalty; `taus` per centre pixel, or RANGE_TAU repeated: one loop, monomorphised twice).
#[inline(always)]
fn penalties(pen: &mut [f32], taps: &[f32], centres: &[f32], taus: impl Iterator<Item = f32>) {
    for (((p, &a), &c), tau) in pen.iter_mut().zip(taps).zip(centres).zip(taus) {
        let e = ((a - c).abs() - tau).max(0.0);
        *p = 0.5 * e * e;
    }
}

/// Reusable per-call buffers: the weights of every tap for one block of one row.
struct Scratch {
    k: usize,
    /// Tap-major: tap t's weights for the block at `t * BLOCK`.
    weights: Vec<f32>,
    /// Per pixel of the block: the max logit over the taps inside.
    max: Vec<f32>,
    /// Per pixel of the block: 1 / the sum of the weights.
    norm: Vec<f32>,
    /// Per pixel of the block: the weighted sum being accumulated.
    acc: Vec<f32>,
    /// Tap-major like `weights`: the fixed range term's penalty of each tap for the
    /// block, computed once and subtracted from the luma and the chroma logits alike.
    fixed: Vec<f32>,
}

impl Scratch {
    fn new(k: usize, w: usize) -> Self {
        let b = BLOCK.min(w);
        Scratch {
            k,
            weights: vec![0.0; k * k * BLOCK],
            max: vec![0.0; b],
            norm: vec![0.0; b],
            acc: vec![0.0; b],
            fixed: vec![0.0; k * k * BLOCK],
        }
    }
}

/// Tap t = (dy + r) k + (dx + r) of the spec as its offset (dy, dx).
#[inline(always)]
fn tap(k: usize, t: usize) -> (isize, isize) {
    let r = (k / 2) as isize;
    ((t / k) as isize - r, (t % k) as isize - r)
}

/// The pixel columns `[x0, x1)` of block `[bx0, bx1)` where tap (dy, dx) lies inside the
/// `h` x `w` image at row `y`; None when the tap's row is outside or the span is empty.
#[inline(always)]
fn span(
    y: usize,
    dy: isize,
    dx: isize,
    h: usize,
    w: usize,
    bx: (usize, usize),
) -> Option<(usize, usize)> {
    let yy = y as isize + dy;
    if yy < 0 || yy >= h as isize {
        return None;
    }
    let x0 = (bx.0 as isize).max(-dx);
    let x1 = (bx.1 as isize).min(w as isize - dx);
    (x0 < x1).then_some((x0 as usize, x1 as usize))
}

/// One pyramid level's inputs to [`filter_level`].
struct Level<'a> {
    /// The level's radiance [3, H, W].
    x: &'a [f32],
    /// The network's logits for the level.
    f: &'a [f32],
    /// The opened luminance the fixed range term reads, where aux is given.
    opened: Option<&'a [f32]>,
    h: usize,
    w: usize,
}

/// Filters one level: per pixel, the luma kernel on the level's luminance and the chroma
/// kernel on its three channels. Returns (fy [H, W], fc [3, H, W]). Runs the widest build
/// the CPU has (AVX-512, AVX2, else the baseline SSE2 one); all give the same bits.
fn filter_level(lv: &Level, p: &Params, s: &mut Scratch) -> (Vec<f32>, Vec<f32>) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx512f") {
        // SAFETY: the CPU has AVX-512F. No FMA: bit-identical to the baseline's results.
        return unsafe { filter_level_avx512(lv, p, s) };
    }
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2. No FMA: the results are bit-identical to the baseline's.
        return unsafe { filter_level_avx2(lv, p, s) };
    }
    filter_level_any(lv, p, s)
}

/// Declares `$name`: [`filter_level_any`] compiled with the target features `$features`.
macro_rules! filter_level_for {
    ($(#[$doc:meta])* $name:ident, $features:literal) => {
        $(#[$doc])*
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $features)]
        fn $name(lv: &Level, p: &Params, s: &mut Scratch) -> (Vec<f32>, Vec<f32>) {
            filter_level_any(lv, p, s)
        }
    };
}

filter_level_for!(
    /// [`filter_level_any`] compiled for AVX-512: 16 lanes (0.83x AVX2's time at 1080p).
    filter_level_avx512,
    "avx512f"
);
filter_level_for!(
    /// [`filter_level_any`] compiled for AVX2: 8 lanes instead of SSE2's 4 (about 2x faster).
    filter_level_avx2,
    "avx2"
);

/// The body of [`filter_level`], inlined into each instruction-set version.
#[inline(always)]
fn filter_level_any(lv: &Level, p: &Params, s: &mut Scratch) -> (Vec<f32>, Vec<f32>) {
    let &Level { x, f, opened, h, w } = lv;
    let n = h * w;
    let k2 = p.kernel * p.kernel;
    let guide = |c: usize| p.guide.then(|| &f[(2 * k2 + 2 + c) * n..][..n]);
    let luma = luminance(x, n);
    let fixed = p
        .fixed_range
        .then(|| range_guide(&luma, opened, h, w, p.exposure));
    let tau = (p.fixed_range && p.range_noise > 0.0)
        .then(|| range_threshold(&luma, h, w, p.exposure, p.range_noise));
    let mut fy = vec![0.0; n];
    let mut fc = vec![0.0; 3 * n];
    for y in 0..h {
        for bx0 in (0..w).step_by(BLOCK) {
            let bx = (bx0, (bx0 + BLOCK).min(w));
            let at = y * w + bx0..y * w + bx.1;
            if let Some(g) = &fixed {
                s.fixed_terms(g, tau.as_deref(), y, (h, w), bx);
            }
            let with_fixed = fixed.is_some();
            s.weights_for(&f[..k2 * n], guide(0), with_fixed, y, h, w, bx);
            s.apply(&luma, y, h, w, bx, &mut fy[at.clone()]);
            let chroma = &f[k2 * n..2 * k2 * n];
            s.weights_for(chroma, guide(1), with_fixed, y, h, w, bx);
            for c in 0..3 {
                let plane = &x[c * n..][..n];
                s.apply(plane, y, h, w, bx, &mut fc[c * n..][at.clone()]);
            }
        }
    }
    (fy, fc)
}

impl Scratch {
    /// The fixed range term's penalty max(0, |g(tap) - g(centre)| - tau(centre))^2 / 2 of
    /// every tap inside the image for row `y`, block `bx`, from its guide plane
    /// ([`range_guide`]) and its threshold plane ([`range_threshold`]; `None`: RANGE_TAU
    /// everywhere), into `fixed`.
    #[inline(always)]
    fn fixed_terms(
        &mut self,
        g: &[f32],
        tau: Option<&[f32]>,
        y: usize,
        (h, w): (usize, usize),
        bx: (usize, usize),
    ) {
        for t in 0..self.k * self.k {
            let (dy, dx) = tap(self.k, t);
            let Some((x0, x1)) = span(y, dy, dx, h, w, bx) else {
                continue;
            };
            let row = (y as isize + dy) as usize * w;
            let gt = &g[row + (x0 as isize + dx) as usize..][..x1 - x0];
            let gc = &g[y * w + x0..][..x1 - x0];
            let pen = &mut self.fixed[t * BLOCK..][x0 - bx.0..x1 - bx.0];
            match tau {
                None => penalties(pen, gt, gc, std::iter::repeat(RANGE_TAU)),
                Some(tau) => penalties(pen, gt, gc, tau[y * w + x0..][..x1 - x0].iter().copied()),
            }
        }
    }

    /// The softmax weights (unnormalised, with 1 / sum in `norm`) of row `y`, block `bx`,
    /// over the taps inside the image; `apply` reads only those. With a learned `guide`
    /// plane each logit gains the range term -(g(tap) - g(centre))^2 / 2 (guides cleaned
    /// like logits); `with_fixed` then subtracts the penalties [`Scratch::fixed_terms`] left.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)] // the block's coordinates, as `apply` takes them
    fn weights_for(
        &mut self,
        logits: &[f32],
        guide: Option<&[f32]>,
        with_fixed: bool,
        y: usize,
        h: usize,
        w: usize,
        bx: (usize, usize),
    ) {
        let nb = bx.1 - bx.0;
        let plane = h * w;
        let max = &mut self.max[..nb];
        max.fill(f32::NEG_INFINITY);
        for t in 0..self.k * self.k {
            let (dy, dx) = tap(self.k, t);
            let Some((x0, x1)) = span(y, dy, dx, h, w, bx) else {
                continue;
            };
            let wt = &mut self.weights[t * BLOCK..][x0 - bx.0..x1 - bx.0];
            let src = &logits[t * plane + y * w..][x0..x1];
            for (o, &v) in wt.iter_mut().zip(src) {
                *o = clean_logit(v);
            }
            if let Some(g) = guide {
                let row = (y as isize + dy) as usize * w;
                let gt = &g[row + (x0 as isize + dx) as usize..][..x1 - x0];
                let gc = &g[y * w + x0..][..x1 - x0];
                for ((o, &a), &c) in wt.iter_mut().zip(gt).zip(gc) {
                    let d = clean_logit(a) - clean_logit(c);
                    *o -= 0.5 * d * d;
                }
            }
            if with_fixed {
                let pen = &self.fixed[t * BLOCK..][x0 - bx.0..x1 - bx.0];
                wt.iter_mut().zip(pen).for_each(|(o, p)| *o -= p);
            }
            for (&v, m) in wt.iter().zip(&mut max[x0 - bx.0..x1 - bx.0]) {
                *m = if v > *m { v } else { *m };
            }
        }
        let norm = &mut self.norm[..nb];
        norm.fill(0.0);
        for t in 0..self.k * self.k {
            let (dy, dx) = tap(self.k, t);
            let Some((x0, x1)) = span(y, dy, dx, h, w, bx) else {
                continue;
            };
            let r = x0 - bx.0..x1 - bx.0;
            let wt = &mut self.weights[t * BLOCK..][r.clone()];
            for ((o, m), s) in wt.iter_mut().zip(&max[r.clone()]).zip(&mut norm[r]) {
                *o = exp_nonpos(*o - m);
                *s += *o;
            }
        }
        // The max tap has weight exp(0) = 1 and the centre tap is always inside: sum >= 1.
        norm.iter_mut().for_each(|s| *s = 1.0 / *s);
    }

    /// `out[x] = sum_t weight_t[x] * plane(y + dy, x + dx)`, normalised, for the block.
    #[inline(always)]
    fn apply(
        &mut self,
        plane: &[f32],
        y: usize,
        h: usize,
        w: usize,
        bx: (usize, usize),
        out: &mut [f32],
    ) {
        let acc = &mut self.acc[..bx.1 - bx.0];
        acc.fill(0.0);
        for t in 0..self.k * self.k {
            let (dy, dx) = tap(self.k, t);
            let Some((x0, x1)) = span(y, dy, dx, h, w, bx) else {
                continue;
            };
            let row = (y as isize + dy) as usize * w;
            let src = &plane[row + (x0 as isize + dx) as usize..][..x1 - x0];
            let wt = &self.weights[t * BLOCK..][x0 - bx.0..x1 - bx.0];
            for ((a, &wv), &v) in acc[x0 - bx.0..x1 - bx.0].iter_mut().zip(wt).zip(src) {
                *a += wv * v;
            }
        }
        for ((o, a), s) in out.iter_mut().zip(acc.iter()).zip(&self.norm) {
            *o = a * s;
        }
    }
}

/// `fc += share * dc` per pixel, `share` in [0, 1] the largest (all three channels alike)
/// that leaves every channel at least [`CHROMA_KEEP`] of its value (step 4 of the spec).
/// Clamping each channel after the composition instead turned a warm pixel whose
/// correction drove red and green negative into pure blue.
fn add_chroma_correction(fc: &mut [f32], dc: &[Vec<f32>], n: usize) {
    let (r, rest) = fc.split_at_mut(n);
    let (g, b) = rest.split_at_mut(n);
    for (i, ((r, g), b)) in r.iter_mut().zip(g).zip(b.iter_mut()).enumerate() {
        let room_share = |f: f32, d: f32| {
            let (room, need) = ((1.0 - CHROMA_KEEP) * f.max(0.0), (-d).max(0.0));
            (room + CHROMA_EPS) / (need.max(room) + CHROMA_EPS)
        };
        let (dr, dg, db) = (dc[0][i], dc[1][i], dc[2][i]);
        let share = room_share(*r, dr)
            .min(room_share(*g, dg))
            .min(room_share(*b, db));
        *r += dr * share;
        *g += dg * share;
        *b += db * share;
    }
}

/// The coarse clamp at one level: a correction adds at most `gain` times the fine value
/// (radius 0) or its (2 radius + 1)^2 mean, times `rise` per pixel where given.
#[derive(Clone, Copy)]
struct Cap<'a> {
    gain: f32,
    radius: usize,
    rise: Option<&'a [f32]>,
}

/// The coarse cap's rise at one level (`temc.coarse_sparse` = `share`):
/// max(1, share / max(d, [`COARSE_SPARSE_FLOOR`])), d the share of the (2 radius + 1)^2
/// window's pixels (edges replicated) whose luminance in `x` [3, H, W] is above 0.
fn sparse_rise(x: &[f32], h: usize, w: usize, radius: usize, share: f32) -> Vec<f32> {
    let mut lit = luminance(x, h * w);
    lit.iter_mut()
        .for_each(|y| *y = if *y > 0.0 { 1.0 } else { 0.0 });
    let mut d = box_mean(&lit, h, w, 2 * radius + 1);
    d.iter_mut()
        .for_each(|v| *v = (share / v.max(COARSE_SPARSE_FLOOR)).max(1.0));
    d
}

/// What a coarse correction may add at each fine pixel ([`Cap`]): `gain` times the fine
/// value clamped at 0, or its (2 radius + 1)^2 mean, times the rise where given (in that
/// order, as PyTorch's `_cap`).
fn cap_plane(fine: &[f32], h: usize, w: usize, cap: Cap<'_>) -> Vec<f32> {
    let mut l: Vec<f32> = fine.iter().map(|v| v.max(0.0)).collect();
    if cap.radius > 0 {
        l = box_mean(&l, h, w, 2 * cap.radius + 1);
    }
    l.iter_mut().for_each(|v| *v *= cap.gain);
    if let Some(rise) = cap.rise {
        l.iter_mut().zip(rise).for_each(|(v, r)| *v *= r);
    }
    l
}

/// `sigmoid(blend) * U(coarse - D(fine))` per fine pixel, each capped by the coarse clamp
/// where given ([`Cap`]): what step 4 of the spec adds to `fine`.
fn correction(
    fine: &[f32],
    coarse: &[f32],
    blend: &[f32],
    h: usize,
    w: usize,
    (up, clamp): (Upsample, Option<Cap<'_>>),
) -> Vec<f32> {
    let limit = clamp.map(|c| cap_plane(fine, h, w, c));
    let cap = |i: usize, c: f32| limit.as_ref().map_or(c, |l| c.min(l[i]));
    let mut detail = Array2::from_shape_vec((h / 2, w / 2), downsample(fine, 1, h, w))
        .expect("one coarse plane");
    let coarse = ArrayView2::from_shape(detail.dim(), coarse).expect("a coarse plane");
    Zip::from(&mut detail)
        .and(coarse)
        .for_each(|d, &c| *d = c - *d);
    let blend: Vec<f32> = blend.iter().map(|&b| sigmoid(b)).collect(); // one vectorised pass
    let blend = ArrayView2::from_shape((h, w), &blend).expect("a blend per fine pixel");
    let mut out = Array2::<f32>::zeros((h, w));
    match up {
        Upsample::Nearest => Zip::indexed(&mut out)
            .and(blend)
            .for_each(|(y, x), o, &b| *o = b * cap(y * w + x, detail[[y / 2, x / 2]])),
        Upsample::Bilinear => {
            let (ys, xs) = (bilinear_taps(h), bilinear_taps(w));
            Zip::indexed(&mut out).and(blend).for_each(|(y, x), o, &b| {
                let ((y0, y1), (x0, x1)) = (ys[y], xs[x]);
                // The same sum order as PyTorch's upsample_bilinear2d: rows, then columns.
                let row = |r| 0.75 * detail[[r, x0]] + 0.25 * detail[[r, x1]];
                *o = b * cap(y * w + x, 0.75 * row(y0) + 0.25 * row(y1));
            })
        }
    }
    out.into_raw_vec_and_offset().0
}

/// Per fine index along an axis of `n` fine pixels: (the nearer coarse index, weight 3/4;
/// the next one toward the fine pixel's centre, weight 1/4, replicated at the edges).
fn bilinear_taps(n: usize) -> Vec<(usize, usize)> {
    let last = n / 2 - 1;
    (0..n)
        .map(|i| {
            let c = i / 2;
            let next = if i % 2 == 0 {
                c.saturating_sub(1)
            } else {
                (c + 1).min(last)
            };
            (c, next)
        })
        .collect()
}

/// Steps 5-7: the chroma filter's colour at the luma filter's luminance, remodulated,
/// made finite and clamped.
fn recombine(cy: &[f32], cc: &[f32], d: Option<(&[f32], f32)>, n: usize, ldr: bool) -> Vec<f32> {
    let hi = if ldr { 1.0 } else { LINEAR_MAX };
    let mut out = vec![0.0; 3 * n];
    let (o0, rest) = out.split_at_mut(n);
    let (o1, o2) = rest.split_at_mut(n);
    for i in 0..n {
        let c = [cc[i].max(0.0), cc[n + i].max(0.0), cc[2 * n + i].max(0.0)];
        let yc = LUMA_WEIGHTS[0] * c[0] + LUMA_WEIGHTS[1] * c[1] + LUMA_WEIGHTS[2] * c[2];
        let y = cy[i].max(0.0);
        let pull = GREY_PULL * y;
        let s = y / (yc + pull + MIN_CHROMA_LUMA);
        let mut v = [(c[0] + pull) * s, (c[1] + pull) * s, (c[2] + pull) * s];
        if let Some((a, eps)) = d {
            (0..3).for_each(|ch| v[ch] *= a[ch * n + i] + eps);
        }
        let lim = |v: f32| if v.is_finite() { v.clamp(0.0, hi) } else { 0.0 };
        (o0[i], o1[i], o2[i]) = (lim(v[0]), lim(v[1]), lim(v[2]));
    }
    out
}

/// NaN -> 0, everything else clamped to +-[`LOGIT_MAX`] (so +-Inf too).
#[inline(always)]
fn clean_logit(v: f32) -> f32 {
    if v.is_nan() {
        0.0
    } else {
        v.clamp(-LOGIT_MAX, LOGIT_MAX)
    }
}

/// The logistic function of a cleaned logit, from exp(-|a|) so nothing overflows.
#[inline(always)]
fn sigmoid(a: f32) -> f32 {
    let a = clean_logit(a);
    let e = exp_nonpos(-a.abs());
    if a >= 0.0 {
        1.0 / (1.0 + e)
    } else {
        e / (1.0 + e)
    }
}

/// e^x for x <= 0 (after the max is subtracted), within 2 ulp; 0 below -87 where f32
/// underflows. Cephes' expf polynomial with round-to-nearest by the 1.5 * 2^23 trick and
/// the power of two built from bits: no branches, no libm call, so LLVM vectorises it.
#[inline(always)]
fn exp_nonpos(x: f32) -> f32 {
    const MAGIC: f32 = 12_582_912.0; // 1.5 * 2^23: adding it rounds to an integer
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    let xc = if x < -87.0 { -87.0 } else { x };
    let t = xc * std::f32::consts::LOG2_E + MAGIC;
    let nf = t - MAGIC;
    let r = xc - nf * LN2_HI - nf * LN2_LO;
    let mut p = 1.987_569_1e-4_f32;
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 1.666_666_5e-1;
    p = p * r + 0.5; // Cephes' 5.0000001201e-1 rounds to 0.5 in f32
    let e = p * r * r + r + 1.0;
    // t's bits are MAGIC's plus n (n in -126..=0 lies in MAGIC's binade).
    let n = t.to_bits().wrapping_sub(MAGIC.to_bits()) as i32;
    let scale = f32::from_bits(((n + 127) as u32) << 23);
    if x < -87.0 {
        0.0
    } else {
        e * scale
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (xorshift64*): tests need no `rand`.
    struct Rng(u64);

    impl Rng {
        fn uniform(&mut self) -> f32 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32 / (1u64 << 24) as f32
        }

        /// Roughly normal with standard deviation `sd` (sum of four uniforms).
        fn normal(&mut self, sd: f32) -> f32 {
            let s: f32 = (0..4).map(|_| self.uniform()).sum();
            (s - 2.0) * sd * 3f32.sqrt()
        }

        fn vec(&mut self, n: usize, f: impl Fn(&mut Self) -> f32) -> Vec<f32> {
            (0..n).map(|_| f(self)).collect()
        }
    }

    fn params(levels: usize, kernel: usize) -> Params {
        Params {
            levels,
            kernel,
            demodulate: false,
            eps: 0.01,
            ldr: false,
            guide: false,
            fixed_range: false,
            exposure: 1.0,
            upsample: Upsample::Nearest,
            range_opening: RangeOpening::Plain,
            coarse_clamp: false,
            coarse_gain: COARSE_GAIN,
            coarse_radius: 0,
            coarse_sparse: 0.0,
            range_noise: 0.0,
        }
    }

    /// Random logits for every level (kernels and blends) with standard deviation `sd`.
    fn logits(rng: &mut Rng, p: &Params, h: usize, w: usize, sd: f32) -> Vec<Vec<f32>> {
        let c = channels(p.kernel, p.guide);
        (0..p.levels)
            .map(|l| rng.vec(c * (h >> l) * (w >> l), |r| r.normal(sd)))
            .collect()
    }

    fn run(
        p: &Params,
        rgb: &[f32],
        albedo: Option<&[f32]>,
        f: &[Vec<f32>],
        h: usize,
        w: usize,
    ) -> Vec<f32> {
        let f: Vec<&[f32]> = f.iter().map(|v| v.as_slice()).collect();
        reconstruct(p, rgb, albedo, None, &f, h, w).unwrap()
    }

    fn lum(v: &[f32], n: usize, i: usize) -> f32 {
        (0..3).map(|c| LUMA_WEIGHTS[c] * v[c * n + i]).sum()
    }

    fn close(a: f32, b: f32, tol: f32) -> bool {
        (a - b).abs() <= tol * b.abs().max(1.0)
    }

    #[test]
    fn reach_matches_the_spec() {
        assert_eq!(reach(3, 5, Upsample::Nearest), 17);
        assert_eq!(reach(1, 5, Upsample::Nearest), 2);
        assert_eq!(reach(2, 3, Upsample::Nearest), 4);
        assert_eq!(reach(1, 5, Upsample::Bilinear), 2);
        assert_eq!(reach(3, 5, Upsample::Bilinear), 20);
        assert_eq!((channels(5, false), channels(5, true)), (52, 54));
    }

    #[test]
    fn exp_is_accurate() {
        let mut worst = 0.0f64;
        for i in 0..=870_000 {
            let x = -(i as f32) * 1e-4;
            let want = (x as f64).exp();
            worst = worst.max(((exp_nonpos(x) as f64) - want).abs() / want);
        }
        assert!(worst < 3e-7, "relative error {worst}");
        assert_eq!(exp_nonpos(-88.0), 0.0);
        assert_eq!(exp_nonpos(-2.0 * LOGIT_MAX), 0.0);
        assert_eq!(exp_nonpos(0.0), 1.0);
    }

    #[test]
    fn zero_logits_at_one_level_are_a_box_filter_renormalised_at_the_border() {
        let (h, w, k) = (7, 9, 3);
        let mut rng = Rng(1);
        let rgb = rng.vec(3 * h * w, |r| r.uniform() + 0.1);
        let f = vec![vec![0.0; channels(k, false) * h * w]];
        let out = run(&params(1, k), &rgb, None, &f, h, w);
        for c in 0..3 {
            for y in 0..h {
                for x in 0..w {
                    let (mut s, mut n) = (0.0, 0.0);
                    for yy in y.saturating_sub(1)..(y + 2).min(h) {
                        for xx in x.saturating_sub(1)..(x + 2).min(w) {
                            s += rgb[c * h * w + yy * w + xx];
                            n += 1.0;
                        }
                    }
                    let got = out[c * h * w + y * w + x];
                    assert!(close(got, s / n, 1e-5), "({c},{y},{x}): {got} vs {}", s / n);
                }
            }
        }
    }

    #[test]
    fn a_constant_image_stays_constant_for_any_logits() {
        let (h, w) = (16, 24);
        let mut rng = Rng(2);
        for (levels, k, sd) in [(1, 3, 3.0), (2, 5, 1.0), (3, 5, 5.0), (3, 3, 20.0)] {
            let p = params(levels, k);
            let rgb: Vec<f32> = [0.7f32, 0.2, 3.5]
                .iter()
                .flat_map(|&v| vec![v; h * w])
                .collect();
            let out = run(&p, &rgb, None, &logits(&mut rng, &p, h, w, sd), h, w);
            for (i, (o, v)) in out.iter().zip(&rgb).enumerate() {
                assert!(
                    close(*o, *v, 1e-5),
                    "L={levels} k={k} value {i}: {o} vs {v}"
                );
            }
        }
    }

    #[test]
    fn heavy_tailed_noise_keeps_its_mean_under_random_logits() {
        let (h, w) = (128, 128);
        let n = h * w;
        let base = [0.6f32, 0.25, 0.1];
        let mut rng = Rng(3);
        let u = rng.vec(n, |r| r.uniform());
        let rgb: Vec<f32> = base
            .iter()
            .flat_map(|b| u.iter().map(move |u| 2.0 * b * u * u))
            .collect();
        let p = params(3, 5);
        let out = run(&p, &rgb, None, &logits(&mut rng, &p, h, w, 2.0), h, w);
        for c in 0..3 {
            let mean =
                |v: &[f32]| v[c * n..][..n].iter().map(|&x| x as f64).sum::<f64>() / n as f64;
            let (i, o) = (mean(&rgb), mean(&out));
            assert!((o / i - 1.0).abs() < 0.01, "channel {c}: mean {i} -> {o}");
        }
    }

    #[test]
    fn the_output_luminance_is_the_luma_paths() {
        // The luma path sees only Y and the luma logits, so a grey image of the same Y gives
        // the luma path's result in every channel.
        let (h, w) = (16, 16);
        let n = h * w;
        let mut rng = Rng(4);
        let p = params(3, 3);
        let rgb = rng.vec(3 * n, |r| 4.0 * r.uniform() * r.uniform());
        let f = logits(&mut rng, &p, h, w, 2.0);
        let out = run(&p, &rgb, None, &f, h, w);
        let grey: Vec<f32> = (0..3)
            .flat_map(|_| (0..n).map(|i| lum(&rgb, n, i)))
            .collect();
        let luma = run(&p, &grey, None, &f, h, w);
        for (i, &want) in luma[..n].iter().enumerate() {
            let got = lum(&out, n, i);
            assert!(close(got, want, 1e-5), "pixel {i}: {got} vs {want}");
        }
    }

    #[test]
    fn a_chroma_result_far_darker_than_the_luma_turns_grey_smoothly() {
        // The centre's luma comes from a bright pixel, its chroma from a red-blue corner
        // `tiny` times as bright: the hue survives 1e-4, and at 1e-12 there is none left.
        let (h, w, n) = (3, 3, 9);
        let p = params(1, 3);
        let mut f = vec![-LOGIT_MAX; 20 * n];
        f[4 * n..5 * n].fill(0.0); // luma: the centre tap
        f[9 * n..10 * n].fill(0.0); // chroma: the top-left tap
        for (tiny, grey) in [(1e-4f32, false), (1e-12, true), (1e-29, true)] {
            let mut rgb = vec![0.0f32; 3 * n];
            for (c, (centre, corner)) in [(0.5, 1.0), (0.4, 0.0), (0.3, 0.5)].iter().enumerate() {
                (rgb[c * n + 4], rgb[c * n]) = (*centre, corner * tiny);
            }
            let out = run(&p, &rgb, None, &[f.clone()], h, w);
            let (y, o) = (lum(&rgb, n, 4), [out[4], out[n + 4], out[2 * n + 4]]);
            assert!(
                close(lum(&out, n, 4), y, 1e-6),
                "{tiny}: luminance {o:?} vs {y}"
            );
            if grey {
                assert!(
                    o.iter().all(|&v| (v - y).abs() < 1e-3 * y),
                    "{tiny}: {o:?} not grey"
                );
            } else {
                assert!(
                    o[1] < 0.05 * y && o[0] > 1.5 * o[2],
                    "{tiny}: hue lost, {o:?}"
                );
            }
        }
    }

    #[test]
    fn non_finite_and_huge_logits_give_finite_output() {
        let (h, w) = (8, 16);
        let n = h * w;
        let mut rng = Rng(5);
        let specials = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN,
            1e30,
            -1e30,
            88.0,
            -88.0,
        ];
        let rgb = rng.vec(3 * n, |r| LINEAR_MAX * r.uniform().powi(8));
        let albedo = rng.vec(3 * n, |r| if r.uniform() < 0.3 { 0.0 } else { r.uniform() });
        for (demodulate, ldr) in [(false, false), (true, false), (true, true)] {
            let p = Params {
                demodulate,
                ldr,
                ..params(3, 5)
            };
            let mut f = logits(&mut rng, &p, h, w, 1.0);
            for v in f.iter_mut().flatten() {
                if rng.uniform() < 0.5 {
                    *v =
                        specials[(rng.uniform() * specials.len() as f32) as usize % specials.len()];
                }
            }
            let out = run(&p, &rgb, Some(&albedo), &f, h, w);
            let hi = if ldr { 1.0 } else { LINEAR_MAX };
            assert!(out.iter().all(|v| v.is_finite() && (0.0..=hi).contains(v)));
        }
    }

    #[test]
    fn nan_logits_are_zero_and_infinite_ones_are_clamped() {
        let (h, w, k) = (4, 6, 3);
        let n = h * w;
        let mut rng = Rng(6);
        let rgb = rng.vec(3 * n, |r| r.uniform() + 0.1);
        let box_out = run(
            &params(1, k),
            &rgb,
            None,
            &[vec![0.0; channels(k, false) * n]],
            h,
            w,
        );
        let nan_out = run(
            &params(1, k),
            &rgb,
            None,
            &[vec![f32::NAN; channels(k, false) * n]],
            h,
            w,
        );
        assert_eq!(box_out, nan_out);
        // +Inf on the centre tap, -Inf elsewhere: the identity.
        let mut f = vec![f32::NEG_INFINITY; channels(k, false) * n];
        for kernel in 0..2 {
            f[(kernel * k * k + k * k / 2) * n..][..n].fill(f32::INFINITY);
        }
        let out = run(&params(1, k), &rgb, None, &[f], h, w);
        assert!(out.iter().zip(&rgb).all(|(o, v)| close(*o, *v, 1e-6)));
    }

    #[test]
    fn demodulation_round_trips_a_constant_irradiance() {
        let (h, w) = (16, 8);
        let n = h * w;
        let mut rng = Rng(7);
        let p = Params {
            demodulate: true,
            eps: 0.01,
            ..params(2, 5)
        };
        let albedo = rng.vec(3 * n, |r| if r.uniform() < 0.2 { 0.0 } else { r.uniform() });
        let irradiance = [2.0f32, 1.5, 0.5];
        let rgb: Vec<f32> = (0..3 * n)
            .map(|i| irradiance[i / n] * (albedo[i] + p.eps))
            .collect();
        let out = run(
            &p,
            &rgb,
            Some(&albedo),
            &logits(&mut rng, &p, h, w, 3.0),
            h,
            w,
        );
        for (i, (o, v)) in out.iter().zip(&rgb).enumerate() {
            assert!(close(*o, *v, 1e-5), "value {i}: {o} vs {v}");
        }
    }

    #[test]
    fn bad_arguments_are_errors() {
        let (h, w) = (8, 8);
        let n = h * w;
        let rgb = vec![0.5; 3 * n];
        let f0 = vec![0.0; channels(3, false) * n];
        let f1 = vec![0.0; channels(3, false) * n / 4];
        let ok: [&[f32]; 2] = [&f0, &f1];
        let p = params(2, 3);
        assert!(reconstruct(&p, &rgb, None, None, &ok, h, w).is_ok());
        let err = |p: &Params, rgb: &[f32], a: Option<&[f32]>, f: &[&[f32]], h, w| {
            matches!(
                reconstruct(p, rgb, a, None, f, h, w),
                Err(Error::InvalidArgument(_))
            )
        };
        assert!(err(&params(0, 3), &rgb, None, &[], h, w));
        assert!(err(&params(2, 4), &rgb, None, &ok, h, w));
        assert!(err(&params(1, 3), &rgb, None, &ok, h, w));
        assert!(err(&p, &rgb, None, &ok[..1], h, w));
        assert!(err(&p, &rgb[1..], None, &ok, h, w));
        assert!(err(&p, &rgb, None, &[&f0, &f0], h, w));
        assert!(err(&p, &rgb, None, &ok, 0, 0));
        assert!(err(&params(2, 3), &vec![0.5; 3 * 7 * 8], None, &ok, 7, 8));
        assert!(err(&params(40, 3), &rgb, None, &ok, h, w));
        assert!(err(&params(1, 3), &rgb, None, &ok[..1], usize::MAX, 2));
        let demod = Params {
            demodulate: true,
            ..p
        };
        assert!(err(&demod, &rgb, None, &ok, h, w));
        assert!(err(&demod, &rgb, Some(&rgb[..10]), &ok, h, w));
        assert!(err(
            &Params { eps: 0.0, ..demod },
            &rgb,
            Some(&rgb),
            &ok,
            h,
            w
        ));
        assert!(reconstruct(&demod, &rgb, Some(&rgb), None, &ok, h, w).is_ok());
        let cap = |coarse_gain, coarse_radius, coarse_sparse| Params {
            coarse_clamp: true,
            coarse_gain,
            coarse_radius,
            coarse_sparse,
            ..p
        };
        assert!(reconstruct(&cap(0.5, 4, 0.5), &rgb, None, None, &ok, h, w).is_ok());
        for (gain, radius, sparse) in [
            (0.0, 0, 0.0),
            (f32::NAN, 0, 0.0),
            (1.0, COARSE_RADIUS_MAX + 1, 0.0),
            (1.0, 0, 1.5),
            (1.0, 0, -0.1),
            (1.0, 0, f32::NAN),
        ] {
            assert!(err(&cap(gain, radius, sparse), &rgb, None, &ok, h, w));
        }
    }

    #[test]
    fn every_instruction_set_gives_the_same_bits() {
        let (h, w, k) = (12, 300, 5);
        let mut rng = Rng(9);
        let x = rng.vec(3 * h * w, |r| r.uniform());
        let opened = rng.vec(h * w, |r| r.uniform());
        for (guide, fixed_range) in [(false, false), (true, false), (true, true)] {
            let p = Params {
                guide,
                fixed_range,
                ..params(1, k)
            };
            let o = fixed_range.then_some(opened.as_slice());
            let f = rng.vec(channels(k, guide) * h * w, |r| r.normal(3.0));
            let mut s = Scratch::new(k, w);
            let lv = Level {
                x: &x,
                f: &f,
                opened: o,
                h,
                w,
            };
            let any = filter_level_any(&lv, &p, &mut s);
            assert_eq!(filter_level(&lv, &p, &mut s), any);
            // The dispatch takes the widest; the narrower ones must agree too.
            #[cfg(target_arch = "x86_64")]
            if std::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2.
                let avx2 = unsafe { filter_level_avx2(&lv, &p, &mut s) };
                assert_eq!(avx2, any);
            }
        }
    }

    /// A lamp whose guide differs from its surroundings' by 6 (range term -18 per tap)
    /// stays out of its neighbours under box logits, and they stay out of it, while the
    /// same logits without the guide spread it.
    #[test]
    fn the_guide_fences_a_lamp_off() {
        let (h, w, k) = (8, 8, 3);
        let n = h * w;
        let lamp = |i: usize| (2..4).contains(&(i / w)) && (2..4).contains(&(i % w));
        let rgb: Vec<f32> = (0..3 * n)
            .map(|i| if lamp(i % n) { 500.0 } else { 0.1 })
            .collect();
        let mut f = vec![0.0; channels(k, true) * n];
        for g in [2 * k * k + 2, 2 * k * k + 3] {
            (0..n).filter(|&i| lamp(i)).for_each(|i| f[g * n + i] = 6.0);
        }
        let p = Params {
            guide: true,
            ..params(1, k)
        };
        let out = run(&p, &rgb, None, &[f], h, w);
        let unguided = run(
            &params(1, k),
            &rgb,
            None,
            &[vec![0.0; channels(k, false) * n]],
            h,
            w,
        );
        let beside = 4 * w + 4; // diagonal to the lamp's corner (3, 3)
        assert!(
            close(lum(&out, n, beside), 0.1, 1e-3),
            "{}",
            lum(&out, n, beside)
        );
        assert!(lum(&unguided, n, beside) > 50.0);
        assert!(close(lum(&out, n, 2 * w + 2), 500.0, 1e-3));
    }

    /// The fixed range term with logits that pull every pixel toward the lamp's taps by
    /// e^12 (a worst case a network could learn): a 4x4 lamp 1000x its ceiling stays out
    /// of every ceiling pixel and keeps its own value, wherever the exposure puts the
    /// ceiling above RANGE_FLOOR (below it, darkness reads as one level: the floor's price).
    #[test]
    fn the_fixed_range_term_keeps_a_lamp_out_of_any_logits() {
        let (h, w, k) = (16, 16, 5);
        let n = h * w;
        let lamp = |i: usize| (4..8).contains(&(i / w)) && (4..8).contains(&(i % w));
        let rgb: Vec<f32> = (0..3 * n)
            .map(|i| if lamp(i % n) { 100.0 } else { 0.1 })
            .collect();
        // Logit 20 on every tap that lands on the lamp, 0 elsewhere.
        let mut f = vec![0.0; channels(k, false) * n];
        for i in 0..n {
            for t in 0..k * k {
                let (dy, dx) = tap(k, t);
                let (y, x) = ((i / w) as isize + dy, (i % w) as isize + dx);
                let inside = (0..h as isize).contains(&y) && (0..w as isize).contains(&x);
                if inside && lamp(y as usize * w + x as usize) {
                    f[t * n + i] = 12.0;
                    f[(k * k + t) * n + i] = 12.0;
                }
            }
        }
        for exposure in [1.0, 1.8, 10.0, 1000.0] {
            let p = Params {
                fixed_range: true,
                exposure,
                ..params(1, k)
            };
            let out = run(&p, &rgb, None, &[f.clone()], h, w);
            let free = run(&params(1, k), &rgb, None, &[f.clone()], h, w);
            for i in 0..n {
                let want = if lamp(i) { 100.0 } else { 0.1 };
                assert!(
                    (lum(&out, n, i) - want).abs() <= 0.02 * want,
                    "exposure {exposure}, pixel {i}: {} for {want}",
                    lum(&out, n, i)
                );
            }
            assert!(lum(&free, n, 3 * w + 3) > 90.0, "without it the lamp leaks");
        }
    }

    /// A firefly (smaller than the 3x3 opening) is not fenced off: the box filter spreads
    /// it as it would without the term, keeping the energy.
    #[test]
    fn the_fixed_range_term_lets_a_firefly_spread() {
        let (h, w, k) = (16, 16, 5);
        let n = h * w;
        let fly = 8 * w + 8;
        let rgb: Vec<f32> = (0..3 * n)
            .map(|i| if i % n == fly { 1000.0 } else { 0.1 })
            .collect();
        let f = vec![vec![0.0; channels(k, false) * n]];
        let p = Params {
            fixed_range: true,
            ..params(1, k)
        };
        let out = run(&p, &rgb, None, &f, h, w);
        let plain = run(&params(1, k), &rgb, None, &f, h, w);
        for i in 0..n {
            assert!(close(lum(&out, n, i), lum(&plain, n, i), 1e-5), "pixel {i}");
        }
        assert!(lum(&out, n, fly) < 41.0);
    }

    /// The threshold from local noise: on a clean bright floor, a one-pixel shadow line 1.7
    /// stops darker is below RANGE_TAU, so the fixed threshold lets a box kernel fill it
    /// in; with `range_noise` the line counts as an edge and stays darker.
    #[test]
    fn the_noise_threshold_keeps_a_clean_shadow_line_dark() {
        let (h, w, k) = (16, 16, 5);
        let n = h * w;
        let rgb: Vec<f32> = (0..3 * n)
            .map(|i| if i % w == 8 { 0.3 } else { 1.0 })
            .collect();
        let f = vec![vec![0.0; channels(k, false) * n]];
        let fixed = Params {
            fixed_range: true,
            ..params(1, k)
        };
        let noise = Params {
            range_noise: 4.0,
            ..fixed
        };
        let line = 8 * w + 8;
        let before = lum(&run(&fixed, &rgb, None, &f, h, w), n, line);
        let after = lum(&run(&noise, &rgb, None, &f, h, w), n, line);
        assert!(
            before > 0.84,
            "the fixed threshold fills the line in: {before}"
        );
        assert!(after < 0.75, "the line stays darker: {after}");
    }

    /// The threshold is 0 on a flat image and RANGE_TAU on a 1-spp-like one (a quarter of
    /// the pixels bright, the rest black), so noise never reads as an edge.
    #[test]
    fn the_noise_threshold_follows_the_noise() {
        let (h, w) = (12, 20);
        let flat = range_threshold(&vec![0.5; h * w], h, w, 1.0, 4.0);
        assert!(flat.iter().all(|&t| t == 0.0), "{flat:?}");
        let mut rng = Rng(7);
        let sparse = rng.vec(h * w, |r| if r.uniform() < 0.25 { 4.0 } else { 0.0 });
        let tau = range_threshold(&sparse, h, w, 1.0, 4.0);
        assert!(tau.iter().all(|&t| t == RANGE_TAU), "{tau:?}");
    }

    /// Under the aux-guided opening, a 1 px lamp with an emitter's albedo keeps its light
    /// and none reaches its neighbours, while a firefly on the surface and one on a lone
    /// texel (no neighbour on its surface, not an emitter) still spread as they would under
    /// the plain opening; without the aux planes the reconstruction refuses.
    #[test]
    fn the_aux_guided_opening_keeps_a_small_lamp_and_spreads_fireflies() {
        let (h, w, k) = (16, 16, 5);
        let n = h * w;
        let (lamp, fly, texel) = (5 * w + 5, 11 * w + 10, 3 * w + 12);
        let rgb: Vec<f32> = (0..3 * n)
            .map(|i| match i % n {
                j if j == lamp => 800.0,
                j if j == fly || j == texel => 900.0,
                _ => 0.1,
            })
            .collect();
        let mut aux = vec![0.5f32; 7 * n];
        for c in 0..3 {
            aux[c * n + lamp] = 1.0;
            aux[c * n + texel] = 0.2;
        }
        let f = vec![vec![0.0; channels(k, false) * n]];
        let plain = Params {
            fixed_range: true,
            ..params(1, k)
        };
        let p = Params {
            range_opening: RangeOpening::Aux,
            ..plain
        };
        let a = RangeAux {
            planes: &aux,
            count: 7,
            albedo: Some(0),
        };
        let fr: Vec<&[f32]> = f.iter().map(Vec::as_slice).collect();
        let out = reconstruct(&p, &rgb, None, Some(a), &fr, h, w).unwrap();
        let spread = run(&plain, &rgb, None, &f, h, w);
        assert!(close(lum(&out, n, lamp), 800.0, 1e-5));
        assert!(lum(&out, n, lamp + 1) < 0.2 && lum(&out, n, lamp + w) < 0.2);
        assert!(
            lum(&spread, n, lamp + 1) > 20.0,
            "the plain opening spreads the lamp"
        );
        for i in [fly, fly + 1, texel, texel - w] {
            assert!(
                close(lum(&out, n, i), lum(&spread, n, i), 1e-5),
                "pixel {i}"
            );
        }
        assert!(reconstruct(&p, &rgb, None, None, &fr, h, w).is_err());
        let short = RangeAux { count: 8, ..a };
        assert!(reconstruct(&p, &rgb, None, Some(short), &fr, h, w).is_err());
    }

    /// With the coarse clamp a coarse level's correction at most doubles a fine value
    /// (COARSE_GAIN 1): a firefly on a dark floor, box kernels, blends wide open, comes out
    /// nowhere above twice what the finest level alone gives; without the clamp the coarse
    /// levels raise the floor around it far more (the block).
    #[test]
    fn the_coarse_clamp_caps_what_coarse_levels_add() {
        let (h, w, k, levels) = (16, 16, 3, 3);
        let n = h * w;
        let fly = 9 * w + 6;
        let rgb: Vec<f32> = (0..3 * n)
            .map(|i| if i % n == fly { 700.0 } else { 0.01 })
            .collect();
        let blends_open = |l: usize| {
            let nl = (h >> l) * (w >> l);
            let mut f = vec![0.0; channels(k, false) * nl];
            f[2 * k * k * nl..].fill(LOGIT_MAX);
            f
        };
        let f: Vec<Vec<f32>> = (0..levels).map(blends_open).collect();
        let fine = run(&params(1, k), &rgb, None, &f[..1], h, w);
        let free = run(&params(levels, k), &rgb, None, &f, h, w);
        let capped = Params {
            coarse_clamp: true,
            ..params(levels, k)
        };
        let out = run(&capped, &rgb, None, &f, h, w);
        let ratio = |o: &[f32], i| lum(o, n, i) / lum(&fine, n, i);
        assert!((0..n).all(|i| ratio(&out, i) <= 2.0 + 1e-4));
        assert!((0..n).any(|i| ratio(&free, i) > 10.0), "the block it caps");
    }

    /// Two levels of 3x3 logits on `h` x `w`: identity kernels at the fine level, a box at
    /// level 1, blends open (the coarse cap tests').
    fn identity_over_box(h: usize, w: usize) -> Vec<Vec<f32>> {
        let k = 3;
        let level = |l: usize| {
            let nl = (h >> l) * (w >> l);
            let mut f = vec![0.0; channels(k, false) * nl];
            if l == 0 {
                f[..2 * k * k * nl].fill(-LOGIT_MAX);
                f[4 * nl..5 * nl].fill(LOGIT_MAX); // luma centre tap
                f[13 * nl..14 * nl].fill(LOGIT_MAX); // chroma centre tap
            }
            f[2 * k * k * nl..].fill(LOGIT_MAX); // blends open
            f
        };
        (0..2).map(level).collect()
    }

    /// The cap against a local mean (`temc.coarse_radius`): on a floor at 1-spp-like
    /// sparsity (most pixels black in the fine level's own result, identity kernels), a
    /// pixel's own value caps a black pixel at black, so the coarse level cannot fill it;
    /// its 5x5 mean lets it. A lone firefly's dark surroundings outside its own 5x5 stay
    /// capped at twice the dark level (their mean is dark too).
    #[test]
    fn the_coarse_cap_against_a_local_mean_fills_sparse_pixels() {
        let (h, w, k, levels) = (16, 16, 3, 2);
        let n = h * w;
        let f = identity_over_box(h, w);
        // One lit pixel in every other 2x2 block: the blocks alternate 1 and 0 at level 1,
        // whose box kernel brings a black block up to about 0.5.
        let even = |v: usize| v.is_multiple_of(2);
        let lit = |y: usize, x: usize| even(y) && even(x) && even(y / 2 + x / 2);
        let sparse: Vec<f32> = (0..3 * n)
            .map(|i| if lit(i % n / w, i % n % w) { 4.0 } else { 0.0 })
            .collect();
        let capped = |r| Params {
            coarse_clamp: true,
            coarse_radius: r,
            ..params(levels, k)
        };
        let black = w + 2; // (1, 2), in the black block (0, 1)
        let own = run(&capped(0), &sparse, None, &f, h, w);
        let mean = run(&capped(2), &sparse, None, &f, h, w);
        assert!(lum(&own, n, black) < 1e-6, "{}", lum(&own, n, black));
        assert!(lum(&mean, n, black) > 0.25, "{}", lum(&mean, n, black));
        let fly = 9 * w + 6;
        let dark: Vec<f32> = (0..3 * n)
            .map(|i| if i % n == fly { 700.0 } else { 0.01 })
            .collect();
        let near = 11 * w + 9; // in the coarse level's reach, outside the firefly's 5x5
        let free = run(&params(levels, k), &dark, None, &f, h, w);
        let out = run(&capped(2), &dark, None, &f, h, w);
        assert!(lum(&free, n, near) > 1.0, "{}", lum(&free, n, near));
        assert!(
            lum(&out, n, near) <= 2.0 * 0.01 + 1e-4,
            "{}",
            lum(&out, n, near)
        );
    }

    /// The cap's rise where samples are sparse (`temc.coarse_sparse`; the Python test of
    /// the same name): one lit pixel in every 4x4 block, identity kernels at the fine
    /// level, a box at level 1, blends open, capped at half the 5x5 mean. With the rise
    /// (one to four lit pixels in 25: 5x to 3x) the black pixels between the samples come
    /// out about twice as bright, never brighter than with no cap; a dim floor lit
    /// everywhere, firefly and all, rises by 1: the same image.
    #[test]
    fn the_coarse_cap_rises_where_samples_are_sparse() {
        let (h, w, k, levels) = (16, 16, 3, 2);
        let n = h * w;
        let f = identity_over_box(h, w);
        let lit = |i: usize| (i % n / w).is_multiple_of(4) && (i % n % w).is_multiple_of(4);
        let sparse: Vec<f32> = (0..3 * n).map(|i| if lit(i) { 4.0 } else { 0.0 }).collect();
        let capped = |share| Params {
            coarse_clamp: true,
            coarse_gain: 0.5,
            coarse_radius: 2,
            coarse_sparse: share,
            ..params(levels, k)
        };
        let black_mean = |out: &[f32]| {
            let black: Vec<usize> = (0..n).filter(|&i| !lit(i)).collect();
            black.iter().map(|&i| lum(out, n, i)).sum::<f32>() / black.len() as f32
        };
        let base = run(&capped(0.0), &sparse, None, &f, h, w);
        let risen = run(&capped(0.5), &sparse, None, &f, h, w);
        let free = run(&params(levels, k), &sparse, None, &f, h, w);
        assert!(
            black_mean(&risen) > 1.8 * black_mean(&base),
            "{} {}",
            black_mean(&risen),
            black_mean(&base)
        );
        assert!((0..n).all(|i| lum(&risen, n, i) <= lum(&free, n, i) + 1e-6));
        let dark: Vec<f32> = (0..3 * n)
            .map(|i| if i % n == 9 * w + 6 { 700.0 } else { 0.01 })
            .collect();
        assert_eq!(
            run(&capped(0.0), &dark, None, &f, h, w),
            run(&capped(0.5), &dark, None, &f, h, w)
        );
    }

    /// The chroma composition's common cap (recon_vectors' chroma_cap case): dark warm
    /// pixels in a 2x2 block with an orange bright one, the fine chroma kernel one-hot, the
    /// coarse one a box, blends open. The coarse correction drives their red and green far
    /// below zero but not their blue; clamped channel by channel they came out pure blue.
    #[test]
    fn a_coarse_correction_does_not_turn_a_warm_pixel_blue() {
        let (h, w, k) = (8, 8, 3);
        let n = h * w;
        let mut rgb: Vec<f32> = [0.1, 0.08, 0.05].iter().flat_map(|&v| vec![v; n]).collect();
        for (c, v) in [4.0, 2.4, 0.1].into_iter().enumerate() {
            rgb[c * n + 2 * w + 2] = v;
        }
        let mut fine = vec![0.0; channels(k, false) * n];
        fine[9 * n..18 * n].fill(-LOGIT_MAX);
        fine[13 * n..14 * n].fill(LOGIT_MAX);
        fine[18 * n..20 * n].fill(LOGIT_MAX);
        let coarse = vec![0.0; channels(k, false) * n / 4];
        let out = run(&params(2, k), &rgb, None, &[fine, coarse], h, w);
        for i in [2 * w + 3, 3 * w + 2, 3 * w + 3] {
            let (r, g, b) = (out[i], out[n + i], out[2 * n + i]);
            assert!(b <= r && b <= g && r > 0.5 * b, "pixel {i}: {r} {g} {b}");
        }
    }

    /// Per pixel, the chroma correction is added whole where it leaves every channel at least
    /// [`CHROMA_KEEP`] of its value, and otherwise shrunk, all channels alike, until the first
    /// one reaches that floor.
    #[test]
    fn the_chroma_correction_shrinks_all_channels_alike() {
        let fc = vec![0.4, 0.3, 0.2, 0.1, 0.2, 0.05];
        let dc = vec![vec![0.1, -0.3], vec![-0.1, -0.1], vec![0.05, 0.05]];
        let mut out = fc.clone();
        add_chroma_correction(&mut out, &dc, 2);
        let whole = [0.5, 0.1, 0.25]; // green lands exactly on its floor: still whole
        assert!([out[0], out[2], out[4]]
            .iter()
            .zip(whole)
            .all(|(o, w)| (o - w).abs() < 1e-6));
        let share = (out[1] - 0.3) / -0.3;
        assert!(
            (share - 0.5).abs() < 1e-6,
            "red reaches half its value: {share}"
        );
        assert!((out[3] - (0.1 - 0.1 * share)).abs() < 1e-6);
        assert!((out[5] - (0.05 + 0.05 * share)).abs() < 1e-6);
    }

    fn json_f32(v: &serde_json::Value) -> f32 {
        match v {
            serde_json::Value::String(s) => match s.as_str() {
                "nan" => f32::NAN,
                "inf" => f32::INFINITY,
                "-inf" => f32::NEG_INFINITY,
                other => panic!("bad number {other}"),
            },
            v => v.as_f64().expect("a number") as f32,
        }
    }

    fn json_vec(v: &serde_json::Value) -> Vec<f32> {
        v.as_array()
            .expect("an array")
            .iter()
            .map(json_f32)
            .collect()
    }

    /// The PyTorch reference (float64) of training/temc_train/vectors/recon_vectors.py.
    #[test]
    fn matches_the_pytorch_vectors() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/recon_vectors.json");
        let text = std::fs::read_to_string(path).expect("tests/data/recon_vectors.json");
        let doc: serde_json::Value = serde_json::from_str(&text).unwrap();
        let tol = doc["tolerance"].as_f64().unwrap() as f32;
        assert_eq!(doc["logit_max"].as_f64().unwrap() as f32, LOGIT_MAX);
        let cases = doc["cases"].as_array().unwrap();
        assert!(cases.len() >= 8);
        for case in cases {
            let name = case["name"].as_str().unwrap();
            let dim = |k: &str| case[k].as_u64().unwrap() as usize;
            let (h, w) = (dim("h"), dim("w"));
            let p = Params {
                levels: dim("levels"),
                kernel: dim("kernel"),
                demodulate: case["demodulate"].as_bool().unwrap(),
                eps: case["eps"].as_f64().unwrap() as f32,
                ldr: case["ldr"].as_bool().unwrap(),
                guide: case["guide"].as_bool().unwrap_or(false),
                fixed_range: case["fixed_range"].as_bool().unwrap_or(false),
                exposure: case["exposure"].as_f64().unwrap_or(1.0) as f32,
                upsample: {
                    let u = case["upsample"].as_str().unwrap_or("nearest");
                    Upsample::from_name(u).unwrap_or_else(|| panic!("{name}: bad upsample {u}"))
                },
                range_opening: {
                    let o = case["range_opening"].as_str().unwrap_or("plain");
                    RangeOpening::from_name(o)
                        .unwrap_or_else(|| panic!("{name}: bad range_opening {o}"))
                },
                coarse_clamp: case["coarse_clamp"].as_bool().unwrap_or(false),
                coarse_gain: case["coarse_gain"].as_f64().unwrap_or(1.0) as f32,
                coarse_radius: case["coarse_radius"].as_u64().unwrap_or(0) as usize,
                coarse_sparse: case["coarse_sparse"].as_f64().unwrap_or(0.0) as f32,
                range_noise: case["range_noise"].as_f64().unwrap_or(0.0) as f32,
            };
            let rgb = json_vec(&case["rgb"]);
            let albedo = (!case["albedo"].is_null()).then(|| json_vec(&case["albedo"]));
            let aux = (!case["aux"].is_null()).then(|| json_vec(&case["aux"]));
            let f: Vec<Vec<f32>> = case["filters"]
                .as_array()
                .unwrap()
                .iter()
                .map(json_vec)
                .collect();
            let want = json_vec(&case["out"]);
            let fr: Vec<&[f32]> = f.iter().map(Vec::as_slice).collect();
            let a = aux.as_deref().map(|planes| RangeAux {
                planes,
                count: planes.len() / (h * w),
                albedo: Some(0),
            });
            let got = reconstruct(&p, &rgb, albedo.as_deref(), a, &fr, h, w).unwrap();
            assert_eq!(got.len(), want.len(), "{name}");
            for (i, (g, e)) in got.iter().zip(&want).enumerate() {
                assert!(
                    close(*g, *e, tol),
                    "{name} value {i}: rust {g} vs torch {e}"
                );
            }
        }
    }

    /// `cargo test --release --lib reconstruct::tests::bench -- --ignored --nocapture`: one
    /// thread, without and with the fixed range term.
    #[test]
    #[ignore]
    fn bench_1080p_three_levels_of_5x5() {
        // 1920x1088 streams 560 MB of logits from memory; a 256x256 tile stays in cache.
        for (h, w, reps) in [(1088, 1920, 5), (256, 256, 100)] {
            let mut rng = Rng(8);
            let rgb = rng.vec(3 * h * w, |r| r.uniform());
            let f = logits(&mut rng, &params(3, 5), h, w, 2.0);
            let fr: Vec<&[f32]> = f.iter().map(|v| v.as_slice()).collect();
            // Alternated, so both variants see the same machine load.
            let mut best = [f64::INFINITY; 2];
            for _ in 0..reps {
                for (fixed_range, b) in [false, true].into_iter().zip(&mut best) {
                    let p = Params {
                        fixed_range,
                        ..params(3, 5)
                    };
                    let t = std::time::Instant::now();
                    let out = reconstruct(&p, &rgb, None, None, &fr, h, w).unwrap();
                    *b = b.min(t.elapsed().as_secs_f64());
                    std::hint::black_box(out);
                }
            }
            let ns = best.map(|b| b * 1e9 / (h * w) as f64);
            println!(
                "reconstruct {w}x{h}, 3 levels of 5x5: {:.1} ns/pixel, with the fixed range term {:.1} ({:.2}x)",
                ns[0],
                ns[1],
                ns[1] / ns[0]
            );
        }
    }
}
