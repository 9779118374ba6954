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

import numpy as np

from .. import color, evaluate as ev
from ..checkpoint import Checkpoint
from ..data import auto_input_scale
from ..reconstruct import denoise_variants
from .constants import print_ratios, ratios_over, scenes


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
    recs = scenes(a.data, a.split, a.prefix, a.limit)
    ratios = ratios_over(a.data, recs, spps, len(ks),
                         lambda layers, ref: image_errors(model, recon, layers, ref, [0.0] + ks))
    print_ratios(f"{len(recs)} scenes of {a.data} ({a.split}{', ' + a.prefix if a.prefix else ''}); "
                 "RelMSE with K / with 0: geometric mean (worst image)",
                 [f"K = {k:g}" for k in ks], ratios, spps)

if __name__ == "__main__":
    main()
