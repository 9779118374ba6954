"""What the flip ensemble buys: RelMSE of a model run over 1, 2 and 4 flip passes
(`temc denoise --passes`, src/filter/passes.rs) on a data set's test scenes, per spp, as the
geometric mean over the scenes and its ratio to one pass. docs/reconstruction.md, "A flip
ensemble", keeps the run on the Cycles family.

    cd training && python -m temc_train.probes.passes --data ../data/cycles-family \\
        --temc ../target/release/temc --model ../onnx/temc2-balanced.onnx

Each image is denoised once per pass count with all its aux layers on one thread; the
table's seconds are `temc denoise --json`'s execution times summed over the images (at
128x128 they are mostly the per-call plan building, not the passes: docs/speed.md times
1920x1080).
"""

import argparse
import collections
import json
import os
import subprocess
import tempfile

import numpy as np

from ..data import read_exr
from ..evaluate import read_pfm, relmse


def denoise(temc, model, exr, passes, out):
    """Runs `temc denoise` on one EXR with `passes` flip passes; returns (image, seconds)."""
    r = subprocess.run([temc, "denoise", "--model", model, "--color", exr, "-o", out,
                        "--threads", "1", "--passes", str(passes), "--json"],
                       capture_output=True, text=True, check=True)
    rep = json.loads(r.stdout.strip().splitlines()[-1])
    return read_pfm(out), rep["seconds"]["execute"]


def measure(data, temc, model, counts):
    """({spp: [[RelMSE per pass count] per scene]}, {pass count: seconds})."""
    manifest = json.load(open(os.path.join(data, "manifest.json")))
    errors, seconds = collections.defaultdict(list), collections.Counter()
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "out.pfm")
        for scene in manifest["scenes"]:
            if scene.get("split", "test") != "test":
                continue
            root = os.path.join(data, scene["dir"])
            ref = read_exr(os.path.join(root, scene["reference"]))["color"]
            for spp, name in scene["noisy"]:
                row = []
                for n in counts:
                    img, s = denoise(temc, model, os.path.join(root, name), n, out)
                    seconds[n] += s
                    row.append(relmse(img, ref))
                errors[spp].append(row)
    return errors, seconds


def table(errors, seconds, counts):
    head = " | ".join(f"{n} pass{'es' if n > 1 else ''}" for n in counts)
    lines = [f"| spp | scenes | {head} |", "|---:|---:|" + "---:|" * len(counts)]
    for spp, rows in sorted(errors.items()):
        g = np.exp(np.log(np.array(rows)).mean(0))
        cells = " | ".join(f"{g[i]:.5f}" + ("" if i == 0 else f" ({g[i] / g[0]:.3f}x)")
                           for i in range(len(counts)))
        lines.append(f"| {spp} | {len(rows)} | {cells} |")
    lines.append("| seconds | | " + " | ".join(f"{seconds[n]:.1f}" for n in counts) + " |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, help="a data set with manifest.json (its test split)")
    ap.add_argument("--temc", required=True, help="the temc binary")
    ap.add_argument("--model", required=True, help="a temc ONNX model")
    ap.add_argument("--passes", default="1,2,4", help="pass counts, the first the baseline")
    a = ap.parse_args(argv)
    counts = [int(n) for n in a.passes.split(",")]
    print(f"RelMSE, geometric mean over the scenes ({os.path.basename(a.model)}; ratio to "
          f"{counts[0]} pass{'es' if counts[0] > 1 else ''}):\n")
    print(table(*measure(a.data, a.temc, a.model, counts), counts))


if __name__ == "__main__":
    main()
