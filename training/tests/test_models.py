import pytest
import torch

from temc_train import color
from temc_train.models import (ARCHS, KERNEL, AENet, DEMCNet, build, count_params, hsv_to_rgb,
                               rgb_to_hsv)

# Parameter counts at width 1.0, from ../shared/reference/temc-architecture.md:
# (conv/deconv weights and biases, batch-norm gamma/beta).
EXPECTED = {
    # DEMC on HSV (3 channels in, 3 out) is exactly the note's DEMC: 44.85 M.
    "demc": (44_843_268, 4_224),
    # TEMC-2 with two stabilising convs: 64.9 M, as in the note's table.
    "temc2": (64_885_636, 5_248),
    # TEMC-1 = chroma DEMC (2 in, 2 out: 576 + 577 fewer than DEMC) + AE (1 -> 1, 1,395,201).
    "temc1": (44_843_268 - 1_153 + 1_395_201, 4_224),
    # AE baseline on chroma || luma || aux (10 -> 3): the note's AE (1 -> 1) plus
    # 9 input channels x 32 x 9 and 2 more output channels x (32 x 9 + 1).
    "ae": (1_395_201 + 9 * 32 * 9 + 2 * (32 * 9 + 1), 0),
}


@pytest.mark.parametrize("arch", ARCHS)
def test_parameter_counts_match_the_architecture_note(arch):
    # The note counts the paper's (direct, sigmoid) head.
    assert count_params(build(arch, 1.0, "direct")) == EXPECTED[arch]


@pytest.mark.parametrize("arch", ARCHS)
def test_the_kernel_head_changes_only_the_last_convs(arch):
    # Each last conv predicts KERNEL^2 weights instead of its 3 (or 2, 1) channels.
    last = {"ae": [(32, 3)], "demc": [(64, 3)], "temc2": [(64, 3)], "temc1": [(64, 2), (32, 1)]}
    extra = sum((KERNEL * KERNEL - cout) * (cin * 9 + 1) for cin, cout in last[arch])
    direct, bn = EXPECTED[arch]
    assert count_params(build(arch, 1.0, "kernel")) == (direct + extra, bn)


def test_building_blocks_match_the_note():
    # The note's own configurations: AE 1 -> 1, and DEMC on RGB (3 -> 3) with 7 aux channels.
    assert count_params(AENet(1, 1, 1.0, "direct")) == (1_395_201, 0)
    assert count_params(DEMCNet(3, 3, 1.0, "direct")) == (44_843_268, 4_224)


def test_note_totals():
    # The note's headline figures.
    assert round(sum(count_params(build("demc", 1.0, "direct"))) / 1e6, 2) == 44.85
    assert round(sum(count_params(build("temc2", 1.0, "direct"))) / 1e6, 1) == 64.9


def test_an_untrained_kernel_head_is_a_box_filter_that_spares_the_borders():
    m = build("temc2", 0.0625).eval()
    hsv = torch.rand(1, 3, 32, 32)
    with torch.no_grad():
        y = m(hsv[:, :2], hsv[:, 2:], torch.rand(1, 7, 32, 32))
    rgb = hsv_to_rgb(hsv)
    # Pixel (0, 0) averages the 3x3 taps inside the image; (10, 10) all 25.
    assert torch.allclose(hsv_to_rgb(y)[0, :, 0, 0], rgb[0, :, :3, :3].mean(dim=(1, 2)), atol=1e-5)
    assert torch.allclose(hsv_to_rgb(y)[0, :, 10, 10], rgb[0, :, 8:13, 8:13].mean(dim=(1, 2)),
                          atol=1e-5)


def test_hsv_conversions_match_the_core():
    g = torch.Generator().manual_seed(2)
    rgb = torch.rand(1, 3, 8, 8, generator=g)
    rgb[0, :, 0, 0] = 0.5  # grey
    rgb[0, :, 0, 1] = 0.0  # black
    want = color.rgb_to_hsv(rgb[0].permute(1, 2, 0).numpy())
    got = rgb_to_hsv(rgb)[0].permute(1, 2, 0).numpy()
    assert abs(got - want).max() < 1e-6
    assert torch.allclose(hsv_to_rgb(rgb_to_hsv(rgb)), rgb, atol=1e-6)


@pytest.mark.parametrize("arch", ARCHS)
@pytest.mark.parametrize("size", [(32, 32), (64, 96)])
def test_output_shape_and_range(arch, size):
    torch.manual_seed(0)
    m = build(arch, 0.0625).eval()
    h, w = size
    xs = [torch.rand(2, c, h, w) for c in (2, 1, 7)]
    with torch.no_grad():
        y = m(*xs)
    assert y.shape == (2, 3, h, w)
    assert torch.all((y >= 0) & (y <= 1))


def test_width_scales_parameters_roughly_quadratically():
    big = sum(count_params(build("temc2", 0.5)))
    small = sum(count_params(build("temc2", 0.25)))
    assert 3.5 < big / small < 4.5


def test_temc1_branches_are_independent():
    # With the paper's head, V comes only from the luma autoencoder, (H, S) only from the
    # chroma DEMC. (The kernel head filters all of R'G'B' in each branch.)
    torch.manual_seed(0)
    m = build("temc1", 0.0625, "direct").eval()
    c, l, a = torch.rand(1, 2, 32, 32), torch.rand(1, 1, 32, 32), torch.rand(1, 7, 32, 32)
    with torch.no_grad():
        y0 = m(c, l, a)
        y1 = m(c, torch.rand(1, 1, 32, 32), a)
    assert torch.equal(y0[:, :2], y1[:, :2])
    assert not torch.equal(y0[:, 2], y1[:, 2])


def test_unknown_architecture_and_head():
    with pytest.raises(ValueError):
        build("unet", 1.0)
    with pytest.raises(ValueError):
        build("temc2", 1.0, "residual")
