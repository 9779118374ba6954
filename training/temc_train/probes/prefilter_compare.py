"""Aux prefiltering, temc's against OIDN's, on our scenes (issue 16: an "RT" filter given
only albedo or only normal denoises that image).

    python -m temc_train.probes.prefilter_compare --data ../data/spectral-v2 \\
        --lib ../target/release/libtemc.so --out ../docs/prefilter.md

For every validation and test scene and noisy spp, the noisy albedo and normal are
prefiltered by temc (the C API, an "RT" filter with only that image and an output, as
Cycles calls OIDN) and by OIDN 2.5 (pyoidn, the same call), and compared with the
reference render's albedo and normal (512 spp). Error: MSE for albedo, mean angle in
degrees for normals; geometric means over scenes. Seconds per 128x128 image beside them.
"""

import argparse
import ctypes
import datetime
import time

import numpy as np

from .. import data

FLOAT3 = 3
DEVICE_CPU = 1


class Temc:
    """The few C API calls an aux prefilter needs, through ctypes."""

    def __init__(self, lib: str):
        self.c = c = ctypes.CDLL(lib)
        c.temcNewDevice.restype = ctypes.c_void_p
        c.temcNewFilter.restype = ctypes.c_void_p
        c.temcNewFilter.argtypes = [ctypes.c_void_p, ctypes.c_char_p]
        for f in ("temcCommitDevice", "temcCommitFilter", "temcExecuteFilter",
                  "temcReleaseFilter", "temcReleaseDevice"):
            getattr(c, f).argtypes = [ctypes.c_void_p]
        c.temcSetSharedFilterImage.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_void_p,
                                               ctypes.c_uint32] + [ctypes.c_size_t] * 5
        c.temcGetDeviceError.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_char_p)]
        self.dev = c.temcNewDevice(DEVICE_CPU)
        c.temcCommitDevice(self.dev)
        self.check()

    def check(self):
        msg = ctypes.c_char_p()
        err = self.c.temcGetDeviceError(self.dev, ctypes.byref(msg))
        if err:
            raise RuntimeError(f"temc error {err}: {msg.value.decode()}")

    def prefilter(self, name: str, img: np.ndarray):
        """(prefiltered image, seconds of execute alone)."""
        img = np.ascontiguousarray(img, np.float32)
        out = np.zeros_like(img)
        h, w = img.shape[:2]
        f = self.c.temcNewFilter(self.dev, b"RT")
        for n, a in ((name.encode(), img), (b"output", out)):
            self.c.temcSetSharedFilterImage(f, n, a.ctypes.data, FLOAT3, w, h, 0, 0, 0)
        self.c.temcCommitFilter(f)
        t = time.perf_counter()
        self.c.temcExecuteFilter(f)
        dt = time.perf_counter() - t
        self.c.temcReleaseFilter(f)
        self.check()
        return out, dt


class Oidn:
    """OIDN 2.5 through pyoidn, the same call; one device for the run."""

    def __init__(self):
        import pyoidn

        self.p = pyoidn
        self.dev = pyoidn.Device()
        self.dev.commit()

    def prefilter(self, name: str, img: np.ndarray):
        p = self.p
        img = np.ascontiguousarray(img, np.float32)
        out = np.zeros_like(img)
        f = p.Filter(self.dev, "RT")
        f.set_image(name, img, p.OIDN_FORMAT_FLOAT3)
        f.set_image(p.OIDN_IMAGE_OUTPUT, out, p.OIDN_FORMAT_FLOAT3)
        f.set_quality(p.OIDN_QUALITY_HIGH)
        f.commit()
        t = time.perf_counter()
        f.execute()
        dt = time.perf_counter() - t
        f.release()
        return out, dt


def albedo_error(x, r):
    return float(np.mean((x - r) ** 2))


def normal_error(x, r):
    """Mean angle (degrees) between the directions, over pixels with a reference normal."""
    nx, nr = np.linalg.norm(x, axis=-1), np.linalg.norm(r, axis=-1)
    ok = nr > 0.5
    cos = (x * r).sum(-1)[ok] / np.maximum(nx[ok] * nr[ok], 1e-12)
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).mean())


def measure(scenes, temc: Temc, oidn: Oidn):
    """{(buffer, spp): {method: ([errors], [seconds])}}."""
    res = {}
    for sc in scenes:
        ref = data.read_exr(sc.reference_path)
        for s, spp in enumerate(sc.spp):
            for buf, err in (("albedo", albedo_error), ("normal", normal_error)):
                noisy = sc.a[buf][s] if buf == "albedo" else data.read_exr(sc.noisy_paths[s])["normal"]
                row = res.setdefault((buf, spp), {})
                for method, fn in (("noisy", lambda b, x: (x, 0.0)), ("temc", temc.prefilter),
                                   ("OIDN 2.5", oidn.prefilter)):
                    out, dt = fn(buf, noisy)
                    e, ts = row.setdefault(method, ([], []))
                    e.append(err(out, ref[buf]))
                    ts.append(dt)
    return res


def geomean(v):
    return float(np.exp(np.mean(np.log(np.maximum(v, 1e-30)))))


def write(res, n_scenes, out):
    lines = ["# Aux prefiltering: temc against OIDN", "",
             "Regenerate with `scripts/prefilter-compare` (one command; every number below comes "
             "from that run). An \"RT\" filter given only an albedo (or only a normal) image and an "
             "output prefilters it, as Cycles asks OIDN to: temc with its self-guided filter "
             "(src/prefilter.rs), OIDN 2.5 with its trained prefilter networks (pyoidn, quality "
             "high). Reference: the reference render's albedo and normal (512 spp). Seconds: "
             "the median execute call per image, set-up excluded, 2 threads.",
             f"{n_scenes} scenes (validation and test splits), 128x128, "
             f"{datetime.date.today().isoformat()}.", "",
             "| buffer | spp | error | noisy | temc | OIDN 2.5 | temc s | OIDN s |",
             "|---|---:|---|---:|---:|---:|---:|---:|"]
    for (buf, spp), row in sorted(res.items()):
        unit = "MSE" if buf == "albedo" else "mean angle (deg)"
        e = {m: geomean(v[0]) for m, v in row.items()}
        t = {m: float(np.median(v[1])) for m, v in row.items()}
        lines.append(f"| {buf} | {spp} | {unit}, geo. mean | {e['noisy']:.4g} | {e['temc']:.4g} | "
                     f"{e['OIDN 2.5']:.4g} | {t['temc']:.4f} | {t['OIDN 2.5']:.4f} |")
    lines += ["", "## Reading", ""]
    for (buf, spp), row in sorted(res.items()):
        e = {m: geomean(v[0]) for m, v in row.items()}
        change = lambda m: 100.0 * (e[m] / e["noisy"] - 1.0)  # noqa: E731
        lines.append(f"- {buf} at {spp} spp: temc {change('temc'):+.0f} % against the noisy "
                     f"input, OIDN {change('OIDN 2.5'):+.0f} %; temc's error is "
                     f"{e['temc'] / e['OIDN 2.5']:.2f}x OIDN's.")
    lines += ["", "temc's prefilter is a self-guided filter whose strength follows the noise it "
              "estimates, not a trained network: where that estimate is too high (clean, detailed "
              "aux at high spp) it blurs. The lever that would close the gap is a small network "
              "trained for aux prefiltering on the data set's albedo and normal pairs, as OIDN "
              "ships."]
    with open(out, "w") as f:
        f.write("\n".join(lines) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True)
    ap.add_argument("--lib", required=True, help="libtemc.so (cargo build --release)")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    scenes = data.load_split(a.data, "val") + data.load_split(a.data, "test")
    res = measure(scenes, Temc(a.lib), Oidn())
    write(res, len(scenes), a.out)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
