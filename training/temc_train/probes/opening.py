"""What the fixed range term's opening does to accuracy: each checkpoint denoised (network +
reconstruction + keep-mean, as the core runs it) with the plain and the aux-guided opening
(docs/reconstruction.md, "Aux-guided opening"), and for multi-level models also with the
coarse clamp (step 4), against OIDN 2.5 high on the same images, in one run. Prints the
geometric-mean RelMSE over OIDN high's per spp, and the scenes the aux-guided opening moved
most.

    python -m temc_train.probes.opening --data ../data/spectral-v2 --generated 32 \\
        --checkpoint runs/temc2-w0.125-energy/checkpoint.pt
"""

import argparse
import os

import numpy as np

from .. import color, evaluate as ev
from ..checkpoint import Checkpoint
from ..data import auto_input_scale
from ..reconstruct import denoise_image
from .report import read_test_scenes

SPPS = (4, 16, 64)
# The reconstruction variants compared: name -> settings over the checkpoint's own.
VARIANTS = {"plain": {"range_opening": "plain", "coarse_clamp": False},
            "aux": {"range_opening": "aux", "coarse_clamp": False},
            "aux, clamp": {"range_opening": "aux", "coarse_clamp": True}}


def variants(recon):
    """The VARIANTS that differ for a model: the clamp only where there are coarse levels."""
    return [v for v in VARIANTS if recon["levels"] > 1 or not VARIANTS[v]["coarse_clamp"]]


def scene_errors(rec, root, models):
    """{(model, variant or "OIDN high", spp): RelMSE} of one test scene."""
    d = os.path.join(root, rec["dir"])
    ref = ev.read_exr(os.path.join(d, rec["reference"]))["color"]
    out = {}
    for spp, fname in rec["noisy"]:
        if spp not in SPPS:
            continue
        layers = ev.read_exr(os.path.join(d, fname))
        out[("OIDN high", "", spp)] = ev.relmse(ev.oidn_denoise(layers, "high")[0], ref)
        aux = np.moveaxis(color.aux_channels(layers["albedo"], layers["normal"], layers["depth"]), 0, -1)
        scale = auto_input_scale(layers["color"])
        for name, (model, recon) in models.items():
            for v in variants(recon):
                r = dict(recon, fixed_range=True, **VARIANTS[v])
                img = denoise_image(model, r, layers["color"], aux, scale)
                out[(name, v, spp)] = ev.relmse(img, ref)
    return out


# Families of our data set's test split, by name (report.py's grouping).
FAMILIES = (("hand-written", "named-"), ("held-out", "holdout-"), ("generated", "scene-"))


def geomean_ratio(rows, key, spp):
    return float(np.exp(np.mean([np.log(r[key + (spp,)] / r[("OIDN high", "", spp)])
                                 for r in rows.values()])))


def cells(rows, name, recon):
    """One table row's cells: per spp, each variant's ratio, joined by arrows."""
    return [" -> ".join(f"{geomean_ratio(rows, (name, v), s):.2f}" for v in variants(recon))
            for s in SPPS]


def family_lines(rows, models):
    """Per model and family of our test split (when it has more than one)."""
    out = []
    for family, prefix in FAMILIES:
        sub = {k: v for k, v in rows.items() if k.startswith(prefix)}
        if not sub or len(sub) == len(rows):
            continue
        for name, (_, recon) in models.items():
            out.append(f"| {name}, {family} ({len(sub)}) | " + " | ".join(cells(sub, name, recon)) + " |")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--generated", type=int, default=None,
                    help="how many generated test scenes besides the hand-written and held-out ones")
    ap.add_argument("--checkpoint", action="append", required=True)
    a = ap.parse_args(argv)
    models = {}
    for path in a.checkpoint:
        ck = Checkpoint.read(path)
        models[os.path.basename(os.path.dirname(os.path.abspath(path)))] = (ck.build()[0].eval(), ck.recon)
    _, tests = read_test_scenes(a.data, a.generated)
    rows = {rec["name"]: scene_errors(rec, a.data, models) for rec in tests}
    print(f"{len(rows)} test scenes of {a.data}; RelMSE / OIDN high's, geometric mean, "
          + " -> ".join(VARIANTS) + " (the clamp for multi-level models only)")
    print("| model | " + " | ".join(f"{s} spp" for s in SPPS) + " |")
    print("|---|" + "---:|" * len(SPPS))
    for name, (_, recon) in models.items():
        print(f"| {name} | " + " | ".join(cells(rows, name, recon)) + " |")
    print("\n".join(family_lines(rows, models)))
    for name in models:
        moved = sorted(((r[(name, "aux", 16)] / r[(name, "plain", 16)], scene) for scene, r in rows.items()))
        print(f"{name}, aux / plain RelMSE at 16 spp: best " +
              ", ".join(f"{s} {v:.2f}" for v, s in moved[:4]) + "; worst " +
              ", ".join(f"{s} {v:.2f}" for v, s in moved[-4:]))


if __name__ == "__main__":
    main()
