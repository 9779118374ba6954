"""The PyTorch reconstruction (temc_train/reconstruct.py) against the shared vectors
(tests/data/recon_vectors.json, which Rust checks too) in float32, and the properties the
spec promises: border renormalisation, constants and means kept, finite for any logits."""

import json
import math
import pathlib

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from temc_train.vectors import recon_vectors
from temc_train.reconstruct import (LINEAR_MAX, LOGIT_MAX, LUMA, RANGE_TAU, aux_opened, channels, opened,
                                    median9, range_threshold, reach, reconstruct)

VECTORS = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "recon_vectors.json"
DOC = json.loads(VECTORS.read_text())


def num(v):
    return {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}.get(v, v)


def decode(case):
    """The case's flat lists as the arrays recon_vectors.run takes."""
    h, w = case["h"], case["w"]
    arr = lambda v, hh, ww: np.array([num(x) for x in v], np.float64).reshape(-1, hh, ww)
    c = dict(case, rgb=arr(case["rgb"], h, w), filters=[
        arr(f, h >> l, w >> l) for l, f in enumerate(case["filters"])])
    c["albedo"] = None if case["albedo"] is None else arr(case["albedo"], h, w)
    c["aux"] = None if case.get("aux") is None else arr(case["aux"], h, w)
    c.setdefault("range_opening", "plain")
    c.setdefault("coarse_clamp", False)
    return c


def close(got, want, tol):
    err = np.abs(got - want) / np.maximum(1.0, np.abs(want))
    return float(err.max())


@pytest.mark.parametrize("case", DOC["cases"], ids=[c["name"] for c in DOC["cases"]])
def test_float32_matches_the_vectors(case):
    want = np.array(case["out"], np.float64).reshape(3, case["h"], case["w"])
    got = recon_vectors.run(decode(case), torch.float32)
    assert close(got, want, DOC["tolerance"]) <= DOC["tolerance"]


@pytest.mark.parametrize("case", DOC["cases"], ids=[c["name"] for c in DOC["cases"]])
def test_the_vectors_are_current(case):
    want = np.array(case["out"], np.float64).reshape(3, case["h"], case["w"])
    assert close(recon_vectors.run(decode(case), torch.float64), want, 1e-8) <= 1e-8


def random_filters(gen, n, h, w, levels, kernel, sd):
    return [sd * torch.randn(n, channels(kernel), h >> l, w >> l, generator=gen)
            for l in range(levels)]


def lum(x):
    return sum(LUMA[c] * x[:, c] for c in range(3))


def test_reach_and_channels():
    assert reach(3, 5) == 17 and reach(1, 5) == 2 and reach(2, 3) == 4
    assert reach(3, 5, "bilinear") == 20 and reach(1, 5, "bilinear") == 2
    assert channels(5) == 52


@pytest.mark.parametrize("upsample", ["nearest", "bilinear"])
@pytest.mark.parametrize("levels,kernel", [(2, 3), (3, 5)])
def test_an_impulse_reaches_no_farther_than_reach_says(levels, kernel, upsample):
    """The tile overlap rests on reach: measured over every phase of the coarsest block, an
    impulse moves no output farther; bilinear reaches 2^(L-1) - 1 px past nearest."""
    gen = torch.Generator().manual_seed(11)
    n = 64
    f = [x.double() for x in random_filters(gen, 1, n, n, levels, kernel, 1.0)]
    base = torch.rand(1, 3, n, n, generator=gen, dtype=torch.float64) + 0.5

    def farthest(up):
        far = 0
        for phase in range(2 ** (levels - 1)):
            cy = cx = n // 2 + phase
            bumped = base.clone()
            bumped[0, :, cy, cx] += 1.0
            d = reconstruct(bumped, None, f, kernel, upsample=up) - reconstruct(base, None, f, kernel, upsample=up)
            ys, xs = np.nonzero(d[0].abs().amax(0).numpy() > 1e-12)
            far = max(far, int(np.maximum(np.abs(ys - cy), np.abs(xs - cx)).max()))
        return far

    assert farthest(upsample) <= reach(levels, kernel, upsample)
    if upsample == "bilinear":
        assert farthest("bilinear") - farthest("nearest") == 2 ** (levels - 1) - 1


@pytest.mark.parametrize("blend", [-2.0, 0.0, 30.0])
def test_bilinear_composition_keeps_the_mean_and_shows_no_block_steps(blend):
    """Each coarse pixel hands on four fine pixels' worth (edges replicated), so the image's
    mean moves to the coarse level's as with nearest; a coarse ramp arrives as a ramp, where
    nearest leaves 2x2 steps."""
    from temc_train.reconstruct import _compose
    gen = torch.Generator().manual_seed(5)
    fine = torch.rand(1, 1, 16, 12, generator=gen, dtype=torch.float64)
    coarse = torch.rand(1, 1, 8, 6, generator=gen, dtype=torch.float64)
    b = torch.full((1, 1, 16, 12), blend, dtype=torch.float64)
    s = torch.sigmoid(torch.tensor(blend, dtype=torch.float64))
    for up in ("nearest", "bilinear"):
        got = _compose(fine, coarse, b, up).mean()
        assert torch.allclose(got, fine.mean() + s * (coarse.mean() - fine.mean()), rtol=1e-12)
    ramp = torch.arange(8, dtype=torch.float64).view(1, 1, 8, 1).expand(1, 1, 8, 6)
    flat = torch.zeros(1, 1, 16, 12, dtype=torch.float64)
    up = _compose(flat, ramp, torch.full_like(flat, 30.0), "bilinear")[0, 0, 1:-1, 0]
    assert torch.allclose(up.diff(), torch.full((13,), 0.5, dtype=torch.float64))
    steps = _compose(flat, ramp, torch.full_like(flat, 30.0), "nearest")[0, 0, 1:-1, 0].diff()
    assert set(steps.round(decimals=6).tolist()) == {0.0, 1.0}


def test_the_chroma_composition_scales_its_correction_and_keeps_every_channel():
    """Where a coarse correction would take a channel below CHROMA_KEEP of its fine value, the
    whole correction shrinks, all three channels alike, to where the first one reaches that
    floor; elsewhere it is added whole (the luma composition's _compose)."""
    from temc_train.reconstruct import CHROMA_KEEP, _compose, _compose_chroma, _correction
    gen = torch.Generator().manual_seed(9)
    fine = torch.rand(2, 3, 16, 12, generator=gen, dtype=torch.float64) ** 3
    coarse = torch.rand(2, 3, 8, 6, generator=gen, dtype=torch.float64) ** 3
    blend = torch.randn(2, 1, 16, 12, generator=gen, dtype=torch.float64) * 3
    for up in ("nearest", "bilinear"):
        got = _compose_chroma(fine, coarse, blend, up)
        whole = _compose(fine, coarse, blend, up)
        d = _correction(fine, coarse, blend, up, None)
        assert (got >= CHROMA_KEEP * fine - 1e-12).all()
        free = (whole >= CHROMA_KEEP * fine).all(dim=1, keepdim=True).expand_as(got)
        assert free.any() and not free.all()
        assert torch.equal(got[free], whole[free])
        share = ((got - fine) / d)[~free].view(-1)  # one share per pixel, all channels alike
        bounded = (got - CHROMA_KEEP * fine).amin(dim=1, keepdim=True).expand_as(got)[~free]
        assert ((share > -1e-9) & (share < 1)).all() and (bounded.abs() < 1e-12).all()


def test_a_coarse_correction_does_not_turn_a_warm_pixel_blue():
    """recon_vectors' chroma_cap case: dark warm pixels in a 2x2 block with an orange bright
    one; the coarse correction drives their red and green far below zero, not their blue.
    Clamped channel by channel they came out pure blue (0, 0, 2.1)."""
    from temc_train.vectors.recon_vectors import cases, run
    case = next(c for c in cases() if c["name"] == "chroma_cap_8x8_L2_k3")
    out = run(case, torch.float64)
    for y, x in ((2, 3), (3, 2), (3, 3)):
        r, g, b = out[:, y, x]
        assert b <= r and b <= g and r > 0.5 * b


def test_zero_logits_at_one_level_are_a_box_filter_renormalised_at_the_border():
    gen = torch.Generator().manual_seed(1)
    rgb = torch.rand(2, 3, 7, 9, generator=gen) + 0.1
    out = reconstruct(rgb, None, [torch.zeros(2, channels(3), 7, 9)], 3)
    sums = torch.nn.functional.avg_pool2d(rgb, 3, 1, 1, divisor_override=1)
    count = torch.nn.functional.avg_pool2d(torch.ones(1, 1, 7, 9), 3, 1, 1, divisor_override=1)
    torch.testing.assert_close(out, sums / count, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("levels,kernel,sd", [(1, 3, 3.0), (2, 5, 1.0), (3, 5, 5.0), (3, 3, 20.0)])
def test_a_constant_image_stays_constant_for_any_logits(levels, kernel, sd):
    gen = torch.Generator().manual_seed(2)
    rgb = torch.tensor([0.7, 0.2, 3.5]).view(1, 3, 1, 1).expand(2, 3, 16, 24)
    out = reconstruct(rgb, None, random_filters(gen, 2, 16, 24, levels, kernel, sd), kernel)
    torch.testing.assert_close(out, rgb, rtol=1e-5, atol=1e-6)


def test_heavy_tailed_noise_keeps_its_mean_under_random_logits():
    gen = torch.Generator().manual_seed(3)
    u = torch.rand(1, 1, 128, 128, generator=gen)
    rgb = 2.0 * torch.tensor([0.6, 0.25, 0.1]).view(1, 3, 1, 1) * u**2
    out = reconstruct(rgb, None, random_filters(gen, 1, 128, 128, 3, 5, 2.0), 5)
    ratio = out.double().mean((0, 2, 3)) / rgb.double().mean((0, 2, 3))
    assert torch.all((ratio - 1).abs() < 0.01), ratio


def test_the_output_luminance_is_the_luma_paths():
    gen = torch.Generator().manual_seed(4)
    rgb = 4.0 * torch.rand(2, 3, 16, 16, generator=gen) * torch.rand(2, 3, 16, 16, generator=gen)
    f = random_filters(gen, 2, 16, 16, 3, 3, 2.0)
    grey = lum(rgb).unsqueeze(1).expand(2, 3, 16, 16)
    torch.testing.assert_close(lum(reconstruct(rgb, None, f, 3)),
                               reconstruct(grey, None, f, 3)[:, 0], rtol=1e-5, atol=1e-6)


def test_demodulation_round_trips_a_constant_irradiance():
    gen = torch.Generator().manual_seed(7)
    albedo = torch.rand(2, 3, 16, 8, generator=gen)
    albedo = torch.where(torch.rand(2, 3, 16, 8, generator=gen) < 0.2, 0.0, albedo)
    rgb = torch.tensor([2.0, 1.5, 0.5]).view(1, 3, 1, 1) * (albedo + 0.01)
    out = reconstruct(rgb, albedo, random_filters(gen, 2, 16, 8, 2, 5, 3.0), 5, demodulate=True)
    torch.testing.assert_close(out, rgb, rtol=1e-5, atol=1e-6)


def _one_pixel_case(chroma_tiny):
    """A 3x3 image whose centre the luma filter takes from a bright pixel and the chroma
    filter from a corner `chroma_tiny` times as bright (a red-blue corner)."""
    rgb = torch.zeros(1, 3, 3, 3)
    rgb[0, :, 1, 1] = torch.tensor([0.5, 0.4, 0.3])
    rgb[0, :, 0, 0] = chroma_tiny * torch.tensor([1.0, 0.0, 0.5])
    f = torch.full((1, channels(3), 3, 3), -LOGIT_MAX)
    f[0, 4], f[0, 9] = 0.0, 0.0  # luma: the centre tap; chroma: the top-left tap
    return rgb, f.requires_grad_()


@pytest.mark.parametrize("tiny", [1e-4, 1e-12, 1e-25, 1e-29])
def test_a_chroma_result_far_darker_than_the_luma_keeps_gradients_finite(tiny):
    # c * y / yc had gradients y / yc^2: -inf, then NaN, from yc ~ 1e-19 down (measured).
    rgb, f = _one_pixel_case(tiny)
    out = reconstruct(rgb, None, [f], 3)
    (out[0, :, 1, 1] * torch.tensor([1.0, 2.0, 3.0])).sum().backward()
    assert torch.isfinite(f.grad).all()
    centre = out[0, :, 1, 1]
    y = float(lum(rgb)[0, 1, 1])
    assert abs(float(lum(out)[0, 1, 1]) - y) < 1e-6 * y  # the luma path's luminance, always
    if tiny >= 1e-4:  # colour still well above the pull: the corner's hue, green-free
        assert float(centre[1]) < 0.05 * y and float(centre[0]) > 1.5 * float(centre[2])
    else:  # no colour to speak of: grey
        assert float((centre - y).abs().max()) < 1e-3 * y


@pytest.mark.parametrize("demodulate,ldr", [(False, False), (True, False), (True, True)])
def test_non_finite_and_huge_logits_give_finite_output_and_gradients(demodulate, ldr):
    gen = torch.Generator().manual_seed(5)
    rgb = (LINEAR_MAX * torch.rand(1, 3, 8, 16, generator=gen) ** 8).requires_grad_()
    albedo = torch.rand(1, 3, 8, 16, generator=gen)
    specials = torch.tensor(recon_vectors.SPECIALS, dtype=torch.float32)
    filters = []
    for f in random_filters(gen, 1, 8, 16, 3, 5, 1.0):
        pick = torch.rand(f.shape, generator=gen) < 0.5
        idx = torch.randint(len(specials), f.shape, generator=gen)
        filters.append(torch.where(pick, specials[idx], f).requires_grad_())
    out = reconstruct(rgb, albedo, filters, 5, demodulate=demodulate, ldr=ldr)
    assert torch.isfinite(out).all() and out.min() >= 0 and out.max() <= (1 if ldr else LINEAR_MAX)
    out.sum().backward()
    assert torch.isfinite(rgb.grad).all()
    assert all(torch.isfinite(f.grad).all() for f in filters)


def test_bad_filter_shapes_are_errors():
    with pytest.raises(ValueError):
        reconstruct(torch.zeros(1, 3, 8, 8), None, [torch.zeros(1, channels(3), 8, 4)], 3)


def test_guide_channels_and_their_gradient():
    # The range term is differentiable in the guides where they differ (the heads start
    # them small and random for that reason) and fences a lamp off where they differ a lot.
    assert channels(5, True) == 54
    rgb = torch.full((1, 3, 8, 8), 0.1)
    rgb[:, :, 2:4, 2:4] = 500.0
    f = torch.zeros(1, channels(3, True), 8, 8)
    f[:, -2:, 2:4, 2:4] = 6.0
    out = reconstruct(rgb, None, [f], 3, guide=True)
    assert abs(float(lum(out)[0, 4, 4]) - 0.1) < 1e-3
    assert float(lum(reconstruct(rgb, None, [f[:, :-2]], 3))[0, 4, 4]) > 50.0
    g = (0.01 * torch.randn(1, 2, 8, 8)).requires_grad_()
    out = reconstruct(rgb, None, [torch.cat([torch.zeros(1, 2 * 9 + 2, 8, 8), g], 1)], 3, guide=True)
    out.sum().backward()
    assert float(g.grad.abs().max()) > 0


def _lamp_logits(lamp, kernel, value):
    """Logits `value` on every tap that lands on the `lamp` mask [H, W], 0 elsewhere."""
    h, w = lamp.shape
    taps = F.unfold(lamp[None, None].float(), kernel, padding=kernel // 2).view(kernel * kernel, h, w)
    on = taps * value
    return torch.cat([on, on, torch.zeros(2, h, w)])[None]


@pytest.mark.parametrize("exposure", [1.0, 1.8, 10.0, 1000.0])
def test_the_fixed_range_term_keeps_a_lamp_out_of_any_logits(exposure):
    # The Rust test of the same name, through PyTorch: logits pull every pixel toward the
    # lamp by e^12, and still no ceiling pixel moves by 2 %, nor the lamp.
    lamp = torch.zeros(16, 16, dtype=torch.bool)
    lamp[4:8, 4:8] = True
    rgb = torch.where(lamp, 100.0, 0.1).expand(1, 3, 16, 16).contiguous()
    f = _lamp_logits(lamp, 5, 12.0)
    out = lum(reconstruct(rgb, None, [f], 5, fixed_range=True, scale=exposure))[0]
    want = torch.where(lamp, 100.0, 0.1)
    assert float(((out - want).abs() / want).max()) <= 0.02
    assert float(lum(reconstruct(rgb, None, [f], 5))[0, 3, 3]) > 90.0


def test_the_fixed_range_term_lets_a_firefly_spread_and_passes_no_gradient_to_it():
    rgb = torch.full((1, 3, 16, 16), 0.1)
    rgb[:, :, 8, 8] = 1000.0
    f = torch.zeros(1, channels(5), 16, 16, requires_grad=True)
    out = reconstruct(rgb, None, [f], 5, fixed_range=True)
    assert torch.allclose(out, reconstruct(rgb, None, [f], 5), rtol=1e-5)
    assert float(lum(out)[0, 8, 8]) < 41.0
    out.sum().backward()
    assert torch.isfinite(f.grad).all()


def test_the_noise_threshold_keeps_a_clean_shadow_line_dark():
    # The Rust test of the same name: a one-pixel line 1.7 stops below a clean bright floor
    # is under RANGE_TAU, so the fixed threshold lets a box kernel fill it in; the threshold
    # from local noise keeps it darker.
    rgb = torch.ones(1, 3, 16, 16)
    rgb[:, :, :, 8] = 0.3
    f = torch.zeros(1, channels(5), 16, 16)
    before = float(lum(reconstruct(rgb, None, [f], 5, fixed_range=True))[0, 8, 8])
    after = float(lum(reconstruct(rgb, None, [f], 5, fixed_range=True, range_noise=4.0))[0, 8, 8])
    assert before > 0.84 and after < 0.75, (before, after)


def test_the_noise_threshold_follows_the_noise():
    # 0 on a flat image, RANGE_TAU on a 1-spp-like one (a quarter of the pixels bright).
    flat = range_threshold(torch.full((1, 1, 12, 20), 0.5), 1.0, 4.0)
    assert bool((flat == 0).all())
    g = torch.Generator().manual_seed(7)
    sparse = torch.where(torch.rand(1, 1, 12, 20, generator=g) < 0.25, 4.0, 0.0)
    assert bool((range_threshold(sparse, 1.0, 4.0) == RANGE_TAU).all())
    assert range_threshold(sparse, 1.0, 0.0) == RANGE_TAU


def _surface_aux(h, w):
    return torch.full((1, 7, h, w), 0.5)


def test_the_aux_guided_opening_keeps_a_small_lamp_and_spreads_fireflies():
    # The Rust test of the same name: a 1 px lamp with an emitter's albedo keeps its light
    # and lends none; a firefly on the surface and one on a lone non-emitter texel spread
    # exactly as under the plain opening; without aux planes the call is refused.
    rgb = torch.full((1, 3, 16, 16), 0.1)
    rgb[:, :, 5, 5], rgb[:, :, 11, 10], rgb[:, :, 3, 12] = 800.0, 900.0, 900.0
    aux = _surface_aux(16, 16)
    aux[:, :3, 5, 5], aux[:, :3, 3, 12] = 1.0, 0.2
    f = torch.zeros(1, channels(5), 16, 16)
    out = lum(reconstruct(rgb, None, [f], 5, fixed_range=True, range_opening="aux", aux=aux))[0]
    spread = lum(reconstruct(rgb, None, [f], 5, fixed_range=True))[0]
    assert abs(float(out[5, 5]) - 800.0) < 1e-3
    assert float(out[5, 6]) < 0.2 and float(out[6, 5]) < 0.2 and float(spread[5, 6]) > 20.0
    for y, x in ((11, 10), (11, 11), (3, 12), (2, 12)):
        assert torch.allclose(out[y, x], spread[y, x], rtol=1e-5)
    with pytest.raises(ValueError):
        reconstruct(rgb, None, [f], 5, fixed_range=True, range_opening="aux")
    with pytest.raises(ValueError):
        reconstruct(rgb, None, [f], 5, fixed_range=True, range_opening="closed", aux=aux)


def test_the_aux_guided_opening_is_the_plain_one_on_one_surface_and_never_above_the_input():
    gen = torch.Generator().manual_seed(3)
    y = torch.rand(1, 1, 12, 20, generator=gen) ** 4 * 50.0
    flat = _surface_aux(12, 20)
    assert torch.equal(aux_opened(y, flat), opened(y))
    aux = (torch.rand(1, 7, 12, 20, generator=gen) > 0.5).float() * 0.4
    o = aux_opened(y, aux)
    assert (o <= y).all() and torch.equal(aux_opened(o, aux), o)


def test_the_coarse_clamp_caps_what_coarse_levels_add():
    # The Rust test of the same name: a firefly on a dark floor, box kernels, blends wide
    # open; with the clamp nothing exceeds twice the finest level alone, without it the
    # coarse levels raise the floor around the firefly more than tenfold.
    rgb = torch.full((1, 3, 16, 16), 0.01)
    rgb[:, :, 9, 6] = 700.0

    def filters(levels):
        out = []
        for l in range(levels):
            f = torch.zeros(1, channels(3), 16 >> l, 16 >> l)
            f[:, 18:] = LOGIT_MAX
            out.append(f)
        return out

    fine = lum(reconstruct(rgb, None, filters(1), 3))
    capped = lum(reconstruct(rgb, None, filters(3), 3, coarse_clamp=True))
    free = lum(reconstruct(rgb, None, filters(3), 3))
    assert float((capped / fine).max()) <= 2.0 + 1e-4
    assert float((free / fine).max()) > 10.0


def identity_over_box():
    """Two levels of 3x3 logits on 16x16: identity kernels at the fine level, a box at level
    1, blends open (the coarse cap tests')."""
    fine = torch.zeros(1, channels(3), 16, 16)
    fine[:, :18] = -LOGIT_MAX
    fine[:, 4] = fine[:, 13] = LOGIT_MAX  # the centre taps
    fine[:, 18:] = LOGIT_MAX
    return [fine, torch.zeros(1, channels(3), 8, 8)]


def test_the_coarse_cap_against_a_local_mean_fills_sparse_pixels():
    # The Rust test of the same name: one lit pixel in every other 2x2 block, identity
    # kernels at the fine level, a box at level 1, blends open. Capped against its own value
    # a black pixel stays black; against its 5x5 mean the coarse level fills it. Outside a
    # firefly's own 5x5 its dark surroundings stay at most twice the dark level.
    filters = identity_over_box

    yy, xx = torch.meshgrid(torch.arange(16), torch.arange(16), indexing="ij")
    lit = (yy % 2 == 0) & (xx % 2 == 0) & ((yy // 2 + xx // 2) % 2 == 0)
    sparse = (4.0 * lit).expand(1, 3, 16, 16).float()
    own = lum(reconstruct(sparse, None, filters(), 3, coarse_clamp=True))
    mean = lum(reconstruct(sparse, None, filters(), 3, coarse_clamp=True, coarse_radius=2))
    assert float(own[0, 1, 2]) < 1e-6
    assert float(mean[0, 1, 2]) > 0.25
    dark = torch.full((1, 3, 16, 16), 0.01)
    dark[:, :, 9, 6] = 700.0
    free = lum(reconstruct(dark, None, filters(), 3))
    capped = lum(reconstruct(dark, None, filters(), 3, coarse_clamp=True, coarse_radius=2))
    assert float(free[0, 11, 9]) > 1.0
    assert float(capped[0, 11, 9]) <= 0.02 + 1e-4


def test_the_coarse_cap_rises_where_samples_are_sparse():
    # The Rust test of the same name: one lit pixel in every 4x4 block under
    # identity_over_box, capped at half the 5x5 mean. With coarse_sparse 0.5 the cap rises
    # (one to four lit pixels in 25: the bound, 5x, to 3x) and the black pixels between the
    # samples come out about twice as bright, never brighter than with no cap at all; a dim
    # floor that is lit everywhere, firefly and all, has a rise of 1: the same image.
    yy, xx = torch.meshgrid(torch.arange(16), torch.arange(16), indexing="ij")
    lit = (yy % 4 == 0) & (xx % 4 == 0)
    sparse = (4.0 * lit).expand(1, 3, 16, 16).float()
    kw = dict(coarse_clamp=True, coarse_gain=0.5, coarse_radius=2)
    base = lum(reconstruct(sparse, None, identity_over_box(), 3, **kw))[0][~lit]
    risen = lum(reconstruct(sparse, None, identity_over_box(), 3, coarse_sparse=0.5, **kw))[0][~lit]
    assert float(risen.mean()) > 1.8 * float(base.mean()), (risen.mean(), base.mean())
    free = lum(reconstruct(sparse, None, identity_over_box(), 3))[0][~lit]
    assert bool((risen <= free + 1e-6).all())  # it loosens the cap, never adds past none
    dark = torch.full((1, 3, 16, 16), 0.01)
    dark[:, :, 9, 6] = 700.0
    assert torch.equal(reconstruct(dark, None, identity_over_box(), 3, **kw),
                       reconstruct(dark, None, identity_over_box(), 3, coarse_sparse=0.5, **kw))


def test_the_coarse_cap_refuses_a_bad_gain_or_radius():
    rgb = torch.ones(1, 3, 8, 8)
    f = [torch.zeros(1, channels(3), 8, 8), torch.zeros(1, channels(3), 4, 4)]
    for gain, radius in ((0.0, 0), (math.inf, 0), (1.0, 9), (1.0, 1.5), (1.0, -1)):
        with pytest.raises(ValueError):
            reconstruct(rgb, None, f, 3, coarse_clamp=True, coarse_gain=gain, coarse_radius=radius)
    for share in (-0.1, 1.5, math.nan):
        with pytest.raises(ValueError):
            reconstruct(rgb, None, f, 3, coarse_clamp=True, coarse_sparse=share)


def test_median9_is_torch_median_for_every_order():
    # A network of compare-exchanges that sorts every 0/1 input sorts everything (Knuth's
    # 0-1 principle): all 512 of them, then random values with and without ties.
    bits = torch.tensor([[(i >> j) & 1 for j in range(9)] for i in range(512)], dtype=torch.float32)
    cases = [bits.t().reshape(1, 9, 16, 32)]
    g = torch.Generator().manual_seed(5)
    cases += [torch.rand(2, 9, 7, 5, generator=g), torch.randint(0, 3, (2, 9, 7, 5), generator=g).float()]
    for taps in cases:
        assert torch.equal(median9(taps), taps.median(1, keepdim=True).values)
