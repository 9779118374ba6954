"""Writes tests/data/feature_vectors.json: the automatic exposure and the aux features
(albedo, normal, depth; docs/contracts.md §1, steps 3 and 7) on small cases, with what this
package computes for them, so the Rust core (tests/feature_vectors.rs) and training
(tests/test_feature_vectors.py) check themselves against one file.

Run from training/: python -m temc_train.vectors.feature_vectors. Inputs are float32 values,
written exactly; non-finite values as "nan", "inf", "-inf".
"""

import argparse
import json
import math
import pathlib

import numpy as np

from .. import color
from ..data import auto_input_scale
from .recon_vectors import _num  # NaN/Inf as JSON strings, as the Rust side reads them

OUT = pathlib.Path(__file__).resolve().parents[3] / "tests" / "data" / "feature_vectors.json"
# Exposure: the core rounds its scale to float32 (6e-8 relative), this package keeps float64.
EXPOSURE_TOLERANCE = 1e-6
# Features: float32 results of the same float64 arithmetic, up to one rounding apart.
FEATURE_TOLERANCE = 1e-6
NAN, INF = math.nan, math.inf
TINY = float(np.float32(1e-45))  # the smallest subnormal float32


def _random_image(rng, n, lo, hi):
    return 10.0 ** rng.uniform(lo, hi, (n, 3))


def exposure_cases():
    """(name, pixels [n, 3]): images whose log-average the exposure rule must find, and the
    pixels its luminance threshold and the sanitiser must drop or fix."""
    rng = np.random.default_rng(17)
    hdr = _random_image(rng, 64, -6, 4)
    hdr[::7] = [NAN, 1.0, 0.5]
    hdr[3::11] = [INF, 2.0, 1.0]
    return [
        ("grey", np.full((4, 3), 0.5)),
        ("black", np.zeros((3, 3))),
        ("one pixel", np.array([[0.2, 0.4, 0.1]])),
        ("below threshold", np.full((5, 3), 1e-9)),
        ("threshold mixed", np.array([[1e-9] * 3, [0.3, 0.3, 0.3], [0.0, 0.0, 0.0], [2.0, 1.0, 0.5]])),
        ("dim", np.full((3, 3), 2e-8)),
        ("negative luminance", np.array([[-1.0, -1.0, 0.5], [0.4, 0.2, 0.1]])),
        ("out of gamut", np.array([[0.5, -0.2, 0.1], [1.0, 0.8, -0.3]])),
        ("non-finite", np.array([[NAN, NAN, NAN], [INF, INF, INF], [-INF, 0.5, 0.5], [0.1, 0.2, 0.3]])),
        ("saturated", np.full((2, 3), 1e30)),
        ("random ldr", rng.random((48, 3))),
        ("random hdr", hdr),
    ]


def albedo_cases():
    return [[0.25, 0.5, 0.75], [NAN, 2.0, -1.0], [0.25, INF, -INF], [0.0, 1.0, 1.0 + 1e-7],
            [TINY, -TINY, 0.999999]]


def normal_cases():
    rng = np.random.default_rng(18)
    return [[0.0, 0.0, 5.0], [0.0, -1e-3, 0.0], [0.0, 0.0, 0.0], [NAN, 1.0, 0.0], [TINY, 0.0, 0.0],
            [1e-15, 1e-15, 0.0], [1e-16, 0.0, 0.0], [3e38, 3e38, 0.0], [INF, 0.0, 0.0],
            [0.3, -0.4, 0.5], [-1.0, 1.0, -1.0]] + rng.normal(size=(8, 3)).tolist()


def depth_cases():
    """(name, depths): whole images' depths; the statistic is over the whole image."""
    rng = np.random.default_rng(19)
    return [
        ("mixed", [1.0, NAN, 4.0, INF, -2.0, 0.0]),
        ("none positive", [NAN, 0.0, -1.0]),
        ("background only", [INF, INF]),
        ("one depth", [3.5]),
        ("random", (rng.random(16) * 20).tolist()),
        ("tiny", [1e-30, 2e-30, 5e-31]),
        ("large", [1e30, 3e38, 1.0]),
    ]


def _f32(x):
    return np.asarray(x, np.float64).astype(np.float32)


def _flat(a):
    return [_num(v) for v in np.asarray(a, np.float64).ravel()]


def vectors() -> dict:
    exposure = [{"name": n, "rgb": _flat(_f32(p)), "scale": auto_input_scale(_f32(p))}
                for n, p in exposure_cases()]
    albedo = [{"in": _flat(_f32(a)), "out": _flat(color.albedo(_f32(a)))} for a in albedo_cases()]
    normal = [{"in": _flat(_f32(n)), "out": _flat(color.normal(_f32(n)))} for n in normal_cases()]
    depth = []
    for name, d in depth_cases():
        d = _f32(d)
        s = color.depth_scale(d)
        depth.append({"name": name, "in": _flat(d), "scale": None if s is None else s,
                      "out": _flat(color.depth(d, s))})
    return {
        "comment": "Written by training/temc_train/vectors/feature_vectors.py; read by "
                   "training/tests/test_feature_vectors.py and tests/feature_vectors.rs. "
                   "Rules: docs/contracts.md section 1, steps 3 and 7.",
        "auto_exposure_key": color.AUTO_EXPOSURE_KEY,
        "exposure_tolerance": EXPOSURE_TOLERANCE,
        "feature_tolerance": FEATURE_TOLERANCE,
        "exposure": exposure, "albedo": albedo, "normal": normal, "depth": depth,
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.parse_args(argv)  # --help; no options
    doc = vectors()
    OUT.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {OUT} ({OUT.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
