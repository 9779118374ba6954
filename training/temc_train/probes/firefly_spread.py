"""Does spreading fireflies before the network help? Issue 36, item 2 asks that fireflies
be removed by spreading their energy (never kept as dots, never deleted). The cheapest way
is a fixed stage before the network: a pixel brighter than K times the brightest of its
eight neighbours keeps K times that, and its excess goes to a Gaussian of SIGMA px around
it (weights renormalised inside the image, so the image's energy is kept to rounding).
This probe runs a temc model on the Cycles family's noisy images with and without that
stage and prints the geometric-mean RelMSE ratio per spp (below 1: the stage helps).

    python -m temc_train.probes.firefly_spread --data ../data/cycles-family \\
        --temc ../target/release/temc --model ../onnx/temc2-balanced.onnx 6:1.5 3:1.5 6:3

Each positional argument is one variant K:SIGMA, or K:SIGMA:R to compare each pixel with
the mean of the (2R+1)^2 window around it without the pixel itself (e.g. 20:1.5:2), which
two adjacent fireflies do not hide from each other. Full aux (albedo, normal, depth), 2
threads, every test scene at `--spp` (default 4, 16 and 64).
"""

import argparse
import os
import subprocess
import tempfile

import numpy as np

from .. import evaluate as ev
from ..reconstruct import LUMA


def _windows(a: np.ndarray, r: int, edge: bool):
    """(dy, dx, a shifted by (dy, dx)) over the (2r+1)^2 window; outside the image the
    nearest pixel (edge) or zero."""
    p = np.pad(a, r, mode="edge") if edge else np.pad(a, r)
    h, w = a.shape
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            yield dy, dx, p[r + dy:r + dy + h, r + dx:r + dx + w]


def _blur(a: np.ndarray, g: np.ndarray) -> np.ndarray:
    r = g.shape[0] // 2
    out = np.zeros_like(a)
    for dy, dx, v in _windows(a, r, edge=False):
        out += g[dy + r, dx + r] * v
    return out


def _level(lum: np.ndarray, radius: int) -> np.ndarray:
    """What a pixel is compared with: with `radius` 0 the brightest of its eight
    neighbours; otherwise the mean of the (2 radius + 1)^2 window without the pixel itself
    (edges replicated), which two adjacent fireflies do not hide from each other."""
    others = [v for dy, dx, v in _windows(lum, max(radius, 1), edge=True) if (dy, dx) != (0, 0)]
    return np.mean(others, axis=0) if radius else np.max(others, axis=0)


def spread(color: np.ndarray, k: float, sigma: float, radius: int = 0, eps: float = 1e-4):
    """`color` [H, W, 3] with each firefly's excess spread (module docs; `radius`: _level);
    returns (image, number of fireflies)."""
    lum = color @ np.asarray(LUMA, color.dtype)
    cap = k * _level(lum, radius) + eps
    fly = lum > cap
    keep = np.where(fly, cap / np.maximum(lum, 1e-30), 1.0)
    excess = color * (1.0 - keep)[..., None]
    r = int(np.ceil(3 * sigma))
    y, x = np.mgrid[-r:r + 1, -r:r + 1]
    g = np.exp(-(x * x + y * y) / (2 * sigma * sigma))
    g /= g.sum()
    inside = _blur(np.ones(lum.shape), g)  # each source's weight that lands in the image
    out = color * keep[..., None]
    for c in range(3):
        out[..., c] += _blur(excess[..., c] / inside, g)
    return out, int(fly.sum())


def denoise(temc: str, model: str, layers: dict, color: np.ndarray, tmp: str) -> np.ndarray:
    """`temc denoise` on `color` with the layers' aux buffers."""
    args = [temc, "denoise", "--model", model, "--threads", "2", "-o", f"{tmp}/out.pfm"]
    for flag, img in (("--color", color), ("--albedo", layers["albedo"]),
                      ("--normal", layers["normal"]), ("--depth", layers.get("depth"))):
        if img is not None:
            ev.write_pfm(f"{tmp}/{flag[2:]}.pfm", img if img.ndim < 3 or img.shape[2] == 3
                      else img[..., 0])
            args += [flag, f"{tmp}/{flag[2:]}.pfm"]
    subprocess.run(args, check=True, capture_output=True)
    return ev.read_pfm(f"{tmp}/out.pfm")


def parse_variant(text: str) -> tuple:
    """`K:SIGMA[:R]` as (K, SIGMA, R), R 0 (the brightest neighbour) when absent."""
    parts = text.split(":")
    if len(parts) not in (2, 3):
        raise SystemExit(f"variant {text!r}: expected K:SIGMA or K:SIGMA:R")
    return float(parts[0]), float(parts[1]), int(parts[2]) if len(parts) == 3 else 0


def label(k: float, sigma: float, radius: int) -> str:
    """A variant's column heading."""
    against = f", {2 * radius + 1}x{2 * radius + 1} mean" if radius else ""
    return f"K {k:g}, sigma {sigma:g}{against}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True, help="the Cycles family (scenes/cycles)")
    ap.add_argument("--temc", required=True, help="the temc binary")
    ap.add_argument("--model", required=True, help="a temc ONNX model")
    ap.add_argument("variants", nargs="*", default=["6:1.5"],
                    help="K:SIGMA, or K:SIGMA:R to compare with the mean of the (2R+1)^2 "
                         "window without the pixel instead of the brightest neighbour")
    ap.add_argument("--spp", default="4,16,64")
    a = ap.parse_args()
    variants = [parse_variant(s) for s in a.variants]
    spps = [int(s) for s in a.spp.split(",")]
    rows = {}
    test = os.path.join(a.data, "test")
    with tempfile.TemporaryDirectory() as tmp:
        for scene in sorted(os.listdir(test)):
            ref = ev.read_exr(os.path.join(test, scene, "ref.exr"))["color"]
            for spp in spps:
                layers = ev.read_exr(os.path.join(test, scene, f"spp{spp:04d}.exr"))
                noisy = layers["color"].astype(np.float64)
                errs = [ev.relmse(denoise(a.temc, a.model, layers, noisy, tmp), ref)]
                for k, sigma, radius in variants:
                    img, _ = spread(noisy, k, sigma, radius)
                    errs.append(ev.relmse(denoise(a.temc, a.model, layers, img, tmp), ref))
                rows[(scene, spp)] = errs
                print(scene, spp, " ".join(f"{e:.4g}" for e in errs), flush=True)
    print("| spp | RelMSE without | " + " | ".join(label(*v) for v in variants) + " |")
    print("|---:|---:|" + "---:|" * len(variants))
    for spp in spps:
        e = np.array([v for (_, p), v in rows.items() if p == spp])
        g = np.exp(np.mean(np.log(e), axis=0))
        print(f"| {spp} | {g[0]:.4g} | " + " | ".join(f"{x / g[0]:.3f}x" for x in g[1:]) + " |")


if __name__ == "__main__":
    main()
