import torch

from temc_train.loss import mix_loss


def noisy(x, amount, seed=0):
    g = torch.Generator().manual_seed(seed)
    return (x + amount * torch.randn(x.shape, generator=g)).clamp(0, 1)


def image(h=128, w=128, seed=1):
    g = torch.Generator().manual_seed(seed)
    base = torch.rand(2, 3, h // 8, w // 8, generator=g)
    return torch.nn.functional.interpolate(base, size=(h, w), mode="bilinear", align_corners=False)


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


def test_training_loss_wraps_hue_and_ignores_the_hue_of_grey():
    from temc_train.loss import training_loss

    def img(h, s, v=0.5):
        return torch.stack([torch.full((16, 16), float(x)) for x in (h, s, v)])[None]

    # Reds on either side of the wrap are neighbours; red against cyan is far.
    near = training_loss(img(0.99, 0.9), img(0.01, 0.9)).item()
    far = training_loss(img(0.5, 0.9), img(0.01, 0.9)).item()
    assert near < 0.2 * far, (near, far)
    # Grey (S = 0): any hue is the same colour.
    assert training_loss(img(0.3, 0.0), img(0.8, 0.0)).item() < 1e-6
    # Gradients reach the hue.
    p = img(0.2, 0.9).requires_grad_()
    training_loss(p, img(0.01, 0.9)).backward()
    assert p.grad[:, 0].abs().sum() > 0


def test_training_loss_matches_the_core_and_does_not_reward_desaturation():
    from temc_train import color
    from temc_train.loss import training_loss
    from temc_train.models import hsv_to_rgb

    g = torch.Generator().manual_seed(5)
    hsv = torch.rand(1, 3, 8, 8, generator=g)
    want = color.hsv_to_rgb(hsv[0].permute(1, 2, 0).numpy())
    assert torch.allclose(hsv_to_rgb(hsv)[0].permute(1, 2, 0), torch.from_numpy(want), atol=1e-6)

    # A flat red wall, and a prediction of it whose hue is noisy around the wrap: halving
    # its saturation lowers the variance, but must not lower the loss.
    def wall(h, s):
        return torch.stack([h, torch.full_like(h, s), torch.full_like(h, 0.6)])[None]

    ref = wall(torch.full((64, 64), 0.01), 0.8)
    h = torch.remainder(0.01 + 0.04 * torch.randn(64, 64, generator=g), 1.0)
    assert training_loss(wall(h, 0.8), ref) < training_loss(wall(h, 0.4), ref)
