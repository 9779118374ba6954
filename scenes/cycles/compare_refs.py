"""How clean a family's references are: each scene's reference from one rendering (e.g.
2048 spp) against a longer one (e.g. 8192 spp) of the same scene, next to OIDN high's error
at 64 spp against each; and whether the noisy renders are bit-identical (same seeds).

    PYTHONPATH=training ~/.cache/temc-venv/bin/python scenes/cycles/compare_refs.py SHORT LONG
"""

import sys

import numpy as np

from temc_train import data
from temc_train import evaluate as ev


def main(short_root, long_root):
    short = {s.name: s for s in data.load_split(short_root, "test")}
    long = {s.name: s for s in data.load_split(long_root, "test")}
    print("| scene | RelMSE(short ref, long ref) | OIDN 64 spp vs long ref | OIDN 64 spp vs short ref | noisy identical |")
    print("|---|---:|---:|---:|---|")
    for n in sorted(set(short) & set(long)):
        rs, rl = short[n].a["reference"], long[n].a["reference"]
        out, _ = ev.oidn_denoise(data.read_exr(long[n].noisy_paths[-1]), "high", "full")
        same = np.array_equal(short[n].a["color"], long[n].a["color"])
        print(f"| {n} | {ev.relmse(rs, rl):.3g} | {ev.relmse(out, rl):.3g} | {ev.relmse(out, rs):.3g} | {same} |")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
