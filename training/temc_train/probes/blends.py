"""How much does each level take from the coarser ones? Prints, per spp, the mean blend
sigmoid(blend logit) of every level but the coarsest (luma / chroma) that a checkpoint's
network predicts on a data split's images: near 0 a level ignores the levels below it, and
a multi-level model is a one-level model in effect.

    python -m temc_train.probes.blends --data ../data/cycles-family --checkpoint RUN/checkpoint.pt
"""

import argparse

import numpy as np
import torch

from .. import color, data
from ..checkpoint import Checkpoint
from ..models import ALIGNMENT


def blends(model, scene, s):
    """[(luma, chroma) mean blend per level but the coarsest] of noisy image `s`, cropped to
    the alignment."""
    a = scene.a
    hsv, _ = color.encode(a["color"][s], scene.scale[s])
    aux = color.aux_channels(a["albedo"][s], a["normal"][s], a["depth"][s])
    h, w = (n - n % ALIGNMENT for n in hsv.shape[:2])
    t = lambda x: torch.from_numpy(np.ascontiguousarray(x[:, :h, :w]))[None].float()  # noqa: E731
    planes = np.moveaxis(hsv, -1, 0)
    kk = model.kernel ** 2
    with torch.no_grad():
        filters = model(t(planes[:2]), t(planes[2:]), t(aux))
    return [tuple(float(torch.sigmoid(f[0, 2 * kk + i]).mean()) for i in (0, 1))
            for f in filters[:-1]]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--checkpoint", required=True)
    ap.add_argument("--split", default="test")
    a = ap.parse_args(argv)
    model = Checkpoint.read(a.checkpoint).build()[0].eval()
    if model.levels < 2:
        raise SystemExit(f"{a.checkpoint}: one level, nothing to blend")
    rows = {}
    for sc in data.load_split(a.data, a.split):
        for s, spp in enumerate(sc.spp):
            rows.setdefault(spp, []).append(blends(model, sc, s))
    print("| spp | " + " | ".join(f"level {l} luma / chroma" for l in range(model.levels - 1)) + " |")
    print("|---:|" + "---|" * (model.levels - 1))
    for spp, r in sorted(rows.items()):
        m = np.mean(r, axis=0)
        print(f"| {spp} | " + " | ".join(f"{y:.3f} / {c:.3f}" for y, c in m) + " |")


if __name__ == "__main__":
    main()
