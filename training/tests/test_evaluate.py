"""The accuracy report's metrics (evaluate.py) against independent formulas: ICtCp and
Delta E ITP from colour-science, RelMSE, SMAPE, PSNR and SSIM re-implemented here in plain
numpy from their definitions. The README's numbers come from these functions."""

import warnings

import numpy as np
import pytest

from temc_train import color
from temc_train import evaluate as ev

with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # colour warns that SciPy is absent; nothing here uses it
    import colour

# SMPTE ST 2084, written out again so that the test does not lean on color.py.
PQ_M1, PQ_M2 = 2610 / 16384, 2523 / 4096 * 128
PQ_C1, PQ_C2, PQ_C3 = 3424 / 4096, 2413 / 4096 * 32, 2392 / 4096 * 32


def pq(y):
    ym = np.clip(y, 0, 1) ** PQ_M1
    return ((PQ_C1 + PQ_C2 * ym) / (1 + PQ_C3 * ym)) ** PQ_M2


def exposure(r):
    """0.18 over the log-average Rec.709 luminance of the pixels above 1e-8."""
    y = r.reshape(-1, 3).astype(np.float64) @ [0.2126, 0.7152, 0.0722]
    return 0.18 / np.exp(np.log(y[y > 1e-8]).mean())


def pq_pair(x, r):
    """Both images PQ-encoded at the reference's exposure, 100 cd/m^2 per unit, with the
    brightest channel above 10000 cd/m^2 dividing the pixel (the core's ceiling)."""
    def enc(v):
        y = v.astype(np.float64) * exposure(r) * 100 / 10000
        m = np.maximum(y.max(-1, keepdims=True), 1.0)
        return pq(y / m)
    return enc(x), enc(r)


def images(seed=0, h=24, w=20):
    """A smooth positive reference with a bright patch and a noisy estimate of it."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    r = np.stack([0.2 + 0.6 * xx, 0.1 + 0.5 * yy, 0.3 + 0.2 * xx * yy], -1)
    r[4:8, 4:8] *= 40.0
    x = r * rng.exponential(1.0, r.shape)
    return x.astype(np.float32), r.astype(np.float32)


def ictcp_colour(rgb709, scale):
    """ICtCp of linear Rec.709 values through colour-science: to BT.2020, in cd/m^2."""
    cs = colour.RGB_COLOURSPACES
    rgb2020 = colour.RGB_to_RGB(rgb709.astype(np.float64) * scale * 100, cs["ITU-R BT.709"],
                                cs["ITU-R BT.2020"])
    return colour.RGB_to_ICtCp(rgb2020, method="ITU-R BT.2100-2 PQ", L_p=10000)


def test_relmse_and_smape_follow_their_definitions():
    x, r = images()
    x64, r64 = x.astype(np.float64), r.astype(np.float64)
    assert ev.relmse(x, r) == pytest.approx(np.mean((x64 - r64) ** 2 / (r64 ** 2 + 0.01)), rel=1e-6)
    assert ev.smape(x, r) == pytest.approx(
        np.mean(np.abs(x64 - r64) / (np.abs(x64) + np.abs(r64) + 0.01)), rel=1e-6)
    one, two = np.ones((2, 2, 3), np.float32), np.full((2, 2, 3), 2.0, np.float32)
    assert ev.relmse(two, one) == pytest.approx(1 / 1.01)
    assert ev.smape(two, one) == pytest.approx(1 / 3.01)
    assert ev.relmse(one, one) == 0 and ev.smape(one, one) == 0


def test_mean_ratio_is_the_ratio_of_means():
    x, r = images()
    assert ev.mean_ratio(x, r) == pytest.approx(x.astype(np.float64).mean() / r.astype(np.float64).mean())
    assert ev.mean_ratio(r, r) == 1.0


def test_mean_ratio_is_taken_in_the_output_space():
    # An out-of-gamut reference (negative red at positive luminance) and one above the
    # ceiling: the ratio compares what every output is mapped to, so the reference's own
    # gamut map gives 1.
    r = np.array([[[-0.2, 1.0, 0.1], [7e4, 7e4, 7e4]]], np.float32)
    assert ev.mean_ratio(color.sanitize_rgb(r), r) == pytest.approx(1.0)
    raw = r.astype(np.float64).mean()
    assert abs(color.sanitize_rgb(r).astype(np.float64).mean() / raw - 1) > 0.05


def test_psnr_pq_is_that_of_the_pq_encoded_images():
    x, r = images()
    a, b = pq_pair(x, r)
    want = 10 * np.log10(1 / np.mean((a - b) ** 2))
    assert ev.psnr_pq(x, r) == pytest.approx(want, abs=1e-4)
    assert 10 < want < 60


def ssim_numpy(a, b):
    """Mean SSIM per channel: 11-tap Gaussian window (sigma 1.5), edges replicated,
    C1 = (0.01 L)^2, C2 = (0.03 L)^2 with L = 1; a loop over the window, no convolution."""
    g = np.exp(-0.5 * (np.arange(-5, 6) / 1.5) ** 2)
    k = np.outer(g, g) / g.sum() ** 2
    h, w = a.shape[:2]

    def blur(t):
        p = np.pad(t, ((5, 5), (5, 5), (0, 0)), mode="edge")
        return sum(k[i, j] * p[i:i + h, j:j + w] for i in range(11) for j in range(11))

    ma, mb = blur(a), blur(b)
    va, vb, cov = blur(a * a) - ma ** 2, blur(b * b) - mb ** 2, blur(a * b) - ma * mb
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    return np.mean((2 * ma * mb + c1) * (2 * cov + c2) / ((ma ** 2 + mb ** 2 + c1) * (va + vb + c2)))


def test_ssim_pq_matches_a_direct_implementation():
    x, r = images()
    assert ev.ssim_pq(x, r) == pytest.approx(ssim_numpy(*pq_pair(x, r)), abs=1e-6)
    assert ev.ssim_pq(r, r) == pytest.approx(1.0, abs=1e-12)
    assert ev.ssim_pq(x, r) < 0.95


def test_ictcp_matches_colour_science():
    x, r = images()
    s = ev.auto_input_scale(r)
    assert s == pytest.approx(exposure(r), rel=1e-6)
    want = ictcp_colour(x, s)
    for got, w in zip(ev.ictcp(x, s), np.moveaxis(want, -1, 0)):
        np.testing.assert_allclose(got, w, atol=2e-6)


def test_delta_e_itp_matches_colour_science():
    x, r = images()
    s = ev.auto_input_scale(r)
    want = np.mean(colour.delta_E(ictcp_colour(x, s), ictcp_colour(r, s), method="ITP"))
    assert ev.delta_e_itp(x, r) == pytest.approx(want, rel=1e-5)
    assert ev.delta_e_itp(r, r) == 0


@pytest.mark.parametrize("axis, weight", [(0, 1.0), (1, 0.5), (2, 1.0)])
def test_delta_e_itp_weighs_each_axis_as_bt2124(axis, weight):
    # BT.2124: Delta E ITP = 720 sqrt(dI^2 + dT^2 + dP^2) with T = Ct / 2 and P = Cp. Move
    # the reference's pixels by d along one ICtCp axis (inverted through colour-science):
    # the error is 720 d times that axis's weight.
    _, r = images()
    r = r / 4  # keeps the moved colours inside the gamut, where sanitising does nothing
    s = ev.auto_input_scale(r)
    moved = ictcp_colour(r, s)
    d = 2e-3
    moved[..., axis] += d
    cs = colour.RGB_COLOURSPACES
    rgb2020 = colour.ICtCp_to_RGB(moved, method="ITU-R BT.2100-2 PQ", L_p=10000)
    x = colour.RGB_to_RGB(rgb2020, cs["ITU-R BT.2020"], cs["ITU-R BT.709"]) / (s * 100)
    assert x.min() > 0
    assert ev.delta_e_itp(x, r) == pytest.approx(720 * d * weight, rel=1e-3)
    # Its parts: a move along I is all intensity, one along Ct or Cp all chroma.
    intensity, chroma = ev.delta_e_intensity(x, r), ev.delta_e_chroma(x, r)
    moved_part, other = (intensity, chroma) if axis == 0 else (chroma, intensity)
    assert moved_part == pytest.approx(720 * d * weight, rel=1e-3)
    assert other < 1e-3 * moved_part


def test_all_metrics_names_every_metric():
    x, r = images()
    m = ev.all_metrics(x, r)
    assert list(m) == ["RelMSE", "SMAPE", "PSNR-PQ", "SSIM-PQ", "dE-ITP", "dE-I", "dE-CtCp", "mean/ref"]
    assert m["dE-ITP"] == ev.delta_e_itp(x, r) and m["RelMSE"] == ev.relmse(x, r)


def test_border_ratio_sees_only_the_frame():
    r = np.full((64, 48, 3), 0.5, np.float32)
    edge = r.copy()
    edge[:ev.BORDER_PX] *= 0.9           # the top rows: part of the frame
    inner = r.copy()
    inner[20:40, 20:30] *= 0.5           # inside the frame
    assert ev.border_ratio(edge, r) < 0.99 and ev.mean_ratio(edge, r) > ev.border_ratio(edge, r)
    assert ev.border_ratio(inner, r) == pytest.approx(1.0)
    assert ev.mean_ratio(inner, r) < 0.99


def test_dark_relmse_sees_only_the_darkest_pixels():
    r = np.full((40, 40, 3), 1.0, np.float32)
    r[:, :10] = 0.01                      # the darkest quarter
    blotch, glare = r.copy(), r.copy()
    blotch[5:8, 2:5] = 0.2                # a blotch in the dark
    glare[20:23, 20:23] = 1.5             # an error as large in the light
    # All of the blotch's error lies in the quarter: four times its whole-image mean.
    assert ev.dark_relmse(blotch, r) == pytest.approx(4 * ev.relmse(blotch, r), rel=1e-6)
    assert ev.relmse(blotch, r) > 0
    assert ev.dark_relmse(glare, r) == 0 and ev.relmse(glare, r) > 0


def test_pfm_round_trip(tmp_path):
    rgb = np.random.default_rng(3).random((5, 7, 3)).astype(np.float32)
    grey = rgb[..., 0].copy()
    ev.write_pfm(tmp_path / "c.pfm", rgb)
    ev.write_pfm(tmp_path / "g.pfm", grey)
    assert np.array_equal(ev.read_pfm(tmp_path / "c.pfm"), rgb)
    assert np.array_equal(ev.read_pfm(tmp_path / "g.pfm")[..., 0], grey)


def test_reference_variance_and_net_relmse_recover_the_truth():
    # Per-pixel samples around a known truth: the reference is the mean of n samples, its
    # prefix the mean of the first k, and the estimate must give the reference's
    # variance sigma^2 / n in the mean over pixels; the net RelMSE of the truth itself is
    # then about zero while its plain RelMSE is the reference's own error.
    rng = np.random.default_rng(7)
    h, w, n, k = 256, 256, 512, 64
    truth = np.full((h, w, 3), 2.0)
    sigma = 1.5
    # The means of the first k samples and of the other n - k, drawn as such.
    prefix = truth + sigma / np.sqrt(k) * rng.standard_normal(truth.shape)
    rest = truth + sigma / np.sqrt(n - k) * rng.standard_normal(truth.shape)
    ref = (k * prefix + (n - k) * rest) / n
    var = ev.reference_variance(ref, prefix, n, k)
    assert np.mean(var) == pytest.approx(sigma**2 / n, rel=0.05)
    denom = ref * ref + ev.EPS
    own = float(np.mean((truth - ref) ** 2 / denom))
    assert ev.reference_relmse(ref, var) == pytest.approx(own, rel=0.05)
    assert ev.relmse(truth, ref) == pytest.approx(own, rel=1e-9)
    assert abs(ev.relmse_net(truth, ref, var)) < 0.05 * own
    # An estimate with its own error keeps that error, not the reference's on top.
    x = truth + 0.05 * rng.standard_normal(truth.shape)
    assert ev.relmse_net(x, ref, var) == pytest.approx(np.mean((x - truth) ** 2 / denom), rel=0.05)
    with pytest.raises(ValueError):
        ev.reference_variance(ref, prefix, n, n)
