"""The colour pipeline of docs/contracts.md §1 in numpy, as training sees it.

The Rust core (src/color/) is the reference; tests/test_color_vectors.py checks this module
against the vectors the Rust code writes, to 1e-5. Arrays hold pixels on the last axis
(..., 3); arithmetic is float64, results float32 like the network's tensors.
"""

import re
from pathlib import Path

import numpy as np

LINEAR_MAX = 65504.0
LUMA = np.array([0.2126, 0.7152, 0.0722])
NITS_PER_UNIT = 100.0
AUTO_EXPOSURE_KEY = 0.18  # src/color/mod.rs: scale = key / log-average luminance
PQ_MAX_NITS = 10000.0
HIGHLIGHT_KNEE = np.float32(0.95)

M1 = 2610.0 / 16384.0
M2 = 2523.0 / 4096.0 * 128.0
C1 = 3424.0 / 4096.0
C2 = 2413.0 / 4096.0 * 32.0
C3 = 2392.0 / 4096.0 * 32.0

XYZ_TO_SRGB = np.array([
    [3.2406, -1.5372, -0.4986],
    [-0.9689, 1.8758, 0.0415],
    [0.0557, -0.2040, 1.0570],
])


def sanitize_channel(x):
    x = np.asarray(x, dtype=np.float32).astype(np.float64)
    x = np.where(np.isnan(x) | (x == -np.inf), 0.0, x)
    return np.minimum(x, LINEAR_MAX)


def sanitize_rgb(rgb):
    """NaN/-Inf -> 0, +Inf/huge -> 65504, then negative pixels desaturated toward their
    luminance (keeps Y and hue); non-positive Y -> black."""
    c = sanitize_channel(rgb)
    y = (c * LUMA).sum(-1, keepdims=True)
    mn = c.min(-1, keepdims=True)
    neg = mn < 0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(neg & (y > 0), y / (y - mn), 1.0)
    fixed = np.maximum(y + t * (c - y), 0.0)
    fixed = np.where(neg & (y <= 0), 0.0, fixed)
    return np.where(neg, fixed.astype(np.float32).astype(np.float64), c)


def pq_encode(y):
    y = np.clip(np.nan_to_num(np.asarray(y, np.float64), nan=0.0), 0.0, 1.0)
    ym = y ** M1
    return ((C1 + C2 * ym) / (1.0 + C3 * ym)) ** M2


def pq_decode(e):
    e = np.clip(np.nan_to_num(np.asarray(e, np.float64), nan=0.0), 0.0, 1.0)
    p = e ** (1.0 / M2)
    return (np.maximum(p - C1, 0.0) / (C2 - C3 * p)) ** (1.0 / M1)


def _wrap(h):
    w = h - np.floor(h)
    return np.where(w >= 1.0, 0.0, w)


def rgb_to_hsv(rgb):
    """Hexcone HSV in [0,1]; H = 0 where max == min, S = 0 where max == 0."""
    rgb = np.asarray(rgb, np.float64)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    mx = rgb.max(-1)
    mn = rgb.min(-1)
    d = mx - mn
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(mx > 0, d / mx, 0.0)
        h6 = np.where(mx == r, (g - b) / d, np.where(mx == g, (b - r) / d + 2.0, (r - g) / d + 4.0))
    h = np.where(d > 0, _wrap((h6 / 6.0).astype(np.float32).astype(np.float64)), 0.0)
    return np.stack([h, s, mx], -1).astype(np.float32)


def sanitize_hsv(hsv):
    hsv = np.asarray(hsv, np.float32).astype(np.float64)
    hsv = np.where(np.isnan(hsv), 0.0, hsv)
    h = np.where(np.isfinite(hsv[..., 0]), _wrap(np.where(np.isfinite(hsv[..., 0]), hsv[..., 0], 0.0)), 0.0)
    # The wrap runs in f32 in the core; round the same way.
    h = _wrap(h.astype(np.float32).astype(np.float64))
    return np.stack([h, np.clip(hsv[..., 1], 0, 1), np.clip(hsv[..., 2], 0, 1)], -1)


def hsv_to_rgb(hsv):
    """Six-sector inverse; any input gives R'G'B' in [0,1]."""
    h, s, v = np.moveaxis(sanitize_hsv(hsv), -1, 0)
    h6 = h * 6.0
    sector = np.floor(h6)
    f = h6 - sector
    p = v * (1 - s)
    q = v * (1 - s * f)
    t = v * (1 - s * (1 - f))
    i = sector.astype(np.int64) % 6
    choices = [np.stack(c, -1) for c in ((v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q))]
    out = np.select([(i == k)[..., None] for k in range(6)], choices)
    return out.astype(np.float32)


def to_pq(rgb, input_scale=1.0, nits_per_unit=NITS_PER_UNIT):
    """Linear sRGB -> (PQ R'G'B' float32 [...,3], excess float32 [...]): sanitise, scale to
    nits, divide by the brightest channel if it passes 10000 cd/m2 (remembered as excess)."""
    k = np.float64(np.float32(input_scale)) * nits_per_unit / PQ_MAX_NITS
    y = sanitize_rgb(rgb) * k
    m = y.max(-1, keepdims=True)
    over = m > 1.0
    y = np.where(over, y / np.where(over, m, 1.0), y)
    excess = np.minimum(np.where(over, m, 1.0)[..., 0], np.finfo(np.float32).max)
    return pq_encode(y).astype(np.float32), excess.astype(np.float32)


def encode(rgb, input_scale=1.0, nits_per_unit=NITS_PER_UNIT):
    """Linear sRGB -> (hsv float32 [...,3], excess float32 [...])."""
    pq, excess = to_pq(rgb, input_scale, nits_per_unit)
    return rgb_to_hsv(pq), excess


def decode(hsv, excess, input_scale=1.0, nits_per_unit=NITS_PER_UNIT):
    """Network HSV (any values) -> linear sRGB, with the highlight restore rule."""
    hs = sanitize_hsv(hsv)
    pq = hsv_to_rgb(hs).astype(np.float64)
    k = np.float64(np.float32(input_scale)) * nits_per_unit / PQ_MAX_NITS
    ex = np.asarray(excess, np.float32).astype(np.float64)
    ex = np.where(np.isfinite(ex) & (ex > 1.0), ex, 1.0)
    v = hs[..., 2].astype(np.float32)
    w = np.clip((v - HIGHLIGHT_KNEE) / (np.float32(1.0) - HIGHLIGHT_KNEE), 0, 1).astype(np.float64)
    restore = 1.0 + (ex - 1.0) * w
    return np.minimum(pq_decode(pq) * restore[..., None] / k, LINEAR_MAX).astype(np.float32)


# --- auxiliary buffers ---------------------------------------------------------------

def albedo(a):
    a = np.asarray(a, np.float32)
    return np.clip(np.where(np.isnan(a), 0.0, a), 0.0, 1.0).astype(np.float32)


def normal(n):
    n = np.asarray(n, np.float32).astype(np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        len2 = (n * n).sum(-1, keepdims=True)
        ok = np.isfinite(len2) & (len2 >= 1e-30)
        unit = np.where(ok, n / np.sqrt(np.where(ok, len2, 1.0)), 0.0)
    return np.clip((unit + 1.0) * 0.5, 0.0, 1.0).astype(np.float32)


def depth_scale(d):
    d = np.asarray(d, np.float32)
    ok = np.isfinite(d) & (d > 0)
    return float(d[ok].max()) if ok.any() else None


def depth(d, scale):
    d = np.asarray(d, np.float32)
    if scale is None:
        return np.zeros_like(d)
    with np.errstate(invalid="ignore"):
        out = np.where(np.isnan(d) | (d <= 0), 0.0, np.minimum(d / np.float32(scale), 1.0))
    return out.astype(np.float32)


def aux_channels(albedo_img, normal_img, depth_img):
    """One image's auxiliary buffers ([H,W,3], [H,W,3], [H,W]) -> the network's `aux`
    [7,H,W] float32. The depth statistic is taken over the whole image, as the core does
    before tiling."""
    d = depth(depth_img, depth_scale(depth_img))
    return np.concatenate([np.moveaxis(albedo(albedo_img), -1, 0),
                           np.moveaxis(normal(normal_img), -1, 0), d[None]]).astype(np.float32)


# --- spectra -------------------------------------------------------------------------

# The CIE 1931 2-degree observer's 1 nm table has one home, the Rust source
# color/src/cie1931.rs (a const array the tracer's film reads per path); it is parsed here
# at import so Python converts spectra with the very same numbers.
CIE1931_RS = Path(__file__).resolve().parents[2] / "color" / "src" / "cie1931.rs"
_ROW = re.compile(r"^\s*\[\s*([^,\]]+),\s*([^,\]]+),\s*([^,\]]+)\s*\],\s*//\s*(\d+)\s*$")


def parse_cie1931_rs(text):
    """(first nm, [n, 3] float64) from the text of color/src/cie1931.rs: `FIRST_NM` and the
    rows `[x, y, z], // nm` of `CIE_1931_2DEG`, whose declared length, 1 nm steps and
    first wavelength are checked. Raises ValueError on anything else."""
    first = re.search(r"pub const FIRST_NM: f64 = ([0-9.]+);", text)
    decl = re.search(r"pub const CIE_1931_2DEG: \[\[f64; 3\]; (\d+)\] = \[(.*?)\n\];", text, re.S)
    if not first or not decl:
        raise ValueError("cie1931.rs: FIRST_NM or CIE_1931_2DEG not found")
    rows, nms = [], []
    for line in decl.group(2).splitlines():
        if not line.strip():
            continue
        m = _ROW.match(line)
        if not m:
            raise ValueError(f"cie1931.rs: unexpected line {line!r}")
        rows.append([float(m.group(k).replace("_", "")) for k in (1, 2, 3)])
        nms.append(int(m.group(4)))
    first_nm = float(first.group(1))
    n = int(decl.group(1))
    if len(rows) != n or nms != list(range(int(first_nm), int(first_nm) + n)):
        raise ValueError(f"cie1931.rs: {len(rows)} rows for {n} declared, or not 1 nm steps "
                         f"from {first_nm} nm")
    return first_nm, np.array(rows, np.float64)


CIE_FIRST_NM, CIE_1931_2DEG = parse_cie1931_rs(CIE1931_RS.read_text())
VISIBLE_NM = (CIE_FIRST_NM, CIE_FIRST_NM + len(CIE_1931_2DEG) - 1)


def cmf_tabulated(lam):
    """CIE 1931 2-degree CMFs from the CIE's table, linearly interpolated, 0 outside
    360..830 nm; [..., 3]. Same arithmetic as color/src/cie.rs `cmf_tabulated`."""
    x = np.asarray(lam, np.float64) - CIE_FIRST_NM
    t = CIE_1931_2DEG
    inside = (x >= 0) & (x <= len(t) - 1)
    xc = np.where(inside, x, 0.0)
    i = np.minimum(xc.astype(np.int64), len(t) - 2)
    f = (xc - i)[..., None]
    v = t[i] + (t[i + 1] - t[i]) * f
    return np.where(inside[..., None], v, 0.0)


def cmf_tabulated_integral(a, b):
    """Exact integral over [a, b] nm of the piecewise-linear `cmf_tabulated` (trapezoids
    between whole nm, clipped to [a, b]), as the core computes it."""
    lo, hi = max(a, VISIBLE_NM[0]), min(b, VISIBLE_NM[1])
    if hi <= lo:
        return np.zeros(3)
    knots = np.concatenate([[lo], np.arange(np.floor(lo) + 1.0, hi), [hi]])
    c = cmf_tabulated(knots)
    return (0.5 * (c[:-1] + c[1:]) * np.diff(knots)[:, None]).sum(0)


def band_weights(edges):
    """Per band, the XYZ a unit value contributes (Y of a flat unit spectrum = 1)."""
    edges = np.asarray(edges, np.float32).astype(np.float64)
    y_norm = cmf_tabulated_integral(*VISIBLE_NM)[1]
    return np.stack([cmf_tabulated_integral(a, b) / y_norm
                     for a, b in zip(edges[:-1], edges[1:])])


def spectral_to_xyz(values, edges):
    v = np.maximum(sanitize_channel(values), 0.0)
    return v @ band_weights(edges)


def spectral_to_linear_srgb(values, edges):
    return (spectral_to_xyz(values, edges) @ XYZ_TO_SRGB.T).astype(np.float32)
