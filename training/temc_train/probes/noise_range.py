"""The noise range of a data set: RelMSE of every noisy input against its scene's reference,
summarised per (spp, family) over the scenes of the default sampler and per (spp,
sampling: default or weak) over every family, as the median and the 10th and 90th
percentiles over scenes.

    python -m temc_train.probes.noise_range --data /tmp/noise-range

RelMSE is evaluate.relmse (temc-render's `film::relmse`): the mean over pixels and channels of
(x - r)^2 / (r^2 + 0.01). The reference is itself noisy: at `ref_spp` it adds about
spp / ref_spp of an input's RelMSE. Generated scenes only (the named and held-out test
scenes are left out). Prints two Markdown tables, for docs/render.md.
"""

import argparse
import json
import os

import numpy as np

from ..data import read_exr
from ..evaluate import relmse


def color(path: str) -> np.ndarray:
    """The colour layer of a temc-render EXR, [H, W, 3], in float64."""
    return read_exr(path)["color"].astype(np.float64)


def scene_errors(root: str, record: dict):
    """RelMSE by spp of one scene's noisy inputs, or the names of its files with
    non-finite pixels (a tracer bug, which a RelMSE would hide as NaN)."""
    d = os.path.join(root, record["dir"])
    images = {spp: color(os.path.join(d, f)) for spp, f in record["noisy"]}
    ref = color(os.path.join(d, record["reference"]))
    bad = [f for (_, f), x in zip(record["noisy"] + [(0, record["reference"])],
                                  list(images.values()) + [ref]) if not np.isfinite(x).all()]
    if bad:
        return bad
    return {spp: relmse(x, ref) for spp, x in images.items()}


def table(title: str, groups: dict, spps: list) -> str:
    """A Markdown table: a row per group, a column per spp, `median (p10–p90)`."""
    lines = [f"| {title} | scenes | " + " | ".join(f"{s} spp" for s in spps) + " |",
             "|---|---:|" + "---:|" * len(spps)]
    for name in sorted(groups):
        errs = groups[name]
        cells = []
        for s in spps:
            v = np.array([e[s] for e in errs])
            p10, med, p90 = np.percentile(v, [10, 50, 90])
            cells.append(f"{med:.2g} ({p10:.2g}–{p90:.2g})")
        lines.append(f"| {name} | {len(errs)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, help="a data set folder (temc-render dataset --out)")
    a = ap.parse_args(argv)
    with open(os.path.join(a.data, "manifest.json")) as f:
        m = json.load(f)
    rows = [r for r in m["scenes"] if r["name"].startswith("scene-")]
    if not rows:
        raise SystemExit(f"{a.data}: no generated scenes in manifest.json")
    spps = sorted(m["options"]["spp"])
    by_family, by_sampling, broken = {}, {}, []
    for r in rows:
        e = scene_errors(a.data, r)
        if isinstance(e, list):
            broken.append(f"{r['dir']} ({', '.join(e)})")
            continue
        weak = r.get("sampling", "default") != "default"
        by_sampling.setdefault("weak" if weak else "default", []).append(e)
        if not weak:
            by_family.setdefault(r.get("family") or "?", []).append(e)
    by_family["(all)"] = by_sampling.get("default", [])
    by_sampling["(all)"] = [e for v in by_sampling.values() for e in v]
    print(f"RelMSE against the {m['options']['ref_spp']} spp reference, median (10th–90th "
          f"percentile) over the {len(rows)} generated scenes of {a.data}.\n")
    print("Per family, the scenes rendered with the default sampler:\n")
    print(table("family", by_family, spps))
    print("\nPer sampling mode, every family:\n")
    print(table("sampling", by_sampling, spps))
    if broken:
        print(f"\nLeft out, with non-finite pixels: {'; '.join(broken)}")


if __name__ == "__main__":
    main()
