"""What the fixed range term's opening does to accuracy: each checkpoint denoised (network +
reconstruction + keep-mean, as the core runs it) with the plain and the aux-guided opening
(docs/reconstruction.md, "Aux-guided opening"), against OIDN 2.5 high on the same images,
in one run. Prints the geometric-mean RelMSE over OIDN high's per spp, and the scenes the
aux-guided opening moved most.

    python -m temc_train.probes.opening --data ../data/spectral-v2 --generated 32 \\
        --checkpoint runs/temc2-w0.125-energy/checkpoint.pt
"""

import argparse
import os

import numpy as np

from .. import color, evaluate as ev
from ..checkpoint import Checkpoint
from ..data import auto_input_scale
from ..reconstruct import RANGE_OPENINGS, denoise_image
from .report import read_test_scenes

SPPS = (4, 16, 64)


def scene_errors(rec, root, models):
    """{(model, opening or "OIDN high", spp): RelMSE} of one test scene."""
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
            for opening in RANGE_OPENINGS:
                r = dict(recon, fixed_range=True, range_opening=opening)
                img = denoise_image(model, r, layers["color"], aux, scale)
                out[(name, opening, spp)] = ev.relmse(img, ref)
    return out


def geomean_ratio(rows, key, spp):
    return float(np.exp(np.mean([np.log(r[key + (spp,)] / r[("OIDN high", "", spp)])
                                 for r in rows.values()])))


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
    print(f"{len(rows)} test scenes of {a.data}; RelMSE / OIDN high's, geometric mean, plain -> aux")
    print("| model | " + " | ".join(f"{s} spp" for s in SPPS) + " |")
    print("|---|" + "---:|" * len(SPPS))
    for name in models:
        cells = [f"{geomean_ratio(rows, (name, 'plain'), s):.2f} -> {geomean_ratio(rows, (name, 'aux'), s):.2f}"
                 for s in SPPS]
        print(f"| {name} | " + " | ".join(cells) + " |")
    for name in models:
        moved = sorted(((r[(name, "aux", 16)] / r[(name, "plain", 16)], scene) for scene, r in rows.items()))
        print(f"{name}, aux / plain RelMSE at 16 spp: best " +
              ", ".join(f"{s} {v:.2f}" for v, s in moved[:4]) + "; worst " +
              ", ".join(f"{s} {v:.2f}" for v, s in moved[-4:]))


if __name__ == "__main__":
    main()
