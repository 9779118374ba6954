"""Receptive field of each architecture, measured by gradient, and the tile overlap it implies.

The tiler (docs/contracts.md §2, `temc.receptive_field`, `temc.tile_overlap`) needs the
theoretical receptive field: every input pixel that can influence an output pixel. Backprop
on a trained or random network understates it (dead ReLUs and max-pool switches cut paths
off, positive and negative paths can cancel), so the gradient is taken through a
linearised copy instead: ReLU -> identity, max-pool -> average pool over the same 2x2
window, every weight positive. Then an input pixel has a non-zero gradient exactly when
some path connects it to the output pixel. float64 keeps the far tails of the gradient
(products of some forty averaging layers) from underflowing to zero.

The footprint depends on where the output pixel sits relative to the pooling grid (phase
mod 32): an aligned pixel such as the image centre sees less than its neighbours (the
autoencoder: 192 px at phase 0, 224 px elsewhere). So 32 output pixels, one per phase, are
measured at once in a wide strip, each far enough from the others that their footprints
cannot overlap, and the worst case is kept. The networks use square kernels and pools
only, so the footprint along W is the footprint along H.
"""

import functools
import math
from typing import NamedTuple

import numpy as np
import torch
from torch import nn

from .models import ALIGNMENT, AUX, CHROMA, LUMA, build
from .reconstruct import denoise_image, reach

# Narrow and fast; the receptive field does not depend on the width.
WIDTH = 0.0625
STRIP_H = ALIGNMENT


class Reach(NamedTuple):
    extent: int  # the receptive field: width in pixels of the largest footprint
    reach: int   # the most pixels a footprint extends to one side of its output pixel


@torch.no_grad()
def linearise(model: nn.Module) -> nn.Module:
    """Rewrites `model` in place into the positive linear network described above."""
    for parent in list(model.modules()):
        for name, child in list(parent.named_children()):
            if isinstance(child, nn.ReLU):
                setattr(parent, name, nn.Identity())
            elif isinstance(child, nn.MaxPool2d):
                setattr(parent, name, nn.AvgPool2d(child.kernel_size, child.stride))
    for m in model.modules():
        if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d)):
            m.weight.fill_(1.0 / m.weight[0].numel())  # an average: values stay near 1
            if m.bias is not None:
                m.bias.zero_()
        elif isinstance(m, nn.BatchNorm2d):
            m.reset_parameters()
            m.reset_running_stats()
    return model.eval()


@functools.lru_cache(maxsize=None)
def measure(arch: str) -> Reach:
    """The receptive field of `arch`, worst case over the 32 alignment phases."""
    model = linearise(build(arch, WIDTH).double())
    period = 512  # room for each footprint; doubled if one reaches its segment's edge
    while True:
        w = ALIGNMENT * period
        g = torch.Generator().manual_seed(0)
        xs = [torch.rand(1, c, STRIP_H, w, generator=g, dtype=torch.float64).requires_grad_()
              for c in (CHROMA, LUMA, AUX)]
        # Output pixel k sits in the middle of segment k, at phase k of the pooling grid.
        centres = [k * period + period // 2 + k for k in range(ALIGNMENT)]
        with torch.enable_grad():
            model(*xs)[0][0, :, STRIP_H // 2, centres].sum().backward()
        hit = torch.zeros(w, dtype=torch.bool)
        for x in xs:
            hit |= (x.grad[0] != 0).any(dim=0).any(dim=0)
        extent = reach = 0
        contained = True
        for k, c in enumerate(centres):
            cols = hit[k * period:(k + 1) * period].nonzero()[:, 0] + k * period
            lo, hi = int(cols.min()), int(cols.max())
            contained &= lo > k * period and hi < (k + 1) * period - 1
            extent = max(extent, hi - lo + 1)
            reach = max(reach, c - lo, hi - c)
        if contained:
            return Reach(extent, reach)
        period *= 2


def receptive_field(arch: str) -> int:
    return measure(arch).extent


def tile_overlap(arch: str, levels: int, kernel: int, upsample: str = "nearest") -> int:
    """The theoretical overlap: the network's one-sided reach (at least half its receptive
    field: footprints are not centred on their pixel) plus the reconstruction's reach, plus
    the coarsest level's block (a coarse filter pixel covers 2^(L-1) pixels), rounded up to
    the alignment. An upper bound; trained models carry the measured effective_overlap."""
    r = measure(arch)
    need = max(math.ceil(r.extent / 2), r.reach) + reach(levels, kernel, upsample) + 2 ** (levels - 1)
    return int(math.ceil(need / ALIGNMENT) * ALIGNMENT)


EFFECT_TOL = 1e-4  # issue 14: an impulse's effect below this fraction of its size is "none"


@torch.no_grad()
def effective_reach(model: nn.Module, recon: dict, size: int = 256, seed: int = 0) -> int:
    """The measured effective receptive field of network + reconstruction, in pixels from the
    impulse: the largest Chebyshev distance at which adding a unit impulse (of the image's
    mean size) to one noisy pixel changes any output channel by more than EFFECT_TOL of
    the impulse. Taken on a noisy grey image with random aux (the worst of four impulse
    positions, one per pooling phase class), through the network and reconstruction of every
    tile (not the keep-mean stage, which runs on the whole image after tiling)."""
    g = np.random.default_rng(seed)
    base = (0.18 * g.gamma(2.0, 0.5, size=(size, size, 3))).astype(np.float32)
    aux = np.moveaxis(g.random((1, AUX, size, size), dtype=np.float32)[0], 0, -1)
    worst = 0
    for cy, cx in [(size // 2, size // 2), (size // 2 + 5, size // 2 + 11),
                   (size // 2 + 16, size // 2 - 7), (size // 2 - 3, size // 2 + 1)]:
        outs = []
        for bump in (0.0, 1.0):
            img = base.copy()
            img[cy, cx] += bump * 0.18
            outs.append(denoise_image(model, recon, img, aux, 1.0, keep=False))
        d = np.abs(outs[1] - outs[0]).max(axis=-1) / 0.18
        ys, xs = np.nonzero(d > EFFECT_TOL)
        if len(ys):
            worst = max(worst, int(np.maximum(np.abs(ys - cy), np.abs(xs - cx)).max()))
    return worst


def effective_overlap(model: nn.Module, recon: dict) -> int:
    """The tile overlap from the measured effective reach plus half an alignment of margin,
    rounded up to the alignment. The reach is measured on one mild image and grows with
    contrast: a guided model whose reach measured 31 px disagreed across 32-px tile seams
    by 4e-3 in PQ on heavy-tailed noise (tests/filter_api.rs)."""
    r = effective_reach(model, recon) + ALIGNMENT // 2
    return int(max(ALIGNMENT, math.ceil(r / ALIGNMENT) * ALIGNMENT))
