"""Where one image's RelMSE comes from: the pixels that carry most of it, for a temc model
beside OIDN high on one noisy render of a data set. A handful of pixels holding most of the
error is a kept firefly or a leak; an even spread is residual noise.

    python -m temc_train.probes.worst_pixels --data ../data/cycles-family \\
        --scene metal-spheres --spp 16 --temc ../target/release/temc \\
        --model ../onnx/temc2-fast.onnx

Prints the image's RelMSE for the model and OIDN high, then the --top pixels by their share
of the model's RelMSE, with the noisy input, the reference, the model's and OIDN's values
there (linear RGB). Full aux, 2 threads.
"""

import argparse
import json
import os

import numpy as np

from .. import evaluate as ev


def pixel_errors(x: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """RelMSE's terms per pixel, [H, W]: their mean is evaluate.relmse(x, ref)."""
    return ev.relmse_terms(x, ref).mean(-1)


def worst(x: np.ndarray, ref: np.ndarray, top: int):
    """The `top` pixels with the largest RelMSE terms: ((y, x), share of the sum) each."""
    e = pixel_errors(x, ref)
    order = np.argsort(e.ravel())[::-1][:top]
    return [(divmod(int(i), e.shape[1]), float(e.ravel()[i] / e.sum())) for i in order]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True)
    ap.add_argument("--scene", required=True)
    ap.add_argument("--spp", type=int, required=True)
    ap.add_argument("--temc", required=True, help="the temc binary")
    ap.add_argument("--model", required=True, help="a temc ONNX model")
    ap.add_argument("--top", type=int, default=5)
    a = ap.parse_args(argv)
    with open(os.path.join(a.data, "manifest.json")) as f:
        rec = next(r for r in json.load(f)["scenes"] if r["name"] == a.scene)
    d = os.path.join(a.data, rec["dir"])
    path = os.path.join(d, dict(rec["noisy"])[a.spp])
    layers = ev.read_exr(path)
    ref = ev.read_exr(os.path.join(d, rec["reference"]))["color"]
    ours, _ = ev.temc_denoise(a.temc, a.model, path)
    oidn, _ = ev.oidn_denoise(layers)
    print(f"{a.scene} at {a.spp} spp: RelMSE {ev.relmse(ours, ref):.4g} "
          f"({os.path.basename(a.model)}), OIDN high {ev.relmse(oidn, ref):.4g}")
    fmt = lambda v: "(" + ", ".join(f"{c:.3g}" for c in v) + ")"  # noqa: E731
    for (y, x), share in worst(ours, ref, a.top):
        print(f"pixel ({y}, {x}): {100 * share:.1f} % of it; noisy {fmt(layers['color'][y, x])}, "
              f"reference {fmt(ref[y, x])}, model {fmt(ours[y, x])}, OIDN {fmt(oidn[y, x])}")


if __name__ == "__main__":
    main()
