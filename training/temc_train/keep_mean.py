"""The keep-mean stage: after the reconstruction, each block of the output is scaled back to
the noisy input's mean (docs/keep-mean.md). src/keep_mean.rs is the same function in Rust;
tests/data/keep_mean_vectors.json (`vector_cases`, written by
`python -m temc_train.vectors.keep_mean` from training/) pins the two.

The reconstruction's weights sum to one per *output* pixel, so nothing bounds how much a
bright pixel gives away (a thin bright line spread into its neighbours) or keeps (a firefly the
filter drops): the image's mean drifts. The noisy input's mean over a block is unbiased, so
the ratio of the input's and the output's block sums, interpolated smoothly between block
centres and clamped, restores it without moving detail.
"""

import pathlib

import numpy as np

from .color import LINEAR_MAX, LUMA

# The core's stage (src/keep_mean.rs), measured in docs/keep-mean-measured.md: blocks of
# BLOCK pixels with factors in [1 / CLAMP, CLAMP], then the whole image with factors in
# [1 / GLOBAL_CLAMP, GLOBAL_CLAMP].
BLOCK = 128
CLAMP = 4.0
GLOBAL_CLAMP = 16.0
# A factor above SPREAD_ABOVE scales the pixel by SPREAD_ABOVE only and adds the rest times
# the output's mean over the (2 SPREAD_RADIUS + 1)^2 window around it: a block whose filter
# dropped most of its energy (the dark room's fireflies) gets it back as smooth light, not
# as its few remnants multiplied tenfold (docs/keep-mean.md, "Spread").
SPREAD_ABOVE = 1.25
SPREAD_RADIUS = 16
# That window mean is taken over the output clipped at SPREAD_CLIP times its own window mean,
# so a lamp among dark pixels lights its window's share no more than a few ordinary pixels
# would; what the clip holds back comes back in the last, scaling-only pass
# (docs/keep-mean.md, "A spread that cannot leave a lamp").
SPREAD_CLIP = 4.0
# Before the blocks: a lamp (the pixels standing above LAMP_ABOVE times their window mean, of
# radius SPREAD_RADIUS, in the noisy input's luminance over a whole 2x2 block and in the
# output's) gets the input's light over itself and LAMP_GROW pixels around back, as one
# factor of at most LAMP_MOST: filters that dim a lamp no longer make the blocks raise
# everything else to pay for it (docs/keep-mean.md, "A lamp's light back to the lamp").
LAMP_ABOVE = 8.0
LAMP_GROW = 8
LAMP_MOST = 1.5


def block_sums(x: np.ndarray, block: int) -> np.ndarray:
    """[H, W, C] -> [ceil(H / block), ceil(W / block), C] float64 sums (edge blocks partial)."""
    h, w, c = x.shape
    gh, gw = -(-h // block), -(-w // block)
    pad = np.zeros((gh * block, gw * block, c))
    pad[:h, :w] = x
    return pad.reshape(gh, block, gw, block, c).sum((1, 3))


def ratios(noisy: np.ndarray, out: np.ndarray, block: int, clamp: float) -> np.ndarray:
    """Per block and channel: input sum / output sum, 1 where the output block is black,
    clamped to [1 / clamp, clamp]."""
    si, so = block_sums(noisy, block), block_sums(out, block)
    r = np.where(so > 0, si / np.where(so > 0, so, 1.0), 1.0)
    return np.clip(r, 1.0 / clamp, clamp)


def _axis(n: int, g: int, block: int):
    """Bilinear taps along one axis: pixel i sits at grid coordinate (i + 0.5) / block - 0.5,
    clamped to the outermost block centres."""
    t = np.clip((np.arange(n) + 0.5) / block - 0.5, 0.0, g - 1)
    i0 = np.floor(t).astype(int)
    i1 = np.minimum(i0 + 1, g - 1)
    return i0, i1, t - i0


def interpolate(r: np.ndarray, h: int, w: int, block: int) -> np.ndarray:
    """The [gh, gw, C] block factors, bilinear between block centres, at every pixel."""
    gh, gw = r.shape[:2]
    y0, y1, fy = _axis(h, gh, block)
    x0, x1, fx = _axis(w, gw, block)
    fy, fx = fy[:, None, None], fx[None, :, None]
    top = r[y0][:, x0] * (1 - fx) + r[y0][:, x1] * fx
    bottom = r[y1][:, x0] * (1 - fx) + r[y1][:, x1] * fx
    return top * (1 - fy) + bottom * fy


def window_mean(x: np.ndarray, r: int) -> np.ndarray:
    """[H, W, C] float64 mean over the (2r + 1)^2 window around each pixel, the part of it
    inside the image (a flat image stays flat)."""
    h, w, c = x.shape
    p = np.zeros((h + 1, w + 1, c))
    p[1:, 1:] = np.cumsum(np.cumsum(x.astype(np.float64), 0), 1)
    i0, i1 = np.clip(np.arange(h) - r, 0, h), np.clip(np.arange(h) + r + 1, 0, h)
    j0, j1 = np.clip(np.arange(w) - r, 0, w), np.clip(np.arange(w) + r + 1, 0, w)
    s = p[i1][:, j1] - p[i0][:, j1] - p[i1][:, j0] + p[i0][:, j0]
    return s / ((i1 - i0)[:, None] * (j1 - j0)[None, :])[..., None]


def clipped_spread(o: np.ndarray, excess: np.ndarray, radius: int = SPREAD_RADIUS,
                   clip: float = SPREAD_CLIP) -> np.ndarray:
    """The core's spread: `excess` (a factor's part above SPREAD_ABOVE) times the window
    mean of the output `o` clipped at `clip` times its own window mean, so a lamp among dark
    pixels lights its window's share no more than a few ordinary pixels would
    (docs/keep-mean.md, "Spread"). `clip` inf: the unclipped spread of before 2026-12-07's
    clip."""
    mean = window_mean(o, radius)
    if np.isfinite(clip):
        mean = window_mean(np.minimum(o, clip * mean), radius)
    return excess * mean


def apply(out: np.ndarray, f: np.ndarray, above: float = SPREAD_ABOVE,
          spread=clipped_spread) -> np.ndarray:
    """`out` times the factors `f` (float64), where a factor's part above `above` is
    `spread(out, excess)` instead of multiplying the pixel (the probe passes its
    variants)."""
    o = out.astype(np.float64)
    if not (f > above).any():
        return o * f
    scale = np.minimum(f, above)
    return o * scale + spread(o, f - scale)


def keep_mean(out: np.ndarray, noisy: np.ndarray, block: int = BLOCK, clamp: float = CLAMP,
              ldr: bool = False, above: float = SPREAD_ABOVE,
              spread=clipped_spread) -> np.ndarray:
    """`out` [H, W, 3] rescaled so each block's mean follows `noisy` (the sanitised input the
    reconstruction filtered); block 0 means one block for the whole image; factors above
    `above` spread (`apply`; inf: pure scaling). Result finite, in [0, LINEAR_MAX] (LDR:
    [0, 1])."""
    return np.clip(apply(out, factors(out, noisy, block, clamp), above, spread), 0.0,
                   1.0 if ldr else LINEAR_MAX).astype(np.float32)


def opened(mask: np.ndarray) -> np.ndarray:
    """The [H, W, ...] mask's morphological opening by a 2x2 square: the pixels of its
    2x2-filled blocks. A lone pixel (a high sample of a noisy input) drops out; a lamp of 2x2
    pixels or more stays."""
    e = mask[:-1, :-1] & mask[1:, :-1] & mask[:-1, 1:] & mask[1:, 1:]
    d = np.zeros_like(mask)
    for dy in (0, 1):
        for dx in (0, 1):
            d[dy:dy + e.shape[0], dx:dx + e.shape[1]] |= e
    return d


def restore_lamps(out: np.ndarray, noisy: np.ndarray, above: float = LAMP_ABOVE,
                  grow: int = LAMP_GROW, most: float = LAMP_MOST,
                  luma: bool = True) -> np.ndarray:
    """`out` with its lamps scaled by one factor: the lamp is where the noisy input stands
    above `above` times its window mean over a whole 2x2 block (the opening drops lone high
    samples, so picking the set by its noise does not bias it) and the output does too; the
    factor is 1 + (the input's sum - the output's over the lamp grown by `grow` pixels) / the
    output's sum over the lamp, in [1, `most`]. From luminance (one factor for the three
    channels, the lamp keeps its hue); `luma` False: per channel (the probe's variant)."""
    o, n = out.astype(np.float64), noisy.astype(np.float64)
    if luma:
        o, n = ((x * LUMA).sum(-1, keepdims=True) for x in (o, n))
    lamp = opened(n > above * window_mean(n, SPREAD_RADIUS)) & (o > above * window_mean(o, SPREAD_RADIUS))
    if not lamp.any():
        return out
    near = window_mean(lamp.astype(np.float64), grow) > 0 if grow else lamp
    deficit = np.where(near, n - o, 0.0).sum((0, 1))
    own = np.where(lamp, o, 0.0).sum((0, 1))
    g = np.clip(1.0 + deficit / np.maximum(own, 1e-30), 1.0, most)
    return np.where(lamp, out * g, out).astype(np.float32)


def stage(out: np.ndarray, noisy: np.ndarray, ldr: bool = False,
          above: float = SPREAD_ABOVE, spread=clipped_spread,
          last_spreads: bool = False, lamps: bool = True) -> np.ndarray:
    """The core's keep-mean stage: the lamps' own factor (`restore_lamps`), then keep_mean
    over BLOCK-pixel blocks (local energy), then over the whole image (what the block clamp
    left), then over the whole image once more, scaling only: window means are not
    sum-preserving near the image's edges and the clip holds back a lamp's excess, so after
    a spread the mean is off, and this pass makes it exact. Other `above` and `spread`,
    `last_spreads` (the last pass spreads too, as before the clip) and `lamps` False (no
    lamp factor, as before 2026-12-07's second change) are the probe's variants (above
    inf: scaling only)."""
    if lamps:
        out = restore_lamps(out, noisy)
    local = keep_mean(out, noisy, BLOCK, CLAMP, ldr, above, spread)
    whole = keep_mean(local, noisy, 0, GLOBAL_CLAMP, ldr, above, spread)
    last = above if last_spreads else float("inf")
    return keep_mean(whole, noisy, 0, GLOBAL_CLAMP, ldr, last, spread)


def factors(out: np.ndarray, noisy: np.ndarray, block: int, clamp: float) -> np.ndarray:
    """The float64 [H, W, 3] factors keep_mean multiplies `out` by."""
    h, w = out.shape[:2]
    b = block if block > 0 else max(h, w)
    return interpolate(ratios(noisy, out, b, clamp), h, w, b)


VECTORS = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "keep_mean_vectors.json"


def vector_cases():
    """Sizes, block sizes (global included), LDR, black and firefly blocks; values are short
    decimals both sides read exactly as float32."""
    rng = np.random.default_rng(15)
    out = []
    for name, h, w, block, clamp, ldr in [("random_23x37_b8", 23, 37, 8, 4.0, False),
                                          ("global_9x13", 9, 13, 0, 4.0, False),
                                          ("ldr_16x16_b4", 16, 16, 4, 2.0, True),
                                          ("one_pixel", 1, 1, 32, 4.0, False),
                                          ("hard_20x12_b5", 20, 12, 5, 4.0, False),
                                          ("stage_70x20", 20, 70, "stage", 0.0, False)]:
        noisy = np.round(2.0 * rng.random((h, w, 3)) ** 2, 4)
        den = np.round(noisy * rng.uniform(0.5, 1.5, (h, w, 3)), 4)
        if ldr:
            noisy, den = noisy.clip(0, 1), den.clip(0, 1)
        if name.startswith("hard"):
            den[:5, :5] = 0.0          # a black output block
            noisy[12, 3] = [900.0, 40.0, 0.0]  # a firefly the filter dropped
            noisy[15:, 7:] = 0.0       # black input under a lit output
            noisy[2, 9] = [LINEAR_MAX, LINEAR_MAX, 3.0]  # an Inf the sanitiser capped
        if block == "stage":  # the core's two passes (a dim output: the global pass acts)
            den = np.round(0.1 * den, 4)
            want = stage(den.astype(np.float32), noisy.astype(np.float32)).astype(np.float64)
        else:
            want = np.clip(apply(den, factors(den, noisy, block, clamp)), 0.0, 1.0 if ldr else LINEAR_MAX)
        out.append(dict(name=name, w=w, h=h, block=block, clamp=clamp, ldr=ldr,
                        input=noisy.ravel().tolist(), output=den.ravel().tolist(),
                        want=[float(f"{v:.9g}") for v in want.ravel()]))
    # The stage's own BLOCK: the left part darkened, the right brightened, so each block's
    # factor differs and the result pins the block size the two sides use.
    h, w = 24, 3 * BLOCK // 2
    noisy = np.round(2.0 * rng.random((h, w, 3)) ** 2, 4)
    den = np.round(noisy * np.where(np.arange(w) < w // 3, 0.7, 1.2)[None, :, None], 4)
    want = stage(den.astype(np.float32), noisy.astype(np.float32)).astype(np.float64)
    out.append(dict(name=f"stage_{w}x{h}_halves", w=w, h=h, block="stage", clamp=0.0, ldr=False,
                    input=noisy.ravel().tolist(), output=den.ravel().tolist(),
                    want=[float(f"{v:.9g}") for v in want.ravel()]))
    # A lamp the output dimmed (its own factor) beside a lone high sample (no lamp), on
    # noise: the lamps' set, its grown sum and factor, then the blocks.
    h, w = 40, 48
    noisy = np.round(rng.random((h, w, 3)) ** 2, 4)
    den = np.round(noisy * rng.uniform(0.8, 1.2, (h, w, 3)), 4)
    noisy[12:15, 30:33] = [300.0, 250.0, 120.0]
    den[12:15, 30:33] = [240.0, 230.0, 90.0]
    noisy[30, 8] = [300.0, 300.0, 300.0]
    den[30, 8] = [4.0, 4.0, 4.0]
    want = stage(den.astype(np.float32), noisy.astype(np.float32)).astype(np.float64)
    out.append(dict(name=f"stage_{w}x{h}_lamp", w=w, h=h, block="stage", clamp=0.0, ldr=False,
                    input=noisy.ravel().tolist(), output=den.ravel().tolist(),
                    want=[float(f"{v:.9g}") for v in want.ravel()]))
    return out
