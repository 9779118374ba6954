"""What changing one fixed constant of the reconstruction or of keep-mean, or one of a
model's reconstruction settings, would do to accuracy, without retraining: each image of a
data split through a checkpoint's network and its reconstruction under ship.SHIP_RECON
(with --file, that file's FILE_RECON too: the baseline), once as the baseline and once per
variant, keep-mean included. Prints, per spp, the geometric mean over the images of RelMSE
with the variant / RelMSE of the baseline, and the worst image's ratio.

    python -m temc_train.probes.constants --data ../data/cycles-family \\
        --checkpoint runs/temc2-w0.125-l3/checkpoint.pt \\
        --set reconstruct.COARSE_GAIN=0.5 --set reconstruct.COARSE_GAIN=2
    python -m temc_train.probes.constants --data ../data/spectral-v2 --prefix holdout \\
        --spp 4,16,64 --checkpoint runs/temc2-w0.125-l3/checkpoint.pt \\
        --set "recon.coarse_radius=4;recon.coarse_gain=0.5"
    python -m temc_train.probes.constants --data ../data/cycles-family --file temc2-balanced \\
        --checkpoint runs/temc2-w0.125-l3/checkpoint.pt --base recon.coarse_sparse=0 \\
        --set recon.coarse_sparse=0.5

A variant is `MODULE.NAME=VALUE[;MODULE.NAME=VALUE...]`, MODULE one of `reconstruct` and
`keep_mean`, NAME an existing numeric constant there, or MODULE `recon` and NAME a
reconstruction setting a model may change without changing its network (train.SWITCHABLE;
the metadata's `temc.NAME`, e.g. `recon.coarse_radius=4;recon.coarse_gain=0.5`,
`recon.fixed_range=0`, `recon.range_opening=plain`). The Rust core has its own copies of the
constants: a constant worth shipping is a contract change (docs/contracts.md), not a file
edit here; a setting ships through ship.SHIP_RECON or FILE_RECON. A variant that leaves
every image unchanged ends the probe with an error after the table (the constant never
binds on these images, or is not read where the probe looks, e.g. a default argument bound
at import), so a ratio of exactly 1 is never a silent no-op.
"""

import argparse
import contextlib
import json
import os

import numpy as np

from .. import color, evaluate as ev, keep_mean, reconstruct
from ..checkpoint import Checkpoint
from ..data import auto_input_scale
from ..drivers.ship import FILE_RECON, SHIP_RECON
from ..drivers.train import SWITCHABLE
from ..models import RECON_DEFAULTS

# The named choices of the string settings a variant may set.
CHOICES = {"upsample": reconstruct.UPSAMPLES, "range_opening": reconstruct.RANGE_OPENINGS}

MODULES = {"reconstruct": reconstruct, "keep_mean": keep_mean}


def scenes(root, split, prefix, limit):
    """The finished scenes of `split` whose names start with `prefix`, the first `limit`."""
    with open(os.path.join(root, "manifest.json")) as f:
        recs = json.load(f)["scenes"]
    done = [r for r in recs if r["split"] == split and r["name"].startswith(prefix)
            and os.path.exists(os.path.join(root, r["dir"], "done.json"))]
    return done[:limit]


def ratios_over(root, recs, spps, count, errors) -> dict:
    """{(spp, i): [RelMSE of variant i / the baseline's, one per image]} over every noisy
    render at `spps` of the scenes `recs` of data set `root`; `errors(layers, ref)` gives
    the baseline's RelMSE, then the `count` variants'. (The probes' one loop.)"""
    ratios = {(s, i): [] for s in spps for i in range(count)}
    for rec in recs:
        d = os.path.join(root, rec["dir"])
        ref = ev.read_exr(os.path.join(d, rec["reference"]))["color"]
        for spp, name in rec["noisy"]:
            if spp in spps:
                base, *rest = errors(ev.read_exr(os.path.join(d, name)), ref)
                for i, e in enumerate(rest):
                    ratios[(spp, i)].append(e / base)
    return ratios


def print_ratios(head: str, labels: list, ratios: dict, spps) -> None:
    """`head`, then a table per spp (those with images) of each variant's geometric-mean
    ratio and its worst image's."""
    print(head)
    print("| spp | " + " | ".join(labels) + " |")
    print("|---:|" + "---:|" * len(labels))
    for s in (s for s in spps if ratios[(s, 0)]):
        cells = [f"{np.exp(np.mean(np.log(ratios[(s, i)]))):.4f} ({max(ratios[(s, i)]):.3f})"
                 for i in range(len(labels))]
        print(f"| {s} | " + " | ".join(cells) + " |")


def recon_value(name: str, value: str):
    """A `recon.NAME=VALUE` setting's value, typed as RECON_DEFAULTS' (0 or 1 for a switch,
    one of the named choices for `upsample` and `range_opening`); None where NAME is not a
    setting a model may change without changing its network (train.SWITCHABLE) or VALUE
    does not fit it."""
    if name not in SWITCHABLE:
        return None
    default = RECON_DEFAULTS[name]
    if isinstance(default, str):
        return value if value in CHOICES[name] else None
    try:
        number = float(value)
    except ValueError:
        return None
    if isinstance(default, bool):
        return bool(number) if number in (0.0, 1.0) else None
    return type(default)(number)


def parse_variant(text: str) -> list:
    """`MODULE.NAME=VALUE;...` as [(module, name, value)], module None for a `recon.NAME`
    setting; refuses unknown names and values."""
    out = []
    for item in text.split(";"):
        key, _, value = item.partition("=")
        mod_name, _, name = key.strip().partition(".")
        if mod_name == "recon":
            v = recon_value(name, value.strip())
            if v is None:
                raise SystemExit(f"--set {item!r}: not a reconstruction setting a model may "
                                 f"change ({', '.join(SWITCHABLE)}) with a value it takes")
            out.append((None, name, v))
            continue
        mod = MODULES.get(mod_name)
        if mod is None or not isinstance(getattr(mod, name, None), (int, float)):
            raise SystemExit(f"--set {item!r}: not a numeric constant of "
                             f"{' or '.join(MODULES)}")
        kind = type(getattr(mod, name))  # an int constant (a block size) stays an int
        out.append((mod, name, kind(float(value))))
    return out


@contextlib.contextmanager
def patched(assignments: list):
    """The constants set for the duration of the block, restored after it (`recon`
    settings are not constants: image_errors applies them)."""
    assignments = [a for a in assignments if a[0] is not None]
    old = [(mod, name, getattr(mod, name)) for mod, name, _ in assignments]
    try:
        for mod, name, value in assignments:
            setattr(mod, name, value)
        yield
    finally:
        for mod, name, value in old:
            setattr(mod, name, value)


def image_errors(model, recon, layers, ref, variants, base=()):
    """RelMSE of one noisy render under the baseline, then each variant; and the images.
    `base` (parse_variant's list) applies to the baseline and under every variant."""
    aux = np.moveaxis(color.aux_channels(layers["albedo"], layers["normal"], layers["depth"]), 0, -1)
    scale = auto_input_scale(layers["color"])
    images = []
    for assignments in [list(base)] + [list(base) + v for v in variants]:
        settings = dict(recon, **{name: v for mod, name, v in assignments if mod is None})
        with patched(assignments):
            images += reconstruct.denoise_variants(model, [settings], layers["color"], aux, scale)
    return [ev.relmse(img, ref) for img in images], images


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--checkpoint", required=True)
    ap.add_argument("--set", action="append", required=True, dest="variants",
                    help="a variant: MODULE.NAME=VALUE[;MODULE.NAME=VALUE...]; repeat for more")
    ap.add_argument("--file", choices=sorted(FILE_RECON),
                    help="a shipped file whose FILE_RECON joins the baseline")
    ap.add_argument("--base", default=None,
                    help="a variant applied to the baseline and under every --set (e.g. "
                         "recon.coarse_sparse=0 to measure against a shipped file's setting off)")
    ap.add_argument("--spp", default="1,4,16,64")
    ap.add_argument("--split", default="test")
    ap.add_argument("--prefix", default="", help="only scenes whose names start with this")
    ap.add_argument("--limit", type=int, default=None, help="at most this many scenes")
    a = ap.parse_args(argv)
    variants = [parse_variant(v) for v in a.variants]
    base = parse_variant(a.base) if a.base else []
    spps = [int(s) for s in a.spp.split(",")]
    ck = Checkpoint.read(a.checkpoint)
    model = ck.build()[0].eval()
    recon = {**ck.recon, **SHIP_RECON, **FILE_RECON.get(a.file, {})}
    moved = [False] * len(variants)

    def errors(layers, ref):
        errs, (img0, *imgs) = image_errors(model, recon, layers, ref, variants, base)
        for i, img in enumerate(imgs):
            moved[i] |= not np.array_equal(img, img0)
        return errs

    recs = scenes(a.data, a.split, a.prefix, a.limit)
    ratios = ratios_over(a.data, recs, spps, len(variants), errors)
    print_ratios(f"{len(recs)} scenes of {a.data} ({a.split}{', ' + a.prefix if a.prefix else ''}); "
                 "RelMSE with the variant / the baseline"
                 + (f" ({a.base} in both)" if a.base else "") + ": geometric mean (worst image)",
                 a.variants, ratios, spps)
    still = [v for v, m in zip(a.variants, moved) if not m]
    if still:
        raise SystemExit(f"--set {', '.join(still)}: changed no image (it never binds on "
                         "these images, or the probe's path does not read it): its ratios "
                         "above measure nothing")


if __name__ == "__main__":
    main()
