"""Checks a host example's result: every denoised image exists, is finite and (with
--require-better) is closer to the high-sample reference than the noisy input is (RelMSE);
writes a side-by-side PNG (noisy, each denoised image, reference).

    python check_denoised.py --noisy N.exr --reference R.exr --denoised NAME=PATH ... \\
        --png side-by-side.png [--require-better]

Reads PFM, plain EXR and multi-layer EXR (Blender: the Noisy Image pass if present, else
Combined). Needs numpy, OpenEXR and pillow (the venv that scripts/test-all creates).
"""

import argparse
import sys

import numpy as np


def read(path):
    if path.endswith(".pfm"):
        with open(path, "rb") as f:
            kind = f.readline().strip()
            w, h = (int(v) for v in f.readline().split())
            scale = float(f.readline())
            a = np.frombuffer(f.read(), "<f4" if scale < 0 else ">f4").reshape(h, w, -1)
        return np.flipud(a[..., :3]).astype(np.float32)
    import Imath
    import OpenEXR

    f = OpenEXR.InputFile(path)
    names = list(f.header()["channels"])
    dw = f.header()["dataWindow"]
    w, h = dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1
    for prefix in ("ViewLayer.Noisy Image.", "ViewLayer.Combined.", "color.", ""):
        if all(prefix + c in names for c in "RGB"):
            pt = Imath.PixelType(Imath.PixelType.FLOAT)
            return np.stack([np.frombuffer(f.channel(prefix + c, pt), np.float32).reshape(h, w)
                             for c in "RGB"], -1)
    raise SystemExit(f"{path}: no RGB channels among {names[:8]}")


def relmse(x, r):
    return float(np.mean((x - r) ** 2 / (r * r + 0.01)))


def tonemap(x):
    x = np.clip(x, 0, None)
    x = x / (1 + x)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return (np.clip(x, 0, 1) * 255 + 0.5).astype(np.uint8)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--noisy", required=True)
    ap.add_argument("--reference", required=True)
    ap.add_argument("--denoised", action="append", default=[], metavar="NAME=PATH")
    ap.add_argument("--png")
    ap.add_argument("--require-better", action="store_true")
    a = ap.parse_args()
    noisy, ref = read(a.noisy), read(a.reference)
    base = relmse(noisy, ref)
    print(f"noisy: RelMSE {base:.5f}")
    ok = True
    panels = [noisy]
    for item in a.denoised:
        name, path = item.split("=", 1)
        img = read(path)
        if img.shape != ref.shape or not np.isfinite(img).all():
            print(f"{name}: wrong size or non-finite values")
            ok = False
            continue
        e = relmse(img, ref)
        better = e < base
        print(f"{name}: RelMSE {e:.5f} ({base / max(e, 1e-12):.1f}x less than noisy)"
              if better else f"{name}: RelMSE {e:.5f} (not better than noisy)")
        ok &= better or not a.require_better
        panels.append(img)
    panels.append(ref)
    if a.png:
        from PIL import Image

        Image.fromarray(np.concatenate([tonemap(p) for p in panels], 1)).save(a.png)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
