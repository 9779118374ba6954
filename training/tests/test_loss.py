import math
import numpy as np
import pytest
import torch

from temc_train import loss as loss_module
from temc_train.loss import mix_loss


def noisy(x, amount, seed=0):
    g = torch.Generator().manual_seed(seed)
    return (x + amount * torch.randn(x.shape, generator=g)).clamp(0, 1)


def image(h=128, w=128, seed=1):
    g = torch.Generator().manual_seed(seed)
    base = torch.rand(2, 3, h // 8, w // 8, generator=g)
    return torch.nn.functional.interpolate(base, size=(h, w), mode="bilinear", align_corners=False)


def gaussian_blurs(x, which):
    """The loss's windows as plain separable convolutions in float64, edges replicated."""
    k = loss_module._kernels(x.device, torch.float64)[which]
    r = loss_module.RADIUS
    h, w = x.shape[-2:]
    rows = (torch.arange(h + 2 * r) - r).clamp(0, h - 1)
    cols = (torch.arange(w + 2 * r) - r).clamp(0, w - 1)
    padded = x.double()[..., rows, :][..., cols]
    conv = torch.nn.functional.conv2d
    return torch.cat([conv(conv(padded, g.view(1, 1, 1, -1)), g.view(1, 1, -1, 1)) for g in k], 1)


@pytest.mark.parametrize("shape", [(3, 1, 128, 128), (2, 1, 1, 1), (2, 1, 5, 37), (1, 1, 40, 17)])
@pytest.mark.parametrize("which", [slice(None), slice(-1, None)])
def test_blur_is_the_gaussian_windows_with_edges_replicated(shape, which):
    # The matrix products stand for five separable Gaussian convolutions: per plane and
    # window, in the windows' order, on square, odd and tiny crops alike.
    x = torch.rand(shape, generator=torch.Generator().manual_seed(4))
    got = loss_module._blur(x, which)
    torch.testing.assert_close(got.double(), gaussian_blurs(x, which), atol=1e-6, rtol=0)


def test_identical_images_have_zero_loss():
    x = image()
    assert mix_loss(x, x).abs().item() < 1e-6


def test_different_images_have_positive_loss():
    x = image()
    assert mix_loss(noisy(x, 0.1), x).item() > 0.01


def test_loss_falls_as_noise_shrinks():
    x = image()
    losses = [mix_loss(noisy(x, a), x).item() for a in (0.3, 0.1, 0.03, 0.01)]
    assert all(a > b for a, b in zip(losses, losses[1:])), losses


def test_structure_matters_more_than_a_constant_offset():
    # MS-SSIM's contrast-structure terms ignore a small uniform shift; they do not ignore
    # noise of the same L1 size, which is what makes the loss keep detail.
    x = image()
    shifted = (x + 0.02).clamp(0, 1)
    g = torch.Generator().manual_seed(3)
    speckle = (x + 0.02 * torch.sign(torch.randn(x.shape, generator=g))).clamp(0, 1)
    assert mix_loss(speckle, x) > mix_loss(shifted, x)


def test_gradients_are_finite():
    x = image(64, 64)
    p = noisy(x, 0.2).requires_grad_()
    mix_loss(p, x).backward()
    assert torch.isfinite(p.grad).all() and p.grad.abs().sum() > 0
    # Constant images (zero variance everywhere) must not divide by zero.
    c = torch.full((1, 3, 32, 32), 0.5, requires_grad=True)
    mix_loss(c, torch.zeros(1, 3, 32, 32)).backward()
    assert torch.isfinite(c.grad).all()


def test_works_on_tiny_and_odd_sizes():
    for h, w in [(1, 1), (3, 5), (17, 128)]:
        x = image(max(h, 8), max(w, 8))[..., :h, :w]
        v = mix_loss(noisy(x, 0.1), x)
        assert torch.isfinite(v) and v >= 0


def test_training_loss_takes_the_cores_pq():
    import numpy as np

    from temc_train import color
    from temc_train.loss import pq

    g = torch.Generator().manual_seed(5)
    rgb = torch.rand(1, 3, 8, 8, generator=g) * 50  # past the PQ range (100 units) too
    rgb[0, :, 0, 0] = 150.0
    want = color.pq_encode(rgb.double().numpy() * color.NITS_PER_UNIT / color.PQ_MAX_NITS)
    assert np.abs(pq(rgb).double().numpy() - want).max() < 1e-5


def test_training_loss_punishes_darkening_and_desaturation():
    # A flat coloured wall and a noisy reconstruction of it that keeps its mean: a darker
    # or a greyer version of the same reconstruction (what averaging PQ values, or a
    # desaturated prior, gave) must cost more.
    from temc_train.loss import training_loss

    g = torch.Generator().manual_seed(6)
    wall = torch.tensor([0.6, 0.15, 0.05]).view(1, 3, 1, 1).expand(1, 3, 64, 64)
    pred = wall * (1 + 0.05 * torch.randn(1, 3, 64, 64, generator=g))
    base = training_loss(pred, wall)
    assert base < training_loss(0.8 * pred, wall)
    # Desaturating a noisy prediction also lowers its per-channel noise, which MS-SSIM
    # rewards (measured: it can win); the reconstruction cannot desaturate (it only averages
    # neighbours' colours), so the check that matters is on the colour itself.
    grey = (wall * torch.tensor([0.2126, 0.7152, 0.0722]).view(1, 3, 1, 1)).sum(1, keepdim=True)
    assert training_loss(wall, wall) < 1e-6 < training_loss(0.5 * wall + 0.5 * grey, wall)
    # Gradients are finite at black.
    p = torch.zeros(1, 3, 16, 16, requires_grad=True)
    training_loss(p, torch.rand(1, 3, 16, 16)).backward()
    assert torch.isfinite(p.grad).all()


def test_noise2noise_loss_trains_towards_the_targets_mean():
    # The gradient (the denominator carries none) pushes a constant prediction towards the
    # noisy targets' mean, the clean value, from either side.
    from temc_train.loss import noise2noise_loss
    torch.manual_seed(0)
    targets = 0.5 * torch.distributions.Exponential(1.0).sample((4096, 3, 2, 2))
    mean = float(targets.mean())
    for v, sign in ((0.3, -1), (0.7, 1)):
        pred = torch.full_like(targets, v, requires_grad=True)
        noise2noise_loss(pred, targets).backward()
        assert sign * float(pred.grad.sum()) > 0
    pred = torch.full_like(targets, mean, requires_grad=True)
    noise2noise_loss(pred, targets).backward()
    assert abs(float(pred.grad.sum())) < 1e-6


def test_block_mean_error_sees_dropped_samples_the_mix_loss_barely_sees():
    """A filter that leaves out rare bright samples loses energy; the block-mean term counts
    that loss in proportion, and ignores moving energy within a block."""
    from temc_train.loss import block_mean_error, training_loss
    torch.manual_seed(0)
    target = torch.full((1, 3, 32, 32), 0.05)
    target[..., ::8, ::8] = 3.0  # sparse bright samples carry most of the energy
    dropped = torch.full_like(target, 0.05)
    moved = target.roll(1, dims=-1)  # same block sums, different pixels
    assert block_mean_error(target, target) == 0
    assert block_mean_error(moved, target) < 0.05
    drop = float(block_mean_error(dropped, target))
    m = (252 * 0.05 + 4 * 3.0) / 256  # each 16x16 block: four bright samples
    assert drop == pytest.approx((m - 0.05) / (m + 0.01), rel=1e-5)  # 0.43: half the energy gone
    plain = float(training_loss(dropped, target))
    assert float(training_loss(dropped, target, mean_weight=0.1)) == pytest.approx(plain + 0.1 * drop, rel=1e-5)
    p = dropped.clone().requires_grad_()
    block_mean_error(p, target).backward()
    assert (p.grad < 0).all()  # every pixel is pushed brighter


def test_block_mean_error_takes_images_smaller_than_a_block():
    from temc_train.loss import block_mean_error
    assert float(block_mean_error(torch.ones(1, 3, 5, 7), torch.ones(1, 3, 5, 7) * 2)) == pytest.approx(1 / 2.01, rel=1e-5)


def test_block_log_error_charges_darkening_and_brightening_by_the_same_factor_alike():
    """block_mean_error charges a block darkened 4x 0.75 and one brightened 4x 3.0; the
    log-ratio term charges both log 4, and pushes a darkened block brighter."""
    from temc_train.loss import DARK_FLOOR, block_log_error, block_mean_error, training_loss
    target = torch.full((1, 3, 16, 16), 0.2)
    dark, bright = target / 4, target * 4
    assert float(block_log_error(target, target)) == 0
    assert float(block_mean_error(dark, target)) < 0.8 < 2.8 < float(block_mean_error(bright, target))
    expect_dark = math.log((0.2 + DARK_FLOOR) / (0.05 + DARK_FLOOR))
    expect_bright = math.log((0.8 + DARK_FLOOR) / (0.2 + DARK_FLOOR))
    assert float(block_log_error(dark, target)) == pytest.approx(expect_dark, rel=1e-5)
    assert float(block_log_error(bright, target)) == pytest.approx(expect_bright, rel=1e-5)
    assert expect_dark == pytest.approx(expect_bright, rel=0.1)  # within the floor's share
    plain = float(training_loss(dark, target))
    assert float(training_loss(dark, target, dark_weight=0.2)) == pytest.approx(plain + 0.2 * expect_dark, rel=1e-5)
    p = dark.clone().requires_grad_()
    block_log_error(p, target).backward()
    assert (p.grad < 0).all()
    # Negative block means (a chroma overshoot) clamp to zero instead of giving NaN.
    assert math.isfinite(float(block_log_error(-target, target)))


def test_worst_pixel_error_charges_a_kept_firefly_and_not_a_missed_one():
    """One pixel of a 128x128 crop kept at 30x its reference, over residual noise: the mix
    loss weighs it at its share of the crop; the worst-pixel term is the mean excess over the
    worst 0.2 % of pixels and pushes that pixel down hardest. A firefly only the reference
    has (a darker output) costs nothing."""
    from temc_train.loss import WORST_SHARE, pq, training_loss, worst_pixel_error
    target = image()[:1] * 0.5
    base = noisy(target, 0.05)
    kept = base.clone()
    kept[0, :, 64, 64] = 3.0
    assert round(WORST_SHARE * 128 * 128) == 33
    assert float(worst_pixel_error(pq(target), pq(target))) == 0
    worst = worst_pixel_error(pq(kept), pq(target))
    plain = float(training_loss(kept, target))
    assert float(training_loss(kept, target, worst_weight=0.5)) == pytest.approx(
        plain + 0.5 * float(worst), rel=1e-5)
    grads = []
    for term in (lambda p: training_loss(p, target), lambda p: worst_pixel_error(pq(p), pq(target))):
        p = kept.clone().requires_grad_()
        term(p).backward()
        grads.append(p.grad[0, :, 64, 64])
        if len(grads) == 2:  # only the worst pixels get a gradient, all pushing down
            assert (p.grad >= 0).all() and int((p.grad.sum(1) > 0).sum()) == 33
    assert (grads[1] > 3 * grads[0].abs()).all()
    # The reference's own firefly, which the output lacks, is not chased.
    missed = target.clone()
    missed[0, :, 10, 10] = 3.0
    assert float(worst_pixel_error(pq(target), pq(missed))) == 0
    # A crop smaller than 1 / share still charges its one worst pixel.
    tiny = torch.zeros(1, 3, 4, 4)
    tiny[0, :, 1, 2] = 0.5
    assert float(worst_pixel_error(tiny, torch.zeros_like(tiny))) == pytest.approx(0.5)


def test_worst_intensity_error_charges_brightness_on_the_intensity_axis():
    """`--worst-axis intensity`: the same mining on ICtCp's I. A kept firefly is charged, a
    missed one is not, and training_loss adds it in place of the R'G'B' version."""
    from temc_train.loss import ictcp, training_loss, worst_intensity_error, worst_pixel_error
    target = image()[:1] * 0.5
    kept = target.clone()
    kept[0, :, 64, 64] = torch.tensor([3.0, 1.5, 0.5])
    assert float(worst_intensity_error(target, target)) == 0
    worst = worst_intensity_error(kept, target)
    i_kept, i_ref = ictcp(kept)[0, 0, 64, 64], ictcp(target)[0, 0, 64, 64]
    assert float(worst) == pytest.approx(float(i_kept - i_ref) / 33, rel=1e-4)
    plain = float(training_loss(kept, target))
    assert float(training_loss(kept, target, worst_weight=0.5, worst_axis="intensity")) == \
        pytest.approx(plain + 0.5 * float(worst), rel=1e-5)
    assert float(worst_pixel_error(ictcp(target)[:, :1], ictcp(kept)[:, :1])) == 0
    p = kept.clone().requires_grad_()
    worst_intensity_error(p, target).backward()
    assert (p.grad[0, :, 64, 64] > 0).all() and float(p.grad.abs().sum()) > 0


def test_chroma_error_charges_hue_not_intensity():
    """The chroma term is Delta E ITP's Ct and Cp axes, on evaluate.ictcp's colour space
    (which colour-science checks): zero for the reference and for a grey image made brighter
    (intensity only), BT.2124's chroma distance for a pixel moved in hue, and a finite
    gradient where the colours match."""
    from temc_train import evaluate as ev
    from temc_train.loss import CHROMA_EPS, chroma_error, training_loss
    target = image()[:1] * 0.5
    floor = CHROMA_EPS ** 0.5
    assert float(chroma_error(target, target)) == pytest.approx(floor)
    grey = torch.full((1, 3, 8, 8), 0.2)
    assert float(chroma_error(grey * 3, grey)) < 2 * floor
    shifted = target.clone()
    shifted[:, 0] *= 1.5  # redder
    c = float(chroma_error(shifted, target))
    _, t1, p1 = ev.ictcp(shifted[0].permute(1, 2, 0).numpy(), 1.0)
    _, t2, p2 = ev.ictcp(target[0].permute(1, 2, 0).numpy(), 1.0)
    want = np.mean(np.sqrt((0.5 * (t1 - t2)) ** 2 + (p1 - p2) ** 2))
    assert want > 1e-3 and c == pytest.approx(want, rel=1e-3)
    plain = float(training_loss(shifted, target))
    assert float(training_loss(shifted, target, chroma_weight=2.0)) == pytest.approx(
        plain + 2.0 * c, rel=1e-5)
    p = target.clone().requires_grad_()
    chroma_error(p, target).backward()
    assert torch.isfinite(p.grad).all()
