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

import torch
from torch import nn

from .models import ALIGNMENT, AUX, CHROMA, LUMA, build

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
        # Random, not zero, inputs: the kernel head multiplies the predicted weights by the
        # input, so at zero input the weights' paths would carry no gradient.
        g = torch.Generator().manual_seed(0)
        xs = [torch.rand(1, c, STRIP_H, w, generator=g, dtype=torch.float64).requires_grad_()
              for c in (CHROMA, LUMA, AUX)]
        # Output pixel k sits in the middle of segment k, at phase k of the pooling grid.
        centres = [k * period + period // 2 + k for k in range(ALIGNMENT)]
        with torch.enable_grad():
            model(*xs)[0, :, STRIP_H // 2, centres].sum().backward()
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


def tile_overlap(arch: str) -> int:
    """Half the receptive field rounded up to the alignment; never less than the one-sided
    reach (footprints are not centred on their pixel), which the rounding covers for all
    four architectures today."""
    r = measure(arch)
    need = max(math.ceil(r.extent / 2), r.reach)
    return int(math.ceil(need / ALIGNMENT) * ALIGNMENT)
