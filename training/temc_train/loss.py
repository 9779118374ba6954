"""The paper's training loss: Zhao et al. 2017's mix of MS-SSIM and L1.

    L = alpha * (1 - MS-SSIM) + (1 - alpha) * G_sigmaM * |x - y|,  alpha = 0.84

in the multi-sigma, full-resolution form (architecture note §4.1): five Gaussian windows
sigma = 0.5, 1, 2, 4, 8 at the same resolution, the luminance term at the largest sigma
only, contrast-structure terms multiplied over all five, and the L1 term weighted by the
largest Gaussian. Downsampling MS-SSIM needs images over 160 px a side; this form works on
the paper's 128x128 crops (and on anything down to 1x1, by replicate padding).
Computed per channel on [0,1] images (the network's PQ-HSV), then averaged.
"""

import torch
import torch.nn.functional as F

from .models import hsv_to_rgb

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


def _blur(x: torch.Tensor, k: torch.Tensor) -> torch.Tensor:
    """x [B, 1, H, W] blurred by every window of k [S, K]: [B, S, H, W]. Separable (rows,
    then columns): 2K instead of K^2 multiplies per pixel. Replicate padding keeps the
    borders of small crops from reading as dark edges."""
    s, n = k.shape
    x = F.pad(x, (RADIUS,) * 4, mode="replicate")
    x = F.conv2d(x, k.view(s, 1, 1, n))
    return F.conv2d(x, k.view(s, 1, n, 1), groups=s)


def mix_loss(pred: torch.Tensor, target: torch.Tensor, alpha: float = ALPHA) -> torch.Tensor:
    """The mean L_mix over batch, channels and pixels of two [N, C, H, W] tensors."""
    if pred.shape != target.shape:
        raise ValueError(f"shape mismatch {tuple(pred.shape)} vs {tuple(target.shape)}")
    n, c, h, w = pred.shape
    b = n * c  # per channel: every channel is its own grey image
    x = pred.reshape(b, 1, h, w)
    y = target.reshape(b, 1, h, w)
    k = _kernels(pred.device, pred.dtype)
    # One blur call for the five local moments.
    m = _blur(torch.cat([x, y, x * x, y * y, x * y]), k).split(b)
    mx, my = m[0], m[1]
    sxx = m[2] - mx * mx
    syy = m[3] - my * my
    sxy = m[4] - mx * my
    cs = (2 * sxy + C2) / (sxx + syy + C2)
    lum = (2 * mx[:, -1] * my[:, -1] + C1) / (mx[:, -1] ** 2 + my[:, -1] ** 2 + C1)
    ms_ssim = lum * cs.prod(dim=1)
    l1 = _blur((x - y).abs(), k[-1:])[:, 0]  # G_sigmaM-weighted L1
    return (alpha * (1 - ms_ssim) + (1 - alpha) * l1).mean()


def training_loss(pred: torch.Tensor, target: torch.Tensor, alpha: float = ALPHA) -> torch.Tensor:
    """What temc trains on: the paper's mix loss on the R'G'B' of the network's HSV output
    (the core's inverse, before PQ decoding).

    Not on H, S, V themselves: L1 on H calls the reds on either side of the wrap (H near 0
    and near 1) opposites, and a network trained that way answers red with the hue between
    them (yellow, green). Not on the chroma plane (S cos 2piH, S sin 2piH) either, which we
    tried next: there MS-SSIM's contrast term rewards a low-variance prediction, and
    shrinking S shrinks every chroma variance at once; the networks learned to desaturate
    (cornell-spiky's walls at S 0.17 against 0.34). In R'G'B' hue wraps, the hue of grey
    weighs nothing, and desaturating moves every channel's mean."""
    return mix_loss(hsv_to_rgb(pred), hsv_to_rgb(target), alpha)
