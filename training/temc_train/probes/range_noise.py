"""What the fixed range term's threshold from local noise (`temc.range_noise` = K) does to
accuracy, without retraining: each image of a data split through a checkpoint's network
once, then reconstructed (as the core does, keep-mean included) with K = 0 (the fixed
threshold) and each K asked for. Prints, per spp, the geometric mean over the images of
RelMSE at K / RelMSE at 0, and the worst image's ratio.

    python -m temc_train.probes.range_noise --data ../data/cycles-family \\
        --checkpoint runs/temc2-w0.125-l3/checkpoint.pt --k 4,6
    python -m temc_train.probes.range_noise --data ../data/fast-scenes --split val \\
        --limit 24 --checkpoint runs/temc2-w0.125-l3/checkpoint.pt --k 3,4,6
"""

import argparse
import json
import os

import numpy as np

from .. import color, evaluate as ev
from ..checkpoint import Checkpoint
from ..data import auto_input_scale
from ..reconstruct import denoise_variants


def scenes(root, split, prefix, limit):
    """The finished scenes of `split` whose names start with `prefix`, the first `limit`."""
    with open(os.path.join(root, "manifest.json")) as f:
        recs = json.load(f)["scenes"]
    done = [r for r in recs if r["split"] == split and r["name"].startswith(prefix)
            and os.path.exists(os.path.join(root, r["dir"], "done.json"))]
    return done[:limit]


def image_errors(model, recon, layers, ref, ks):
    """RelMSE of one noisy render reconstructed with each K of `ks` (the network runs once),
    under the shipped fixed range term (aux-guided opening)."""
    aux = np.moveaxis(color.aux_channels(layers["albedo"], layers["normal"], layers["depth"]), 0, -1)
    recons = [dict(recon, fixed_range=True, range_opening="aux", range_noise=k) for k in ks]
    images = denoise_variants(model, recons, layers["color"], aux, auto_input_scale(layers["color"]))
    return [ev.relmse(img, ref) for img in images]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--checkpoint", required=True)
    ap.add_argument("--k", default="4,6", help="the K values to compare with 0, comma-separated")
    ap.add_argument("--spp", default="1,4,16,64")
    ap.add_argument("--split", default="test")
    ap.add_argument("--prefix", default="", help="only scenes whose names start with this")
    ap.add_argument("--limit", type=int, default=None, help="at most this many scenes")
    a = ap.parse_args(argv)
    ks = [float(k) for k in a.k.split(",")]
    spps = [int(s) for s in a.spp.split(",")]
    ck = Checkpoint.read(a.checkpoint)
    model, recon = ck.build()[0].eval(), ck.recon
    ratios = {(s, k): [] for s in spps for k in ks}
    recs = scenes(a.data, a.split, a.prefix, a.limit)
    for rec in recs:
        d = os.path.join(a.data, rec["dir"])
        ref = ev.read_exr(os.path.join(d, rec["reference"]))["color"]
        for spp, name in rec["noisy"]:
            if spp in spps:
                base, *rest = image_errors(model, recon, ev.read_exr(os.path.join(d, name)), ref,
                                           [0.0] + ks)
                for k, e in zip(ks, rest):
                    ratios[(spp, k)].append(e / base)
    print(f"{len(recs)} scenes of {a.data} ({a.split}{', ' + a.prefix if a.prefix else ''}); "
          f"RelMSE with K / with 0: geometric mean (worst image)")
    print("| spp | " + " | ".join(f"K = {k:g}" for k in ks) + " |")
    print("|---:|" + "---:|" * len(ks))
    for s in spps:
        cells = [f"{np.exp(np.mean(np.log(ratios[(s, k)]))):.4f} ({max(ratios[(s, k)]):.3f})"
                 for k in ks]
        print(f"| {s} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
