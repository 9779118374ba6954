"""Is a darkened image border (issue 36, item 2: no border artefacts) the filter's edge
handling? This probe denoises Cycles family scenes as they are and padded by P pixels
(numpy's reflect and symmetric modes, every layer alike) and cropped back, and prints the
8-px frame's mean over its reference's (evaluate.border_ratio) and the RelMSE of each.
If padding lifts the frame, the kernels' taps past the edge are at fault; if not, the
frame's own content is.

    python -m temc_train.probes.border_pad --data ../data/cycles-family \\
        --temc ../target/release/temc --model ../onnx/temc2-fast.onnx \\
        --scenes spot-dark-stage,dark-hidden-lamp,lamp-box
"""

import argparse
import os
import tempfile

import numpy as np

from .. import evaluate as ev
from .firefly_spread import denoise

MODES = ("reflect", "symmetric")


def padded(layers: dict, pad: int, mode: str) -> dict:
    """Every image layer padded by `pad` px on each side (other entries kept)."""
    def one(a):
        widths = ((pad, pad), (pad, pad)) + ((0, 0),) * (a.ndim - 2)
        return np.pad(a, widths, mode=mode)
    return {k: one(v) if isinstance(v, np.ndarray) and v.ndim >= 2 else v for k, v in layers.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True, help="the Cycles family (scenes/cycles)")
    ap.add_argument("--temc", required=True, help="the temc binary")
    ap.add_argument("--model", required=True, help="a temc ONNX model")
    ap.add_argument("--scenes", required=True, help="comma-separated scene names")
    ap.add_argument("--spp", default="4,16")
    ap.add_argument("--pad", type=int, default=32)
    a = ap.parse_args()
    print("| scene | spp | " + " | ".join(f"{m} border | {m} RelMSE" for m in ("plain",) + MODES) + " |")
    print("|---|---:|" + "---:|" * 2 * (1 + len(MODES)))
    with tempfile.TemporaryDirectory() as tmp:
        for scene in a.scenes.split(","):
            folder = os.path.join(a.data, "test", scene)
            ref = ev.read_exr(os.path.join(folder, "ref.exr"))["color"]
            for spp in (int(s) for s in a.spp.split(",")):
                layers = ev.read_exr(os.path.join(folder, f"spp{spp:04d}.exr"))
                outs = [denoise(a.temc, a.model, layers, layers["color"].astype(np.float64), tmp)]
                for mode in MODES:
                    big = padded(layers, a.pad, mode)
                    out = denoise(a.temc, a.model, big, big["color"].astype(np.float64), tmp)
                    outs.append(out[a.pad:-a.pad, a.pad:-a.pad])
                cells = [f"{ev.border_ratio(o, ref):.3f} | {ev.relmse(o, ref):.5f}" for o in outs]
                print(f"| {scene} | {spp} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
