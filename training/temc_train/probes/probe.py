"""Equal-budget design probes of the reconstruction (issue 14), evaluated in PyTorch.

    python -m temc_train.probes.probe --data ../data/spectral-v2 --runs runs/probe-* \\
        --out ../docs/reconstruction-design.md

Each run is a train.py checkpoint of one design (levels, split, demodulation). Every run is
evaluated on the same scenes (the data set's validation and test splits as they stand when
this runs, whole images, full aux, automatic exposure) through the network and
reconstruct.py, the function the core runs. Per design and spp: geometric-mean RelMSE,
mean Delta E ITP, and the worst |mean / reference mean - 1| over scenes, beside OIDN 2.5
high on the same images when pyoidn is installed.
"""

import argparse
import glob
import math
import os

import numpy as np
import torch

from .. import color, data, evaluate
from ..checkpoint import Checkpoint
from ..onnx_export import recon_of
from ..reconstruct import denoise_image


def denoise(model, recon, scene, s, keep=True):
    """The whole noisy image `s` of `scene`, denoised as the core would (full aux; `keep`:
    the keep-mean stage)."""
    a = scene.a
    aux = np.moveaxis(color.aux_channels(a["albedo"][s], a["normal"][s], a["depth"][s]), 0, -1)
    return denoise_image(model, recon, a["color"][s], aux, scene.scale[s], keep)


def evaluate_run(model, recon, scenes):
    """{spp: [(relmse, dE, mean ratio), ...]} over scenes."""
    res = {}
    for sc in scenes:
        for s, spp in enumerate(sc.spp):
            out = denoise(model, recon, sc, s)
            res.setdefault(spp, []).append(scores(out, sc.a["reference"]))
    return res


def scores(out, ref):
    """(RelMSE, Delta E ITP, mean ratio) of one output: the probe's three columns."""
    return evaluate.relmse(out, ref), evaluate.delta_e_itp(out, ref), evaluate.mean_ratio(out, ref)


def evaluate_oidn(scenes, score=None):
    """{spp: [score(OIDN high's output, reference), ...]} over scenes (`score`: the probe's
    `scores` by default), or None without pyoidn."""
    score = score or scores
    try:
        import pyoidn  # noqa: F401
    except ImportError:
        return None
    res = {}
    for sc in scenes:
        for s, spp in enumerate(sc.spp):
            layers = {"color": sc.a["color"][s], "albedo": sc.a["albedo"][s],
                      "normal": sc.a["normal"][s]}
            out, _ = evaluate.oidn_denoise(layers, "high", "full")
            res.setdefault(spp, []).append(score(out, sc.a["reference"]))
    return res


def summary(rows):
    rel = math.exp(np.mean([math.log(max(r[0], 1e-12)) for r in rows]))
    de = float(np.mean([r[1] for r in rows]))
    worst = max(abs(r[2] - 1) for r in rows)
    return rel, de, worst


def describe(recon, state=None):
    """The design and (where the checkpoint records it) the training recipe of a run."""
    text = (f"{recon['levels']} level(s) of {recon['kernel']}x{recon['kernel']}, "
            f"{'luma + chroma filters' if recon['split'] == 'both' else 'one filter'}, "
            f"demodulation {'on' if recon['demodulate'] else 'off'}"
            + (", guides" if recon.get("guide") else ""))
    hp = (state or {}).get("hparams")
    if hp:
        target = f"{hp['target_spp']}-spp reference prefix" if hp.get("target_spp") else "clean reference"
        text += f"; {hp.get('loss', 'mix')} loss on the {target}"
    return text


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True)
    ap.add_argument("--runs", nargs="+", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--title", default="Reconstruction design probes (issue 14)")
    ap.add_argument("--regenerate", default="`scripts/design-probes` (trains every design below on "
                    "the same CPU budget,\nthen runs `python -m temc_train.probes.probe`)",
                    help="the command the page names for regenerating it")
    ap.add_argument("--note", default="", help="a paragraph placed after the table")
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    scenes = data.load_split(a.data, "val") + data.load_split(a.data, "test")
    runs = sorted(r for pat in a.runs for r in glob.glob(pat))
    table = []
    for run in runs:
        ck = os.path.join(run, "checkpoint.pt")
        if not os.path.exists(ck):
            continue
        held = Checkpoint.read(ck)
        model, arch, width = held.build()
        recon = recon_of(model)
        st = held.state
        table.append((os.path.basename(run), describe(recon, st), st["train_s"], st["step"],
                      evaluate_run(model, recon, scenes)))
        print(f"evaluated {run}", flush=True)
    oidn = evaluate_oidn(scenes)
    spps = sorted({spp for *_, res in table for spp in res})
    lines = [
        f"# {a.title}",
        "",
        f"Regenerate: {a.regenerate}. One thread per run; evaluated on",
        f"{len(scenes)} whole images of the validation and test splits of "
        f"`{os.path.basename(os.path.normpath(a.data))}`, full aux, through the network and",
        "the reconstruction the core runs (`reconstruct.py`, proven equal to src/reconstruct.rs).",
        "RelMSE: geometric mean over scenes; dE: mean Delta E ITP; mean: the worst",
        "|image mean / reference mean - 1| over scenes.",
        "",
        "| run | design | CPU s | steps | " + " | ".join(
            f"{spp} spp RelMSE | dE | mean" for spp in spps) + " |",
        "| --- | --- | ---: | ---: | " + " | ".join("---: | ---: | ---:" for _ in spps) + " |",
    ]
    for name, desc, secs, steps, res in table:
        cells = []
        for spp in spps:
            rel, de, worst = summary(res[spp])
            cells.append(f"{rel:.4f} | {de:.2f} | {100 * worst:.1f} %")
        lines.append(f"| {name} | {desc} | {secs:.0f} | {steps} | " + " | ".join(cells) + " |")
    if oidn:
        cells = []
        for spp in spps:
            rel, de, worst = summary(oidn[spp])
            cells.append(f"{rel:.4f} | {de:.2f} | {100 * worst:.1f} %")
        lines.append("| OIDN 2.5 high | same images | | | " + " | ".join(cells) + " |")
    if a.note:
        lines += ["", a.note]
    with open(a.out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
