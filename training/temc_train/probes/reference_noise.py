"""Checks the accuracy report's estimate of each reference's own noise on a data set: for
every test scene that keeps a reference prefix, the reference's own RelMSE against the
truth as evaluate.reference_variance estimates it, and the RelMSE of the scene's noisy
inputs in units of it. A noisy render of s spp with its own seed is (ref_spp / s + 1)
such units from a reference of the default sampler (its variance plus the reference's):
3 at 256 spp and 9 at 64 for 512-spp references. Where a scene's ratio is far above that,
rare bright paths the 64-sample prefix missed make the estimate low there, and the
report's subtraction conservative.

    python -m temc_train.probes.reference_noise --data ../data/spectral-v2

Prints a Markdown table (docs/render.md quotes it).
"""

import argparse
import os

import numpy as np

from .. import evaluate as ev
from .report import read_test_scenes, reference_noise


def scene_row(root: str, record: dict):
    """(name, sampling, the reference's own RelMSE, {spp: noisy RelMSE in its units}), or
    None for a scene without a reference prefix."""
    d = os.path.join(root, record["dir"])
    ref = ev.read_exr(os.path.join(d, record["reference"]))["color"]
    var = reference_noise(d, record, ref)
    if var is None:
        return None
    own = ev.reference_relmse(ref, var)
    ratios = {spp: ev.relmse(ev.read_exr(os.path.join(d, f))["color"], ref) / own
              for spp, f in record["noisy"]}
    return record["name"], record.get("sampling", "default"), own, ratios


def table(root: str) -> list:
    """The Markdown table of scene_row over the test split's finished scenes, and a closing
    line with the share of scenes within 25 % of the expected ratio at every spp."""
    manifest, tests = read_test_scenes(root)
    ref_spp = manifest["options"]["ref_spp"]
    rows = [r for r in (scene_row(root, rec) for rec in tests) if r]
    if not rows:
        raise SystemExit(f"no test scene with a reference prefix in {root}")
    spps = sorted(rows[0][3])
    expect = {s: ref_spp / s + 1 for s in spps}
    md = ["| scene | sampling | reference's own RelMSE | "
          + " | ".join(f"{s} spp / own (expected {expect[s]:g})" for s in spps) + " |",
          "|---|---|---:|" + "---:|" * len(spps)]
    near = 0
    for name, sampling, own, ratios in rows:
        md.append(f"| {name} | {sampling} | {own:.3g} | "
                  + " | ".join(f"{ratios[s]:.3g}" for s in spps) + " |")
        near += all(abs(ratios[s] / expect[s] - 1) <= 0.25 for s in spps)
    md += ["", f"{near} of {len(rows)} scenes within 25 % of the expected ratio at every spp "
           f"(median ratios: " + ", ".join(
               f"{s} spp {np.median([r[3][s] for r in rows]):.3g}" for s in spps) + ")."]
    return md


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, help="a temc-render data set with reference prefixes")
    a = ap.parse_args(argv)
    print("\n".join(table(a.data)))


if __name__ == "__main__":
    main()
