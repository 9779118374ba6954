"""Measures the keep-mean stage's settings on one trained model (docs/keep-mean.md).

    python -m temc_train.probes.keep_mean_probe --data ../data/spectral-v2 \\
        --checkpoint runs/temc2-w0.125-energy/checkpoint.pt --out ../docs/keep-mean-measured.md

Every validation and test image is denoised once through the network and reconstruct.py
(the core's function), then each variant below rescales that output; per spp: geometric-mean
RelMSE, mean Delta E ITP, the worst |mean / reference mean - 1| and how many scenes are within
1 % of the reference's mean (both in the output space: evaluate.mean_ratio). The noisy
input's own mean is the row to beat: no correction that follows the input can be closer to
the reference than the input is.
"""

import argparse
import math

import numpy as np
import torch

from .. import color, data, evaluate
from ..checkpoint import load_checkpoint
from ..keep_mean import (SPREAD_RADIUS, clipped_spread, interpolate, keep_mean, ratios,
                         restore_lamps, stage, window_mean)
from ..onnx_export import recon_of
from .probe import denoise


INF = float("inf")


def _luma_variant(block, clamp):
    """One factor per block from luminance, applied to all three channels (keeps hue)."""
    def apply(out, noisy):
        h, w = out.shape[:2]
        b = block if block > 0 else max(h, w)
        lum = lambda x: (x * color.LUMA).sum(-1, keepdims=True)
        f = interpolate(ratios(lum(noisy), lum(out), b, clamp), h, w, b)
        return np.clip(out * f, 0.0, color.LINEAR_MAX)
    return apply


def unclipped(o, excess):
    """The spread before the clip (2026-12-07): the output's own window mean."""
    return clipped_spread(o, excess, clip=INF)


def capped(k, r):
    """The unclipped window mean bounded at k times the output's (2r + 1)^2 mean around the
    pixel (r = 0: the pixel itself)."""
    def spread(o, excess):
        near = window_mean(o, r) if r else o
        return excess * np.minimum(window_mean(o, SPREAD_RADIUS), k * near)
    return spread


def split(k):
    """What stands above k times the window mean scales in place; the rest spreads."""
    def spread(o, excess):
        base = np.minimum(o, k * window_mean(o, SPREAD_RADIUS))
        return excess * (o - base + window_mean(base, SPREAD_RADIUS))
    return spread


def renormalised(k, most):
    """The core's clipped spread scaled, per channel, up to `most` times, to the energy the
    unclipped spread would add; the rest comes back in the last pass."""
    def spread(o, excess):
        mean = window_mean(o, SPREAD_RADIUS)
        full = excess * mean
        clipped = excess * window_mean(np.minimum(o, k * mean), SPREAD_RADIUS)
        g = full.sum((0, 1)) / np.maximum(clipped.sum((0, 1)), 1e-30)
        return clipped * np.minimum(g, most)
    return spread


def tamed(k):
    """No spread: the output clipped at k times its window mean takes the whole factor, what
    stands above it only SPREAD_ABOVE; the last pass scales back the rest. Every pixel is
    its own value times a factor, so black stays black."""
    return lambda o, excess: excess * np.minimum(o, k * window_mean(o, SPREAD_RADIUS))


def input_bounded(noisy, k, r):
    """The core's clipped spread, at most k times the noisy input's (2r + 1)^2 mean: where the
    renderer saw nothing within r pixels, nothing is added."""
    bound = k * window_mean(noisy.astype(np.float64), r)
    return lambda o, excess: np.minimum(clipped_spread(o, excess), excess * bound)


def bright_first(k, most, input_radius=None):
    """Before the clip's stage, the pixels of the output above k times its window mean (a
    lamp and the halo the filters made of it, or kept remnants) get one factor of their own
    per channel, the noisy input's sum over them / the output's, clamped to [1, most]: a
    lamp's deficit goes back to the lamp instead of raising the whole image."""
    def variant(out, noisy):
        o = out.astype(np.float64)
        bright = o > k * window_mean(o, SPREAD_RADIUS)
        if input_radius is not None:  # and the noisy input's mean around it likewise
            n = noisy.astype(np.float64)
            bright &= window_mean(n, input_radius) > k * window_mean(n, SPREAD_RADIUS)
        sums = [(np.where(bright, x, 0.0)).sum((0, 1)) for x in (noisy.astype(np.float64), o)]
        g = np.clip(sums[0] / np.maximum(sums[1], 1e-30), 1.0, most)
        return stage(np.where(bright, o * g, o).astype(np.float32), noisy, lamps=False)
    return variant


def lamp_first(k, most, grow=0, luma=False):
    """The clip's stage after `restore_lamps` with other settings (the core's: k 8, grow 8,
    most 1.5, luminance)."""
    return lambda out, noisy: stage(restore_lamps(out, noisy, k, grow, most, luma), noisy,
                                    lamps=False)


VARIANTS = {
    "none": lambda out, noisy: out,
    "global, per channel": lambda out, noisy: keep_mean(out, noisy, 0, 4.0, above=INF),
    "global, luminance": _luma_variant(0, 4.0),
    "blocks of 16, clamp 4": lambda out, noisy: keep_mean(out, noisy, 16, 4.0, above=INF),
    "blocks of 32, clamp 4": lambda out, noisy: keep_mean(out, noisy, 32, 4.0, above=INF),
    "blocks of 32, clamp 2": lambda out, noisy: keep_mean(out, noisy, 32, 2.0, above=INF),
    "blocks of 32, clamp 16": lambda out, noisy: keep_mean(out, noisy, 32, 16.0, above=INF),
    "global, per channel, clamp 16": lambda out, noisy: keep_mean(out, noisy, 0, 16.0, above=INF),
    "blocks of 32, clamp 4, then global clamp 16":
        lambda out, noisy: keep_mean(keep_mean(out, noisy, 32, 4.0, above=INF), noisy, 0, 16.0, above=INF),
    "blocks of 64, clamp 4, then global clamp 16, scaling only (the stage before 2026-12-04)":
        lambda out, noisy: stage(out, noisy, above=INF, lamps=False),
    "the stage before the clip, factors above 1.1 spread":
        lambda out, noisy: stage(out, noisy, above=1.1, spread=unclipped, last_spreads=True, lamps=False),
    "the stage before the clip: the same, factors above 1.25 spread over 33x33":
        lambda out, noisy: stage(out, noisy, spread=unclipped, last_spreads=True, lamps=False),
    "the clip's stage: the same, spread over the output clipped at 4x its window mean":
        lambda out, noisy: stage(out, noisy, lamps=False),
    "the stage before the clip, factors above 2 spread":
        lambda out, noisy: stage(out, noisy, above=2.0, spread=unclipped, last_spreads=True, lamps=False),
    "blocks of 64, clamp 4": lambda out, noisy: keep_mean(out, noisy, 64, 4.0, above=INF),
    "blocks of 32, luminance, clamp 4": _luma_variant(32, 4.0),
    "the stage before the clip, its spread capped at the pixel, last pass scaling":
        lambda out, noisy: stage(out, noisy, spread=capped(1.0, 0), lamps=False),
    "the stage before the clip, its spread capped at 4x the pixel, last pass scaling":
        lambda out, noisy: stage(out, noisy, spread=capped(4.0, 0), lamps=False),
    "the stage before the clip, its spread capped at 4x the 5x5 mean, last pass scaling":
        lambda out, noisy: stage(out, noisy, spread=capped(4.0, 2), lamps=False),
    "the stage before the clip, what stands above 4x the window mean scaling in place (split 4)":
        lambda out, noisy: stage(out, noisy, spread=split(4.0), lamps=False),
    "the clip's stage, factors above 2 spread":
        lambda out, noisy: stage(out, noisy, above=2.0, lamps=False),
    "the clip's stage, its clipped spread renormalised (up to 2x) to the unclipped one's energy":
        lambda out, noisy: stage(out, noisy, spread=renormalised(4.0, 2.0), lamps=False),
    "the clip's stage, no spread: what stands above 4x the window mean takes 1.25 (tamed)":
        lambda out, noisy: stage(out, noisy, spread=tamed(4.0), lamps=False),
    "the clip's stage, its spread at most 4x the noisy input's 5x5 mean (input-bounded)":
        lambda out, noisy: stage(out, noisy, spread=input_bounded(noisy, 4.0, 2), lamps=False),
    "the clip's stage after the bright pixels' own factor (up to 1.5; bright-first)":
        bright_first(4.0, 1.5),
    "the clip's stage after the bright pixels' own factor (up to 2; bright-first)":
        bright_first(4.0, 2.0),
    "the clip's stage after the bright pixels' own factor (up to 1.5, bright in the input's 3x3 "
    "mean too; bright-first)":
        bright_first(4.0, 1.5, input_radius=1),
    "the clip's stage after the bright pixels' own factor (up to 1.5, bright in the input's 5x5 "
    "mean too; bright-first)":
        bright_first(4.0, 1.5, input_radius=2),
    "the clip's stage after the bright pixels' own factor (above 8x, up to 1.5, bright in the "
    "input's 5x5 mean too; bright-first)":
        bright_first(8.0, 1.5, input_radius=2),
    "the clip's stage after a lamp's own factor (input bright in a 2x2 block and output "
    "bright, per channel, up to 1.5; lamp-first)": lamp_first(4.0, 1.5),
    "the clip's stage after a lamp's own factor (the same, deficit over the lamp grown by 4 "
    "px; lamp-first)": lamp_first(4.0, 1.5, grow=4),
    "the clip's stage after a lamp's own factor (the same, grown by 8 px; lamp-first)":
        lamp_first(4.0, 1.5, grow=8),
    "the clip's stage after a lamp's own factor (the same, grown by 8 px, up to 2; lamp-first)":
        lamp_first(4.0, 2.0, grow=8),
    "the clip's stage after a lamp's own factor (the same, grown by 8 px, from luminance; "
    "lamp-first)": lamp_first(4.0, 1.5, grow=8, luma=True),
    "the clip's stage after a lamp's own factor (the same, grown by 8 px, up to 1.25, from "
    "luminance; lamp-first)": lamp_first(4.0, 1.25, grow=8, luma=True),
    "the core's stage: the clip's after a lamp's own factor (above 8x, grown by 8 px, up to "
    "1.5, from luminance; lamp-first)": stage,
}


def row(res):
    rel = math.exp(np.mean([math.log(max(r[0], 1e-12)) for r in res]))
    de = float(np.mean([r[1] for r in res]))
    worst = max(abs(r[2] - 1) for r in res)
    within = sum(abs(r[2] - 1) <= 0.01 for r in res)
    return f"{rel:.5f} | {de:.3f} | {100 * worst:.1f} % | {within}/{len(res)}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True)
    ap.add_argument("--checkpoint", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--splits", default="val,test", help="comma-separated splits to denoise")
    ap.add_argument("--spp", default="", help="comma-separated spp to probe (default: all)")
    ap.add_argument("--scenes", default="", help="comma-separated scene-name prefixes to probe "
                    "(default: every scene of the splits)")
    ap.add_argument("--variants", default="", help="probe only the variants whose names hold "
                    "one of these comma-separated texts (the noisy input's row stays)")
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    prefixes = tuple(p for p in a.scenes.split(",") if p)
    scenes = [sc for split in a.splits.split(",") for sc in data.load_split(a.data, split)
              if not prefixes or sc.name.startswith(prefixes)]
    texts = a.variants.split(",")
    variants = {k: v for k, v in VARIANTS.items() if any(t in k for t in texts)}
    only = {int(x) for x in a.spp.split(",") if x}
    model, *_ = load_checkpoint(a.checkpoint)
    recon = recon_of(model)
    res = {}  # {(variant, spp): [(relmse, dE, mean ratio)]}
    worst = {}  # {(variant, spp): (|ratio - 1|, scene)}
    for sc in scenes:
        ref = sc.a["reference"]
        for s, spp in enumerate(sc.spp):
            if only and spp not in only:
                continue
            noisy = color.sanitize_rgb(sc.a["color"][s])
            out = denoise(model, recon, sc, s, keep=False)
            for name, f in [("noisy input", lambda o, n: n)] + list(variants.items()):
                x = f(out, noisy)
                m = evaluate.mean_ratio(x, ref)
                res.setdefault((name, spp), []).append((evaluate.relmse(x, ref), evaluate.delta_e_itp(x, ref), m))
                worst[(name, spp)] = max(worst.get((name, spp), (0, "")), (abs(m - 1), sc.name))
        print(f"probed {sc.name}", flush=True)
    spps = sorted({spp for _, spp in res})
    lines = [
        "# The keep-mean stage, measured",
        "",
        "Regenerate: `cd training && python -m temc_train.probes.keep_mean_probe --data " + a.data + " "
        f"--checkpoint {a.checkpoint} --splits {a.splits}" + (f" --spp {a.spp}" if a.spp else "")
        + (f" --scenes {a.scenes}" if a.scenes else "")
        + (f" --variants '{a.variants}'" if a.variants else "") + f" --out {a.out}`.",
        f"{len(scenes)} whole images of the {a.splits} split(s), full aux, denoised once by the",
        "checkpoint above through reconstruct.py; each variant then rescales that output. Per spp:",
        "geometric-mean RelMSE | mean Delta E ITP | worst |mean / reference mean - 1| (scene) |",
        "scenes within 1 % of the reference's mean (both means in the output space: gamut-mapped",
        "and capped at LINEAR_MAX, evaluate.mean_ratio). The validation and test scenes are",
        "those this machine had rendered (named stress scenes, then generated ones from",
        "`--start`), so they change from session to session.",
        "",
    ]
    for spp in spps:
        lines += [f"## {spp} spp", "", "| variant | RelMSE | dE ITP | worst mean | within 1 % | worst scene |",
                  "| --- | ---: | ---: | ---: | ---: | --- |"]
        for name in ["noisy input"] + list(variants):
            lines.append(f"| {name} | {row(res[(name, spp)])} | {worst[(name, spp)][1]} |")
        lines.append("")
    with open(a.out, "w") as f:
        f.write("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
