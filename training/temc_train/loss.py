"""The paper's training loss: Zhao et al. 2017's mix of MS-SSIM and L1.

    L = alpha * (1 - MS-SSIM) + (1 - alpha) * G_sigmaM * |x - y|,  alpha = 0.84

in the multi-sigma, full-resolution form (architecture note §4.1): five Gaussian windows
sigma = 0.5, 1, 2, 4, 8 at the same resolution, the luminance term at the largest sigma
only, contrast-structure terms multiplied over all five, and the L1 term weighted by the
largest Gaussian. Downsampling MS-SSIM needs images over 160 px a side; this form works on
the paper's 128x128 crops (and on anything down to 1x1, by replicate padding).
Computed per channel on [0,1] images, then averaged: temc takes it on the PQ R'G'B' of the
reconstructed linear output (`training_loss`).
"""

import functools

import torch
import torch.nn.functional as F

from . import color

SIGMAS = (0.5, 1.0, 2.0, 4.0, 8.0)
ALPHA = 0.84
C1 = 0.01 ** 2
C2 = 0.03 ** 2
RADIUS = int(2 * max(SIGMAS))  # kernel size 4 * sigma_max + 1 = 33


def _kernels(device, dtype) -> torch.Tensor:
    """[S, K] normalised 1-D Gaussians, one per sigma (the 2-D windows are separable)."""
    r = torch.arange(-RADIUS, RADIUS + 1, device=device, dtype=dtype)
    g = torch.exp(-0.5 * (r[None] / torch.tensor(SIGMAS, device=device, dtype=dtype)[:, None]) ** 2)
    return g / g.sum(dim=1, keepdim=True)


@functools.lru_cache(maxsize=16)
def _blur_matrix(n: int, device, dtype) -> torch.Tensor:
    """[S, n, n]: row i holds output i's taps of each window over the n inputs, with the
    replicate padding folded in (a tap past the border reads the border pixel)."""
    k = _kernels(device, dtype)
    s, taps = k.shape
    idx = (torch.arange(n, device=device)[:, None] + torch.arange(taps, device=device)[None]
           - RADIUS).clamp(0, n - 1)
    m = torch.zeros(s, n, n, device=device, dtype=dtype)
    m.scatter_add_(2, idx[None].expand(s, n, taps), k[:, None, :].expand(s, n, taps).contiguous())
    return m


def _blur(x: torch.Tensor, which: slice = slice(None)) -> torch.Tensor:
    """x [B, 1, H, W] blurred by the windows `which` of SIGMAS: [B, S, H, W]. Separable,
    as matrix products: exactly the 1-D convolutions with replicate padding (which keeps
    the borders of small crops from reading as dark edges), 4x faster on a CPU than conv2d
    with these shapes, where this loss took 60 % of a training step. Each pass is one
    large product rather than one per plane and window (broadcasting x against the
    windows copied it S times): along rows by every window at once, then along columns
    by each window on its own (docs/reconstruction.md, "two training functions")."""
    b, _, h, w = x.shape
    mh = _blur_matrix(h, x.device, x.dtype)[which]
    mw = _blur_matrix(w, x.device, x.dtype)[which]
    s = mh.shape[0]
    rows = x.reshape(b * h, w) @ mw.reshape(s * w, w).t()  # [B*H, S*W]
    rows = rows.view(b, h, s, w).permute(2, 1, 0, 3).reshape(s, h, b * w)
    return torch.bmm(mh, rows).view(s, h, b, w).permute(2, 0, 1, 3)


def mix_loss(pred: torch.Tensor, target: torch.Tensor, alpha: float = ALPHA) -> torch.Tensor:
    """The mean L_mix over batch, channels and pixels of two [N, C, H, W] tensors."""
    if pred.shape != target.shape:
        raise ValueError(f"shape mismatch {tuple(pred.shape)} vs {tuple(target.shape)}")
    n, c, h, w = pred.shape
    b = n * c  # per channel: every channel is its own grey image
    x = pred.reshape(b, 1, h, w)
    y = target.reshape(b, 1, h, w)
    # One blur call for the five local moments.
    m = _blur(torch.cat([x, y, x * x, y * y, x * y])).split(b)
    mx, my = m[0], m[1]
    sxx = m[2] - mx * mx
    syy = m[3] - my * my
    sxy = m[4] - mx * my
    cs = (2 * sxy + C2) / (sxx + syy + C2)
    lum = (2 * mx[:, -1] * my[:, -1] + C1) / (mx[:, -1] ** 2 + my[:, -1] ** 2 + C1)
    ms_ssim = lum * cs.prod(dim=1)
    l1 = _blur((x - y).abs(), slice(-1, None))[:, 0]  # G_sigmaM-weighted L1
    return (alpha * (1 - ms_ssim) + (1 - alpha) * l1).mean()


PQ_FLOOR = 1e-10


def pq(rgb: torch.Tensor, nits_per_unit: float = color.NITS_PER_UNIT,
       floor: float = PQ_FLOOR) -> torch.Tensor:
    """Linear values (already times the exposure) -> PQ code values in [0, 1], as the core
    encodes them (contract §1 steps 3-5; values past 10000 cd/m2 clip). The floor keeps the
    gradient of y^m1 finite at black; metrics, which need no gradient, pass 0."""
    y = torch.clamp(rgb * (nits_per_unit / color.PQ_MAX_NITS), floor, 1.0)
    ym = y ** color.M1
    return ((color.C1 + color.C2 * ym) / (1.0 + color.C3 * ym)) ** color.M2


# Linear BT.709 -> the LMS of BT.2100 ICtCp (BT.709 -> BT.2020 by BT.2087, then BT.2100's
# LMS matrix), and PQ L'M'S' -> I, Ct, Cp.
_RGB709_TO_LMS = (torch.tensor([[1688, 2146, 262], [683, 2951, 462], [99, 309, 3688]],
                               dtype=torch.float64) / 4096.0
                  @ torch.tensor([[0.6274039, 0.3292830, 0.0433131],
                                  [0.0690973, 0.9195404, 0.0113623],
                                  [0.0163914, 0.0880133, 0.8955953]], dtype=torch.float64))
_LMS_TO_ICTCP = torch.tensor([[2048, 2048, 0], [6610, -13613, 7003], [17933, -17390, -543]],
                             dtype=torch.float64) / 4096.0


def ictcp(rgb: torch.Tensor, floor: float = PQ_FLOOR) -> torch.Tensor:
    """Linear BT.709 values (times the exposure), channels on dim 1 -> ICtCp on dim 1, as
    ITU-R BT.2100 defines it at 100 cd/m2 per unit: the one home of the colour space of
    the Delta E ITP metric (evaluate.delta_e_itp) and of the chroma term."""
    m = _RGB709_TO_LMS.to(rgb)
    lms = torch.einsum("ij,nj...->ni...", m, rgb)
    return torch.einsum("ij,nj...->ni...", _LMS_TO_ICTCP.to(rgb), pq(lms, floor=floor))


CHROMA_EPS = 1e-10  # keeps the square root's gradient finite where the chroma matches


def chroma_error(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """mean sqrt((dCt / 2)^2 + dCp^2) over pixels: Delta E ITP (BT.2124) without its
    intensity axis and its factor 720, which the mix loss on R'G'B' already covers. The
    worst-pixel term pulls a kept firefly down in every channel alike and costs colour
    (1-3 % more Delta E ITP per cycle on the Cycles family, docs/reconstruction.md); this
    term charges the hue and saturation it moves."""
    d = ictcp(pred) - ictcp(target)
    return ((0.5 * d[:, 1]) ** 2 + d[:, 2] ** 2 + CHROMA_EPS).sqrt().mean()


REL_EPS = 0.01  # the RelMSE metric's epsilon (evaluate.EPS)


def relative_l1(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """mean |x - r| / (|r| + 0.01) on linear values: the error RelMSE measures, without its
    square. A filter that leaks a lamp into the dark ceiling beside it costs little on PQ
    (a few pixels) and a lot here."""
    return ((pred - target).abs() / (target.abs() + REL_EPS)).mean()


N2N_EPS = 0.01


def noise2noise_loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Lehtinen et al. 2018's HDR loss for noisy targets: (x - t)^2 / (sg(x) + 0.01)^2 on
    linear values. Squared error is minimised by the target's mean, so a zero-mean noisy
    target trains towards the clean image; the denominator (no gradient through it) makes
    it relative, as RelMSE is. A PQ loss is not: its minimiser under noise is biased."""
    d = pred.detach().abs() + N2N_EPS
    return (((pred - target) / d) ** 2).mean()


MEAN_BLOCK = 16


def block_mean_error(pred: torch.Tensor, target: torch.Tensor, block: int = MEAN_BLOCK) -> torch.Tensor:
    """mean |D(x) - D(r)| / (D(r) + 0.01) over the block means D (block x block, per
    channel) of linear values: the energy a filter keeps or drops, blind to where inside a
    block it goes. The PQ mix loss barely sees a filter that leaves out a scene's rare bright
    samples (the balanced model kept 41 % of the dark room's energy at 256 spp, before the
    keep-mean stage); this term does. Blocks at the far edges may be partial."""
    k = max(1, min(block, pred.shape[-2], pred.shape[-1]))
    dp = F.avg_pool2d(pred, k, ceil_mode=True)
    dt = F.avg_pool2d(target, k, ceil_mode=True)
    return ((dp - dt).abs() / (dt.abs() + REL_EPS)).mean()


DARK_BLOCK = 8
DARK_FLOOR = 0.01


def block_log_error(pred: torch.Tensor, target: torch.Tensor, block: int = DARK_BLOCK,
                    floor: float = DARK_FLOOR) -> torch.Tensor:
    """mean |log(D(x) + f) - log(D(r) + f)| over block means D of linear values: the
    energy term in ratios. `block_mean_error` charges a block darkened to a quarter of its
    reference 0.75 and one brightened to four times 3.0; this term charges both log 4.
    Tried against the darkened dark regions of the Cycles family (docs/keep-mean.md): at
    weight 0.2 it barely lifted them and cost RelMSE, because the learned guides, not the
    loss's lean, take their light; off by default. Blocks after the automatic exposure are
    about 0.05-0.3, well above the floor."""
    k = max(1, min(block, pred.shape[-2], pred.shape[-1]))
    dp = F.avg_pool2d(pred, k, ceil_mode=True).clamp_min(0.0)
    dt = F.avg_pool2d(target, k, ceil_mode=True).clamp_min(0.0)
    return (torch.log(dp + floor) - torch.log(dt + floor)).abs().mean()


WORST_SHARE = 0.002  # ~33 of a 128x128 crop's 16,384 pixels


def worst_pixel_error(pred_pq: torch.Tensor, target_pq: torch.Tensor,
                      share: float = WORST_SHARE) -> torch.Tensor:
    """The mean PQ excess (how far a pixel comes out brighter than its reference, channels
    averaged) of each image's worst `share` of pixels, over the batch: hard-example mining
    on the pixels that dominate RelMSE. A firefly the network keeps whole holds most of some
    Cycles images' 4-spp RelMSE (docs/firefly-probe.md), a lamp's leak into a dark ceiling
    much of others'; the mix loss weighs either at a pixel's share of the crop. One-sided,
    so a firefly in a 512-spp reference, which no input predicts, is not chased; bounded
    like PQ (at most 1), unlike the relative L1, so a kept lamp cannot swamp it."""
    err = (pred_pq - target_pq).mean(dim=1).clamp_min(0.0).flatten(1)
    k = max(1, round(share * err.shape[1]))
    return err.topk(k, dim=1).values.mean()


WORST_AXES = ("rgb", "intensity")


def worst_intensity_error(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """`worst_pixel_error` on ICtCp's intensity I (linear inputs): the worst pixels' excess
    brightness as Delta E ITP's intensity axis reads it. The R'G'B' version pulls every
    channel of a kept firefly down by the same PQ step, which moves its hue; this one
    charges brightness alone and leaves the colour to the chroma term."""
    return worst_pixel_error(ictcp(pred)[:, :1], ictcp(target)[:, :1])


def training_loss(pred: torch.Tensor, target: torch.Tensor, alpha: float = ALPHA,
                  rel_weight: float = 0.0, mean_weight: float = 0.0,
                  dark_weight: float = 0.0, worst_weight: float = 0.0,
                  chroma_weight: float = 0.0, worst_axis: str = "rgb") -> torch.Tensor:
    """What temc trains on: the paper's mix loss on PQ R'G'B' of the reconstructed linear
    output against the reference's (both [N,3,H,W], linear, times the exposure).

    On R'G'B', not on H, S, V: L1 on H calls the reds on either side of the wrap opposites
    (a network trained that way answered red with yellow), and on the chroma plane
    MS-SSIM's contrast term rewarded desaturation. On PQ, not linear values: PQ spaces
    errors as the eye sees them, so dark regions count and highlights do not dominate."""
    pp, pt = pq(pred), pq(target)
    loss = mix_loss(pp, pt, alpha)
    if worst_weight:
        worst = (worst_pixel_error(pp, pt) if worst_axis == "rgb"
                 else worst_intensity_error(pred, target))
        loss = loss + worst_weight * worst
    if chroma_weight:
        loss = loss + chroma_weight * chroma_error(pred, target)
    if rel_weight:
        loss = loss + rel_weight * relative_l1(pred, target)
    if mean_weight:
        loss = loss + mean_weight * block_mean_error(pred, target)
    if dark_weight:
        loss = loss + dark_weight * block_log_error(pred, target)
    return loss
