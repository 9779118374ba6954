"""RelMSE of the noisy input and of OIDN high (pyoidn, HDR, albedo + normal) against the
reference on a rendered Cycles family, per spp: geometric mean over the scenes, and each
scene's numbers. The same metric and OIDN call as temc_train.probes.report (evaluate.py).

    PYTHONPATH=training ~/.cache/temc-venv/bin/python scenes/cycles/measure_oidn.py data/cycles-family

Needs `pip install pyoidn` in the venv (measurement only; never vendored).
"""

import sys

import numpy as np

from temc_train import data
from temc_train import evaluate as ev


def geomean(xs):
    return float(np.exp(np.mean(np.log(xs))))


def measure(root):
    """{spp: [(scene, noisy RelMSE, OIDN RelMSE)]}."""
    rows = {}
    for s in data.load_split(root, "test"):
        ref = data.read_exr(s.reference_path)["color"]
        for spp, path in zip(s.spp, s.noisy_paths):
            layers = data.read_exr(path)
            out, _ = ev.oidn_denoise(layers, "high", "full")
            rows.setdefault(spp, []).append(
                (s.name, ev.relmse(layers["color"], ref), ev.relmse(out, ref)))
    return rows


def main(root):
    rows = measure(root)
    print("| spp | scenes | noisy RelMSE (geomean) | OIDN high RelMSE (geomean) | noisy / OIDN |")
    print("|---:|---:|---:|---:|---:|")
    for spp, r in sorted(rows.items()):
        n, o = geomean([x[1] for x in r]), geomean([x[2] for x in r])
        print(f"| {spp} | {len(r)} | {n:.4g} | {o:.4g} | {n / o:.3g}x |")
    print("\n| scene | " + " | ".join(f"{s} spp noisy / OIDN" for s in sorted(rows)) + " |")
    print("|---|" + "---:|" * len(rows))
    names = [x[0] for x in rows[min(rows)]]
    for i, name in enumerate(names):
        cells = [f"{rows[s][i][1]:.3g} / {rows[s][i][2]:.3g}" for s in sorted(rows)]
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main(sys.argv[1])
