"""How much of a denoiser's error sits beside bright emitters, and what the fixed range
term (reconstruct.fixed_range_term) does to it: issue 36, item 1.

    python -m temc_train.probes.leak_probe --data ../data/cycles-family \\
        --run runs/temc2-w0.125-energy --oidn --out ../docs/leak-probe.md

Both variants run the same checkpoint's network; only the reconstruction's fixed range term
(off, on) differs, so the table isolates it. Whole images of the
data set's test split, full aux, through reconstruct.py (the function the core runs) and the
keep-mean stage, beside OIDN 2.5 high when pyoidn is installed. "Near" pixels lie within
NEAR px of a bright one (reference luminance at the image's automatic exposure >= BRIGHT,
i.e. about 44x the log-mean) and are not bright themselves; "near share" is their part of
the image's RelMSE sum, and "near x" the 99th percentile of output / reference luminance
over them (1 is right; a leak lifts it).
"""

import argparse
import math
import os

import numpy as np
import torch
import torch.nn.functional as F

from .. import data, evaluate
from ..checkpoint import load_checkpoint
from ..onnx_export import recon_of
from ..reconstruct import LUMA
from .probe import denoise, evaluate_oidn

BRIGHT = 8.0
NEAR = 8


def _lum(x):
    return x @ np.asarray(LUMA, x.dtype)


def near_mask(ref: np.ndarray) -> np.ndarray:
    """[H, W] bool: within NEAR px (square window) of a bright pixel, not bright itself."""
    bright = _lum(ref) * data.auto_input_scale(ref) >= BRIGHT
    t = torch.from_numpy(bright.astype(np.float32))[None, None]
    grown = F.max_pool2d(t, 2 * NEAR + 1, stride=1, padding=NEAR)[0, 0].numpy() > 0
    return grown & ~bright


def leak_scores(out: np.ndarray, ref: np.ndarray) -> tuple:
    """(RelMSE, dE ITP, mean ratio, near share, near x) of one output."""
    per = ((out - ref) ** 2 / (ref * ref + evaluate.EPS)).mean(-1)
    near = near_mask(ref)
    share = float(per[near].sum() / max(per.sum(), 1e-30))
    lo, lr = _lum(out)[near], _lum(ref)[near]
    keep = lr > 1e-3 * max(float(_lum(ref).mean()), 1e-30)
    nx = float(np.percentile(lo[keep] / lr[keep], 99)) if keep.any() else float("nan")
    return (float(per.mean()), evaluate.delta_e_itp(out, ref), evaluate.mean_ratio(out, ref),
            share, nx)


def summarise(rows: list) -> tuple:
    """Geometric-mean RelMSE, mean dE, worst |mean - 1|, mean near share, worst near x."""
    geo = math.exp(np.mean([math.log(max(r[0], 1e-12)) for r in rows]))
    near_x = [r[4] for r in rows if not math.isnan(r[4])]
    return (geo, float(np.mean([r[1] for r in rows])), max(abs(r[2] - 1) for r in rows),
            float(np.mean([r[3] for r in rows])), max(near_x) if near_x else float("nan"))


def evaluate_variants(run: str, scenes: list) -> dict:
    """{"off"/"on": {spp: [leak_scores]}} for one checkpoint, without and with the fixed
    range term."""
    model, *_ = load_checkpoint(f"{run}/checkpoint.pt")
    base = recon_of(model)
    res = {}
    for on in (False, True):
        recon = dict(base, fixed_range=on)
        for sc in scenes:
            for s, spp in enumerate(sc.spp):
                out = denoise(model, recon, sc, s)
                res.setdefault("on" if on else "off", {}).setdefault(spp, []).append(
                    leak_scores(out, sc.a["reference"]))
    return res


def table(rows: dict, spps: list) -> list:
    lines = ["| denoiser | spp | RelMSE (geomean) | dE ITP | worst mean | near share | near x (p99) |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for name, res in rows.items():
        for spp in spps:
            g, de, worst, share, nx = summarise(res[spp])
            lines.append(f"| {name} | {spp} | {g:.4g} | {de:.3g} | {100 * worst:.2f} % | "
                         f"{100 * share:.0f} % | {nx:.3g} |")
    return lines


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True)
    ap.add_argument("--run", required=True)
    ap.add_argument("--oidn", action="store_true", help="add OIDN 2.5 high (needs pyoidn)")
    ap.add_argument("--out")
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    scenes = data.load_split(a.data, "test")
    rows = {f"temc, fixed range term {v}": r for v, r in evaluate_variants(a.run, scenes).items()}
    if a.oidn:
        oidn = evaluate_oidn(scenes, leak_scores)
        if oidn is None:
            raise SystemExit("--oidn needs pyoidn: pip install pyoidn==2.5.1.0")
        rows["OIDN 2.5 high"] = oidn
    spps = sorted({spp for r in rows.values() for spp in r})
    lines = [
        "# The fixed range term against lamp leaks (issue 36, item 1)", "",
        f"Regenerate: `cd training && python -m temc_train.probes.leak_probe --data {a.data} --run {a.run}"
        + (" --oidn" if a.oidn else "") + f" --out {a.out}`.", "",
        f"{len(scenes)} test scenes of `{os.path.basename(os.path.normpath(a.data))}`, whole images, "
        "full aux, through the network of the run's checkpoint and reconstruct.py (the core's "
        "function) with the keep-mean stage; only the fixed range term differs between the temc "
        "rows. RelMSE: geometric mean over scenes; dE ITP: mean; worst mean: the worst |image mean "
        "/ reference mean - 1|; near share: the part of each image's RelMSE within "
        f"{NEAR} px of a visible emitter (reference luminance >= {BRIGHT:g} at the automatic "
        "exposure), mean over scenes; near x: the worst scene's 99th percentile of output / "
        "reference luminance over those pixels (1 is right, a leak lifts it).", ""] + table(rows, spps)
    print("\n".join(lines))
    if a.out:
        with open(a.out, "w") as f:
            f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
