"""Error metrics, and the denoisers the accuracy report compares: temc models through the
`temc` command line, and OIDN 2.5 through pyoidn.

Metrics (all against the reference render):
- RelMSE: mean of (x - r)^2 / (r^2 + 0.01) over pixels and channels, linear values.
- SMAPE: mean of |x - r| / (|x| + |r| + 0.01), linear values.
- PSNR and SSIM on PQ-encoded R'G'B' (the core's PQ at the reference's automatic
  exposure): perceptually even steps, so errors in shadows and highlights weigh alike.
- Delta E ITP (ITU-R BT.2124): ICtCp from the PQ-encoded Rec.2020 LMS, at 100 cd/m^2 per
  unit after the automatic exposure; a colour difference of intensity and chroma alike.
  dE-I and dE-CtCp are its intensity and chroma parts alone (their sum is not dE ITP: it
  is the length of the three differences together), the second the colour noise the
  paper's chroma/luma split targets.
- mean/ref: the image's mean over the reference's mean (energy kept: 1).
- RelMSE-net (where the data set keeps a prefix of each reference): RelMSE with the
  reference's own noise subtracted (relmse_net), for references whose noise is not far
  below a denoiser's error (512 spp against 64-spp inputs).
"""

import json
import os
import subprocess
import tempfile
import time

import numpy as np
import torch
import torch.nn.functional as F

from . import color
from .data import auto_input_scale, read_exr
from .loss import ictcp as ictcp_planes

EPS = 0.01

def relmse_terms(x, r):
    """RelMSE's terms, one per pixel and channel: relmse is their mean."""
    return (x - r) ** 2 / (r * r + EPS)


def relmse(x, r):
    return float(np.mean(relmse_terms(x, r)))


def reference_variance(ref, prefix, ref_spp, prefix_spp):
    """Per pixel and channel, the variance of the reference's own noise, from the render of
    its first `prefix_spp` samples (temc-render's `--ref-prefix-spp`). With k prefix samples
    of n, ref - prefix = (n - k) / n (rest - prefix), whose expected square is
    sigma^2 (n - k) / (n k); the reference's variance is sigma^2 / n, so it is that square
    times k / (n - k). One pair per pixel: unbiased, noisy pixel by pixel, steady in a mean
    over an image."""
    k, n = prefix_spp, ref_spp
    if not 0 < k < n:
        raise ValueError(f"a prefix of {k} samples of a {n}-sample reference")
    return (ref - prefix) ** 2 * (k / (n - k))


def relmse_net(x, r, ref_var):
    """RelMSE with the reference's own noise taken out. For a reference independent of `x`
    (temc-render gives it its own seed), E[(x - r)^2] = (x - truth)^2 + var(r), so
    subtracting `ref_var` (reference_variance) leaves x's own error, in RelMSE's units.
    May come out at or below zero where x is closer to the truth than the reference is."""
    return float(np.mean(((x - r) ** 2 - ref_var) / (r * r + EPS)))


def reference_relmse(r, ref_var):
    """The reference's own RelMSE against the truth: what relmse_net takes out."""
    return float(np.mean(ref_var / (r * r + EPS)))


def smape(x, r):
    return float(np.mean(np.abs(x - r) / (np.abs(x) + np.abs(r) + EPS)))


def _pq(x, r):
    s = auto_input_scale(r)
    return color.to_pq(x, s)[0].astype(np.float64), color.to_pq(r, s)[0].astype(np.float64)


def psnr_pq(x, r):
    a, b = _pq(x, r)
    mse = np.mean((a - b) ** 2)
    return float(10 * np.log10(1.0 / max(mse, 1e-12)))


def ssim_pq(x, r):
    """Mean SSIM (Gaussian window sigma 1.5, 11 taps) over the PQ channels."""
    a, b = (torch.from_numpy(np.moveaxis(v, -1, 0)[:, None].copy()) for v in _pq(x, r))
    g = torch.exp(-0.5 * (torch.arange(-5, 6, dtype=torch.float64) / 1.5) ** 2)
    g = (g / g.sum())
    k = (g[:, None] * g[None]).view(1, 1, 11, 11)
    blur = lambda t: F.conv2d(F.pad(t, (5,) * 4, mode="replicate"), k)
    ma, mb = blur(a), blur(b)
    saa, sbb, sab = blur(a * a) - ma ** 2, blur(b * b) - mb ** 2, blur(a * b) - ma * mb
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    s = ((2 * ma * mb + c1) * (2 * sab + c2)) / ((ma ** 2 + mb ** 2 + c1) * (saa + sbb + c2))
    return float(s.mean())


def ictcp(rgb, scale):
    """I, Ct, Cp planes of an [H, W, 3] linear image at `scale` (loss.ictcp, in float64)."""
    lin = torch.from_numpy(np.moveaxis(color.sanitize_rgb(rgb) * scale, -1, 0)[None])
    return tuple(ictcp_planes(lin, floor=0.0)[0].numpy())


def itp_errors(x, r) -> dict:
    """Delta E ITP (BT.2124: 720 sqrt(dI^2 + dT^2 + dP^2), T = Ct / 2, P = Cp) of x from
    the reference r at the reference's automatic exposure, and its two parts: dE-I, mean
    720 |dI| (light and dark, not colour), and dE-CtCp, mean 720 sqrt(dT^2 + dP^2) (the
    colour noise the paper's chroma/luma split targets). One ICtCp conversion for all
    three."""
    s = auto_input_scale(r)
    (i1, t1, p1), (i2, t2, p2) = ictcp(x, s), ictcp(r, s)
    di, dt, dp = 720 * (i1 - i2), 360 * (t1 - t2), 720 * (p1 - p2)
    return {"dE-ITP": float(np.mean(np.sqrt(di ** 2 + dt ** 2 + dp ** 2))),
            "dE-I": float(np.mean(np.abs(di))),
            "dE-CtCp": float(np.mean(np.sqrt(dt ** 2 + dp ** 2)))}


def delta_e_itp(x, r):
    return itp_errors(x, r)["dE-ITP"]


def delta_e_intensity(x, r):
    """Delta E ITP's intensity part alone (itp_errors)."""
    return itp_errors(x, r)["dE-I"]


def delta_e_chroma(x, r):
    """Delta E ITP's chroma part alone (itp_errors)."""
    return itp_errors(x, r)["dE-CtCp"]


def mean_ratio(x, r):
    """The image's mean over the reference's: a denoiser must keep it (1.0). Both are taken
    in the space every output lives in (color.sanitize_rgb: out-of-gamut colours mapped to
    non-negative at equal luminance, values capped at LINEAR_MAX), so the ratio measures what
    the denoiser did, not the contract's gamut map: a 532 nm laser's negative red is +17 %
    red after the map, and an emitter above LINEAR_MAX loses 31 % of one scene's raw mean."""
    xs, rs = color.sanitize_rgb(x), color.sanitize_rgb(r)
    return float(np.mean(xs, dtype=np.float64) / max(np.mean(rs, dtype=np.float64), 1e-30))


BORDER_PX = 8


def border_ratio(x, r):
    """mean_ratio over the image's outer BORDER_PX-wide frame only: a border artefact (a
    darkened or brightened edge, issue 36) moves it from 1.0 while the whole image's mean
    hardly moves."""
    frame = np.ones(x.shape[:2], bool)
    b = BORDER_PX
    frame[b:-b, b:-b] = False
    return mean_ratio(x[frame], r[frame])


DARK_SHARE = 0.25


def dark_relmse(x, r):
    """RelMSE over the darkest DARK_SHARE of the reference's pixels (by luminance): the
    blotches a denoiser leaves in dark, sparsely sampled regions (issue 36) weigh little in
    the whole image's RelMSE, whose error sits where the light is."""
    y = (np.asarray(r, np.float64) * color.LUMA).sum(-1)
    dark = y <= np.quantile(y, DARK_SHARE)
    return relmse(x[dark], r[dark])


METRICS = {"RelMSE": relmse, "SMAPE": smape, "PSNR-PQ": psnr_pq, "SSIM-PQ": ssim_pq,
           "dE-ITP": delta_e_itp, "dE-I": delta_e_intensity, "dE-CtCp": delta_e_chroma,
           "mean/ref": mean_ratio}


def all_metrics(x, r) -> dict:
    itp = itp_errors(x, r)  # the three Delta E ITP metrics from one conversion
    return {k: itp[k] if k in itp else f(x, r) for k, f in METRICS.items()}


def read_pfm(path):
    with open(path, "rb") as f:
        kind = f.readline().strip()
        w, h = (int(v) for v in f.readline().split())
        scale = float(f.readline())
        data = np.frombuffer(f.read(), "<f4" if scale < 0 else ">f4")
    ch = 3 if kind == b"PF" else 1
    return np.flipud(data.reshape(h, w, ch)).astype(np.float32)


def write_pfm(path, img):
    """`img` [H, W, 3] or [H, W] as a little-endian PFM (read_pfm's format, rows bottom up)."""
    img = np.asarray(img, np.float32)
    h, w = img.shape[:2]
    kind = "PF" if img.ndim == 3 else "Pf"
    with open(path, "wb") as f:
        f.write(f"{kind}\n{w} {h}\n-1.0\n".encode())
        f.write(np.ascontiguousarray(np.flipud(img), "<f4").tobytes())


def temc_denoise(binary, model, exr, threads=2, aux="full"):
    """Runs `temc denoise` on a temc-render EXR with the aux layers `aux` (none, albedo,
    full); returns (image, seconds to execute). The model load (commit) is left out, as
    pyoidn's warm filter leaves it out for OIDN."""
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "out.pfm")
        cmd = [binary, "denoise", "--model", model, "--color", exr, "-o", out, "--json",
               "--threads", str(threads), "--aux", aux]
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)}: {r.stderr.strip()}")
        rep = json.loads(r.stdout.strip().splitlines()[-1])
        return read_pfm(out), rep["seconds"]["execute"]


def oidn_denoise(layers, quality="high", aux="full"):
    """OIDN 2.5 (pyoidn) in HDR mode with the aux buffers `aux` (none, albedo, full: albedo
    and normal); returns (image, seconds).
    The first call per quality warms pyoidn's cached filter up and is not timed."""
    import pyoidn

    args = dict(hdr=True, quality=quality)
    c = np.ascontiguousarray(layers["color"], np.float32)
    a = np.ascontiguousarray(layers["albedo"], np.float32) if aux != "none" else None
    n = np.ascontiguousarray(layers["normal"], np.float32) if aux == "full" else None
    key = (quality, aux, c.shape)
    if key not in _warm:
        pyoidn.denoise(c, a, n, **args)
        _warm.add(key)
    t = time.perf_counter()
    out = pyoidn.denoise(c, a, n, **args)
    return np.asarray(out, np.float32), time.perf_counter() - t


_warm = set()

__all__ = ["all_metrics", "read_exr", "temc_denoise", "oidn_denoise", "METRICS"]
