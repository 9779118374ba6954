"""The reconstruction of docs/reconstruction.md in PyTorch: the network's per-pixel filter
logits, applied to linear radiance, differentiably, on NCHW batches.

The Rust core (src/reconstruct.rs) runs the same function at inference; the vectors this
module writes (temc_train.vectors.recon_vectors -> tests/data/recon_vectors.json) keep the two
within 1e-5. Non-finite logits: NaN -> 0, everything clamped to +-LOGIT_MAX, in both.
"""

import math

import numpy as np
import torch
import torch.nn.functional as F

from . import color
from .keep_mean import stage as keep_mean_stage

LINEAR_MAX = 65504.0
LUMA = (0.2126, 0.7152, 0.0722)
LOGIT_MAX = 1e4
MIN_CHROMA_LUMA = 1e-30
GREY_PULL = 1e-6
# The fixed range term (docs/reconstruction.md, "Fixed range term"): log2 luminance steps
# beyond RANGE_TAU (8x) are penalised; RANGE_FLOOR, at the exposure that puts the image's
# log-mean at 0.18, keeps noise in the dark from reading as edges.
RANGE_TAU = 3.0
RANGE_FLOOR = 0.02
# The threshold from local noise (docs/reconstruction.md, "Range threshold from local
# noise"): with `temc.range_noise` = K > 0 each pixel's threshold is min(RANGE_TAU, K * n),
# n the mean over the RANGE_NOISE_BOX^2 window of |Y - median3(Y)| / (median3(Y) +
# RANGE_FLOOR) at the exposure: where the image is clean, smaller steps count as edges.
RANGE_NOISE_BOX = 7
# The aux-guided opening (docs/reconstruction.md, "Aux-guided opening"): two pixels lie on
# one surface when the L1 distance of their aux planes is at most AUX_SAME; a pixel alone
# on its surface among its 3x3 neighbours counts as a feature only with an emitter's albedo
# (every albedo channel at least EMITTER_ALBEDO: temc-render writes 1 for emitters, Cycles
# their emission, clamped to 1 by the aux encoding).
AUX_SAME = 0.3
EMITTER_ALBEDO = 0.95
RANGE_OPENINGS = ("plain", "aux")
# The coarse clamp (docs/reconstruction.md, step 4): a coarse level's correction adds at most
# COARSE_GAIN times the finer level's own value, so a firefly a coarse level spreads cannot
# raise its dark surroundings into a block (keep-mean returns what it holds back). With
# `temc.coarse_gain` and `temc.coarse_radius` a model names its own gain and caps against
# the mean of the fine values over a (2 radius + 1)^2 window instead of the pixel's own
# (docs/reconstruction.md, "The coarse cap against a local mean").
COARSE_GAIN = 1.0
COARSE_RADIUS_MAX = 8
# With `temc.coarse_sparse` = T > 0 the cap rises where a level is sparse: times
# max(1, T / max(d, COARSE_SPARSE_FLOOR)), d the share of the window's pixels whose input
# luminance at that level is above 0. Where most pixels are black because few paths found
# light, the black ones are holes between samples, not a firefly's dark surroundings
# (docs/reconstruction.md, "The coarse cap where samples are sparse"). The floor bounds the
# rise at T / COARSE_SPARSE_FLOOR.
COARSE_SPARSE_FLOOR = 0.1
# The chroma composition's common cap (docs/reconstruction.md, step 4): a coarse correction
# leaves every channel at least CHROMA_KEEP of its fine value; CHROMA_EPS keeps the cap's
# ratio finite where a channel has neither value nor correction (the cap is then 1).
CHROMA_KEEP = 0.5
CHROMA_EPS = 1e-12


def channels(kernel, guide=False):
    """Logit channels per level: a luma and a chroma kernel, two blend logits, and with
    `guide` a luma and a chroma guide."""
    return 2 * kernel * kernel + (4 if guide else 2)


def reach(levels, kernel, upsample="nearest"):
    """A bound on the pixels reached from the centre: level-l taps are 2^l apart and cover
    2^l pixels (the sum over levels; the coarsest level alone reaches (r + 1) 2^(L-1) - 1);
    bilinear composition reads one coarsest pixel more, 2^(L-1) - 1 (measured:
    tests/test_reconstruct.py)."""
    blend = 2 ** (levels - 1) - 1 if upsample == "bilinear" else 0
    return (kernel // 2) * (2**levels - 1) + 2 ** (levels - 1) - 1 + blend


def _lum(x):
    return LUMA[0] * x[:, 0:1] + LUMA[1] * x[:, 1:2] + LUMA[2] * x[:, 2:3]


def _clean(logits):
    """NaN -> 0 and a clamp to +-LOGIT_MAX, so the softmax and sigmoid stay finite."""
    return torch.nan_to_num(logits, nan=0.0, posinf=LOGIT_MAX, neginf=-LOGIT_MAX).clamp(
        -LOGIT_MAX, LOGIT_MAX
    )


def _inside(kernel, h, w, like):
    """[1, k^2, H, W] mask of the taps that lie inside the level image."""
    ones = torch.ones(1, 1, h, w, dtype=like.dtype, device=like.device)
    return F.unfold(ones, kernel, padding=kernel // 2).view(1, kernel * kernel, h, w) > 0.5


def _apply(x, weights, kernel):
    """sum_t weights[:, t] * x(p + tap t): unfold's zero padding meets zero weights."""
    n, c, h, w = x.shape
    taps = F.unfold(x, kernel, padding=kernel // 2).view(n, c, kernel * kernel, h, w)
    return (taps * weights.unsqueeze(1)).sum(2)


def _range_term(guide, kernel):
    """-(g(p + t) - g(p))^2 / 2 per tap t: the guide's learned range term (a cross-bilateral
    on a predicted feature), so rejecting a tap across an edge -- a lamp beside a dark
    ceiling -- takes one feature difference, not a learned logit per tap."""
    n, _, h, w = guide.shape
    taps = F.unfold(guide, kernel, padding=kernel // 2).view(n, kernel * kernel, h, w)
    return -0.5 * (taps - guide) ** 2


def opened(y):
    """The 3x3 grey opening (min, then max, over the taps inside) of a luminance plane:
    bright features smaller than 3x3 (fireflies, noise) drop to their surroundings, larger
    ones (lamps) stay with their edges exact."""
    pad = lambda v: F.pad(v, (1, 1, 1, 1), mode="replicate")  # noqa: E731 (= taps inside)
    eroded = -F.max_pool2d(pad(-y), 3, stride=1)
    return F.max_pool2d(pad(eroded), 3, stride=1)


def _taps3(v):
    """[N, C, 9, H, W]: each pixel's 3x3 window, edges replicated (= the taps inside, for
    a min or a max)."""
    n, c, h, w = v.shape
    return F.unfold(F.pad(v, (1, 1, 1, 1), mode="replicate"), 3).view(n, c, 9, h, w)


def aux_opened(y, aux):
    """The 3x3 grey opening of luminance `y` [N, 1, H, W] over each pixel's neighbours on
    its own surface (aux planes within AUX_SAME, L1; `aux` is the network's [N, 7, H, W],
    albedo first): a small lamp the aux buffers outline keeps its value, a firefly on a
    surface drops to that surface. A pixel with no neighbour on its surface (a texel, a
    silhouette's tip) is linked to all its neighbours, and they to it, unless its albedo is
    an emitter's. Erosion and dilation over one symmetric relation: an opening (idempotent,
    never above `y`)."""
    aux = aux.to(y.dtype)
    same = (_taps3(aux) - aux[:, :, None]).abs().sum(1) <= AUX_SAME
    inside = _inside(3, y.shape[2], y.shape[3], y)  # replicated taps repeat inside ones
    alone = (same & inside).sum(1, keepdim=True) <= 1
    loose = (alone & (aux[:, :3].amin(1, keepdim=True) < EMITTER_ALBEDO)).to(y.dtype)
    same = same | (loose > 0) | (_taps3(loose)[:, 0] > 0)
    big = torch.finfo(y.dtype).max
    eroded = torch.where(same, _taps3(y)[:, 0], big).amin(1, keepdim=True)
    return torch.where(same, _taps3(eroded)[:, 0], -big).amax(1, keepdim=True)


def range_planes(x, levels, aux=None):
    """The fixed range term's opened luminance of radiance `x` per level: with `aux`,
    aux_opened at full resolution and its 2x2 means below (a lamp the fine level keeps stays
    a feature at every level); without, None (each level opens its own luminance)."""
    if aux is None:
        return [None] * levels
    o = aux_opened(_lum(x).detach(), aux.detach())
    out = [o]
    for _ in range(levels - 1):
        out.append(F.avg_pool2d(out[-1], 2))
    return out


# Paeth's 19 compare-exchanges that leave the median of nine values in the middle place.
_MEDIAN9 = ((1, 2), (4, 5), (7, 8), (0, 1), (3, 4), (6, 7), (1, 2), (4, 5), (7, 8), (0, 3),
            (5, 8), (4, 7), (3, 6), (1, 4), (2, 5), (4, 7), (4, 2), (6, 4), (4, 2))


def median9(taps):
    """[N, 9, H, W] -> [N, 1, H, W]: the median of the nine values per pixel, the value
    torch.median gives, by a sorting network of minima and maxima: torch.median over a
    dim of nine took 5 % of a training step on the CPU (docs/reconstruction.md)."""
    p = list(taps.unbind(1))
    for a, b in _MEDIAN9:
        p[a], p[b] = torch.minimum(p[a], p[b]), torch.maximum(p[a], p[b])
    return p[4].unsqueeze(1)


def range_threshold(y, scale=1.0, noise=0.0):
    """The fixed range term's threshold in stops per pixel, [N, 1, H, W] (or RANGE_TAU when
    `noise` is 0): min(RANGE_TAU, noise * n), n the RANGE_NOISE_BOX^2 mean (edges
    replicated) of the relative deviation |Y - median3(Y)| / (median3(Y) + RANGE_FLOOR) of
    luminance `y` at the exposure `scale`. A clean region (n near 0) treats a 2x step, a
    shadow's edge, as an edge; a noisy one keeps RANGE_TAU, so noise never does."""
    if not noise:
        return RANGE_TAU
    v = y.clamp(min=0.0) * scale
    med = median9(_taps3(v)[:, 0])
    rel = (v - med).abs() / (med + RANGE_FLOOR)
    return (noise * _box_mean(rel, RANGE_NOISE_BOX // 2)).clamp(max=RANGE_TAU)


def fixed_range_term(y, kernel, scale=1.0, opened_y=None, noise=0.0):
    """-(max(0, |g(p + t) - g(p)| - tau(p)))^2 / 2 per tap t, g = log2 of the opened
    luminance at the exposure `scale` plus RANGE_FLOOR: a tap more than 2^tau times
    brighter or darker than the centre, in a feature of 3x3 px or more, falls off whatever
    the learned logits say (a lamp 1000x its ceiling weighs e^-24.5 there at tau =
    RANGE_TAU); fireflies, gone from the opening, still spread. tau is range_threshold
    (RANGE_TAU unless `noise`, `temc.range_noise`, is set). `opened_y`: the opening to use
    (range_planes), else the plain opening of `y`. Fixed, not learned: no gradient flows."""
    n, _, h, w = y.shape
    o = opened(y.detach()) if opened_y is None else opened_y.detach()
    g = torch.log2(o.clamp(min=0.0) * scale + RANGE_FLOOR)
    taps = F.unfold(g, kernel, padding=kernel // 2).view(n, kernel * kernel, h, w)
    excess = ((taps - g).abs() - range_threshold(y.detach(), scale, noise)).clamp(min=0.0)
    return -0.5 * excess * excess


def level_weights(x, logits, kernel, guide=False, fixed_range=False, scale=1.0, opened_y=None,
                  noise=0.0):
    """(luma weights, chroma weights, luminance, cleaned logits) of one level: the softmax
    over the taps inside, [N, k^2, H, W] each, and the luminance plane the luma weights
    filter. `opened_y`, `noise`: the fixed range term's opening and noise factor
    (fixed_range_term)."""
    kk = kernel * kernel
    logits = _clean(logits)
    outside = ~_inside(kernel, x.shape[2], x.shape[3], x)
    luma_l, chroma_l = logits[:, :kk], logits[:, kk : 2 * kk]
    if guide:
        luma_l = luma_l + _range_term(logits[:, 2 * kk + 2 : 2 * kk + 3], kernel)
        chroma_l = chroma_l + _range_term(logits[:, 2 * kk + 3 : 2 * kk + 4], kernel)
    y = _lum(x)
    if fixed_range:
        term = fixed_range_term(y, kernel, scale, opened_y, noise)
        luma_l, chroma_l = luma_l + term, chroma_l + term
    luma_w = torch.softmax(luma_l.masked_fill(outside, float("-inf")), dim=1)
    chroma_w = torch.softmax(chroma_l.masked_fill(outside, float("-inf")), dim=1)
    return luma_w, chroma_w, y, logits


def _filter_level(x, logits, kernel, guide=False, fixed_range=False, scale=1.0, opened_y=None,
                  noise=0.0):
    """(fy, fc, luma blend logit, chroma blend logit) of one level."""
    kk = kernel * kernel
    luma_w, chroma_w, y, logits = level_weights(x, logits, kernel, guide, fixed_range, scale,
                                                opened_y, noise)
    fy = _apply(y, luma_w, kernel)
    fc = _apply(x, chroma_w, kernel)
    return fy, fc, logits[:, 2 * kk : 2 * kk + 1], logits[:, 2 * kk + 1 : 2 * kk + 2]


UPSAMPLES = ("nearest", "bilinear")


def _up(x, upsample="nearest"):
    """2x upsampling: `nearest` repeats a coarse pixel over its 2x2 block; `bilinear` weighs
    the two nearest coarse pixels per axis 3/4 and 1/4 (half-pixel centres, edges
    replicated), so each coarse pixel still hands on exactly four fine pixels' worth."""
    if upsample == "bilinear":
        return F.interpolate(x, scale_factor=2, mode="bilinear", align_corners=False)
    if upsample != "nearest":
        raise ValueError(f"upsample must be one of {UPSAMPLES}, got {upsample!r}")
    return x.repeat_interleave(2, dim=2).repeat_interleave(2, dim=3)


def _compose(fine, coarse, blend, upsample="nearest", clamp=None):
    """Vogels et al. 2018: the fine level's detail plus the coarse level's low frequencies.
    The correction, not each term, is upsampled: with `bilinear` the coarse level's blocks
    no longer show as 2x2 steps in flat regions (docs/reconstruction.md, step 4). `clamp`
    (gain, radius, rise), or None: the correction is capped (_cap)."""
    return fine + _correction(fine, coarse, blend, upsample, clamp)


def _cap(fine, gain, radius, rise=None):
    """What a coarse correction may add: `gain` times the fine value (clamped at 0), or
    with `radius` > 0 times its (2 radius + 1)^2 mean, edges replicated; times `rise`
    (sparse_rise) where given. The mean lets a coarse level fill a sparse 1-spp-like dark
    pixel beside lit ones, which its own value would hold at black, while a firefly's dark
    surroundings stay capped."""
    f = fine.clamp(min=0.0)
    cap = gain * (_box_mean(f, radius) if radius else f)
    return cap if rise is None else cap * rise


def _box_mean(x, radius):
    """The (2 radius + 1)^2 mean around each pixel, edges replicated."""
    return F.avg_pool2d(F.pad(x, (radius,) * 4, mode="replicate"), 2 * radius + 1, stride=1)


def sparse_rise(x, radius, share):
    """[N, 1, H, W] factor on the coarse cap at one level (`temc.coarse_sparse` = `share`):
    max(1, share / max(d, COARSE_SPARSE_FLOOR)), d the share of the (2 radius + 1)^2
    window's pixels (edges replicated) whose luminance in `x` (the level's input) is above
    0. A constant of the input: no gradient flows through it."""
    lit = (_lum(x) > 0).to(x.dtype)
    return (share / _box_mean(lit, radius).clamp(min=COARSE_SPARSE_FLOOR)).clamp(min=1.0)


def _correction(fine, coarse, blend, upsample, clamp):
    """sigmoid(blend) * U(coarse - D(fine)), capped by _cap(fine, *clamp) unless `clamp` is
    None."""
    c = _up(coarse - F.avg_pool2d(fine, 2), upsample)
    if clamp is not None:
        c = torch.minimum(c, _cap(fine, *clamp))
    return torch.sigmoid(blend) * c


def _compose_chroma(fine, coarse, blend, upsample="nearest", clamp=None):
    """_compose for the chroma filter's 3 channels, with the correction scaled down per pixel,
    all channels alike, until no channel falls below CHROMA_KEEP of its fine value. A
    correction that drove red and green negative but not blue was clamped channel by channel
    in _recombine, and a warm pixel beside a bright object came out pure blue
    (docs/reconstruction.md, step 4)."""
    d = _correction(fine, coarse, blend, upsample, clamp)
    room = (1.0 - CHROMA_KEEP) * fine.clamp(min=0.0)
    need = (-d).clamp(min=0.0)
    share = (room + CHROMA_EPS) / (torch.maximum(need, room) + CHROMA_EPS)
    return fine + d * share.amin(dim=1, keepdim=True)


def _recombine(cy, cc):
    """The chroma filter's colour at the luma filter's luminance, pulled toward grey where the
    chroma result is darker than GREY_PULL of the luminance (docs/reconstruction.md step 5).
    The pull bounds d out / d cc by 1 / GREY_PULL: a plain c * y / yc has gradients of
    y / yc^2, which overflow float32 (and went NaN in a 3-level run) once yc < ~1e-19."""
    c = cc.clamp(min=0.0)
    y = cy.clamp(min=0.0)
    pull = GREY_PULL * y
    scale = y / (_lum(c) + pull + MIN_CHROMA_LUMA)
    return (c + pull) * scale


def reconstruct(rgb, albedo, filters, kernel, demodulate=False, eps=0.01, ldr=False, guide=False,
                fixed_range=False, scale=1.0, upsample="nearest", range_opening="plain", aux=None,
                coarse_clamp=False, range_noise=0.0, coarse_gain=COARSE_GAIN, coarse_radius=0,
                coarse_sparse=0.0):
    """[N, 3, H, W] reconstruction of linear `rgb` from `filters[l]`
    [N, channels(kernel, guide), H / 2^l, W / 2^l]; `albedo` is read only when demodulating.
    `fixed_range`: add fixed_range_term at every level; `scale` (a number or [N, 1, 1, 1])
    the exposure that puts `rgb` at a log-mean near 0.18 (1 for training crops, which come
    scaled), read only by that term. `upsample`: how the composition brings a coarse
    level's correction to the finer one (UPSAMPLES; `temc.upsample`). `range_opening`
    (RANGE_OPENINGS; `temc.range_opening`): `aux` opens the fixed range term's luminance
    with aux_opened on `aux` (the network's [N, 7, H, W] aux planes), `plain` per level.
    `coarse_clamp` (`temc.coarse_clamp`): cap each coarse correction at `coarse_gain`
    (`temc.coarse_gain`) times the fine value, or with `coarse_radius` (`temc.coarse_radius`)
    times its local mean (_cap), and with `coarse_sparse` (`temc.coarse_sparse`) raised where
    the level is sparse (sparse_rise).
    `range_noise` (`temc.range_noise`): the fixed range term's threshold from local noise
    (range_threshold; 0: RANGE_TAU everywhere)."""
    if range_opening not in RANGE_OPENINGS:
        raise ValueError(f"range_opening must be one of {RANGE_OPENINGS}, got {range_opening!r}")
    if coarse_clamp and not (coarse_gain > 0 and math.isfinite(coarse_gain)
                             and 0 <= coarse_radius <= COARSE_RADIUS_MAX
                             and coarse_radius == int(coarse_radius)):
        raise ValueError(f"coarse_gain must be finite and > 0 and coarse_radius an integer in "
                         f"0..={COARSE_RADIUS_MAX}, got {coarse_gain!r}, {coarse_radius!r}")
    if not 0.0 <= coarse_sparse <= 1.0:  # also refuses NaN
        raise ValueError(f"coarse_sparse must be in [0, 1], got {coarse_sparse!r}")
    for level, f in enumerate(filters):
        want = (rgb.shape[0], channels(kernel, guide), rgb.shape[2] >> level, rgb.shape[3] >> level)
        if tuple(f.shape) != want:
            raise ValueError(f"filters[{level}] has shape {tuple(f.shape)}, expected {want}")
    d = albedo + eps if demodulate else None
    x = rgb / d if demodulate else rgb
    guided = fixed_range and range_opening == "aux"
    if guided and aux is None:
        raise ValueError("range_opening 'aux' needs the aux planes")
    opened_ys = range_planes(x, len(filters), aux if guided else None)
    levels, rises = [], []
    sparse = coarse_clamp and coarse_sparse > 0
    for level, f in enumerate(filters):
        if level:
            x = F.avg_pool2d(x, 2)
        levels.append(_filter_level(x, f, kernel, guide, fixed_range, scale, opened_ys[level],
                                    range_noise))
        rises.append(sparse_rise(x, int(coarse_radius), coarse_sparse)
                     if sparse and level < len(filters) - 1 else None)
    cy, cc = levels[-1][:2]
    for (fy, fc, a, b), rise in reversed(list(zip(levels[:-1], rises))):
        clamp = (coarse_gain, int(coarse_radius), rise) if coarse_clamp else None
        cy = _compose(fy, cy, a, upsample, clamp)
        cc = _compose_chroma(fc, cc, b, upsample, clamp)
    out = _recombine(cy, cc)
    if demodulate:
        out = out * d
    out = torch.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0)
    return out.clamp(0.0, 1.0 if ldr else LINEAR_MAX)


def options(recon: dict) -> dict:
    """reconstruct's keyword settings from a recon dict (a checkpoint's or a model's; each
    absent key at its default): the one place that maps the two, so a new setting is
    threaded once."""
    return {"guide": recon.get("guide", False), "fixed_range": recon.get("fixed_range", False),
            "upsample": recon.get("upsample", "nearest"),
            "range_opening": recon.get("range_opening", "plain"),
            "coarse_clamp": recon.get("coarse_clamp", False),
            "range_noise": recon.get("range_noise", 0.0),
            "coarse_gain": recon.get("coarse_gain", COARSE_GAIN),
            "coarse_sparse": recon.get("coarse_sparse", 0.0),
            "coarse_radius": recon.get("coarse_radius", 0)}


@torch.no_grad()
def denoise_image(model, recon: dict, noisy: np.ndarray, aux: np.ndarray, scale: float,
                  keep: bool = True) -> np.ndarray:
    """A whole image as the core denoises it: `noisy` linear [H, W, 3], `aux` the network's
    aux planes [H, W, 7] (color.aux_channels, moved last), `scale` the input scale; the
    image is mirror-padded to the alignment (32) and the result cropped back, then (with
    `keep`, as the core does) rescaled by the keep-mean stage. Returns [H, W, 3] linear."""
    return denoise_variants(model, [recon], noisy, aux, scale, keep)[0]


@torch.no_grad()
def denoise_variants(model, recons: list, noisy: np.ndarray, aux: np.ndarray, scale: float,
                     keep: bool = True) -> list:
    """denoise_image under each reconstruction setting of `recons`, the network run once
    (for probes that compare fixed functions without retraining)."""
    hsv, _ = color.encode(noisy, scale)
    h, w = noisy.shape[:2]
    pad = ((0, (-h) % 32), (0, (-w) % 32), (0, 0))

    def planes(x):
        return torch.from_numpy(np.moveaxis(np.pad(x, pad, mode="reflect"), -1, 0)[None].copy())

    hsv_t, aux_t = planes(hsv), planes(aux.astype(np.float32))
    radiance = color.sanitize_rgb(noisy).astype(np.float32)
    filters = model.eval()(hsv_t[:, :2], hsv_t[:, 2:], aux_t)
    outs = []
    for recon in recons:
        out = reconstruct(planes(radiance), aux_t[:, :3], filters, recon["kernel"],
                          recon["demodulate"], recon["eps"], scale=scale, aux=aux_t,
                          **options(recon))
        out = np.moveaxis(out[0].numpy(), 0, -1)[:h, :w]
        outs.append(keep_mean_stage(out, radiance) if keep else out)
    return outs
