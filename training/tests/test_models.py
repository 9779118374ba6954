import pytest
import torch

from temc_train.models import ARCHS, KERNEL, LEVELS, build, count_params, filter_channels

# Parameter counts at width 1.0, from docs/reference/temc-architecture.md:
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


# Our output (models.py): the paper's last 3x3 conv (cin -> cout) is replaced by one 1x1
# filter head per pyramid level over the decoder's features at that level.
PAPER_LAST = {"ae": [(32, 3)], "demc": [(64, 3)], "temc2": [(64, 3)], "temc1": [(64, 2), (32, 1)]}
N = KERNEL * KERNEL
HEADS = {  # (decoder widths at levels 0, 1, 2, channels per level) per network
    "ae": [((32, 64, 88), 2 * N + 2)],
    "demc": [((64, 128, 256), 2 * N + 2)],
    "temc2": [((64, 128, 256), 2 * N + 2)],
    "temc1": [((64, 128, 256), N + 1), ((32, 64, 88), N + 1)],
}


@pytest.mark.parametrize("arch", ARCHS)
def test_parameter_counts_match_the_architecture_note_up_to_the_output(arch):
    paper, bn = EXPECTED[arch]
    last = sum((cin * 9 + 1) * cout for cin, cout in PAPER_LAST[arch])
    heads = sum((w + 1) * c for widths, c in HEADS[arch] for w in widths[:LEVELS])
    assert count_params(build(arch, 1.0)) == (paper - last + heads, bn)


def test_note_totals_without_the_output():
    # The note's headline figures hold for the encoders and decoder (the output heads are
    # ours): 44.85 M for DEMC, 64.9 M for TEMC-2.
    for arch, total in (("demc", 44.85), ("temc2", 64.9)):
        m = build(arch, 1.0)
        heads = sum(p.numel() for n, p in m.named_parameters() if ".heads." in n)
        last = (64 * 9 + 1) * 3
        assert round((sum(count_params(m)) - heads + last) / 1e6, 2 if arch == "demc" else 1) == total


@pytest.mark.parametrize("arch", ARCHS)
@pytest.mark.parametrize("size", [(32, 32), (64, 96)])
def test_outputs_are_filters_per_level(arch, size):
    torch.manual_seed(0)
    m = build(arch, 0.0625).eval()
    h, w = size
    xs = [torch.rand(2, c, h, w) for c in (2, 1, 7)]
    with torch.no_grad():
        ys = m(*xs)
    assert [tuple(y.shape) for y in ys] == [(2, filter_channels(), h >> l, w >> l)
                                            for l in range(LEVELS)]


@pytest.mark.parametrize("arch", ARCHS)
def test_an_untrained_network_predicts_box_filters(arch):
    # Zero heads: every logit 0, so every level is a box filter and every blend 1/2.
    m = build(arch, 0.0625).eval()
    with torch.no_grad():
        ys = m(torch.rand(1, 2, 32, 32), torch.rand(1, 1, 32, 32), torch.rand(1, 7, 32, 32))
    assert all(torch.equal(y, torch.zeros_like(y)) for y in ys)


def test_one_filter_shares_luma_and_chroma():
    torch.manual_seed(0)
    m = build("temc2", 0.0625, split="one").eval()
    for p in m.decoder.heads.parameters():
        torch.nn.init.normal_(p)
    with torch.no_grad():
        y = m(torch.rand(1, 2, 32, 32), torch.rand(1, 1, 32, 32), torch.rand(1, 7, 32, 32))[0]
    assert torch.equal(y[:, :N], y[:, N:2 * N]) and torch.equal(y[:, 2 * N], y[:, 2 * N + 1])


def test_levels_and_kernel_are_parameters():
    m = build("temc2", 0.0625, levels=1, kernel=3).eval()
    with torch.no_grad():
        ys = m(torch.rand(1, 2, 32, 32), torch.rand(1, 1, 32, 32), torch.rand(1, 7, 32, 32))
    assert [tuple(y.shape) for y in ys] == [(1, filter_channels(3), 32, 32)]


def test_width_scales_parameters_roughly_quadratically():
    big = sum(count_params(build("temc2", 0.5)))
    small = sum(count_params(build("temc2", 0.25)))
    assert 3.5 < big / small < 4.5


def test_temc1_branches_are_independent():
    # V's branch (the luma autoencoder) predicts the luma filters, the chroma DEMC the chroma
    # filters: the chroma filters do not change when only V does.
    torch.manual_seed(0)
    m = build("temc1", 0.0625).eval()
    for name, p in m.named_parameters():
        if ".heads." in name:
            torch.nn.init.normal_(p)
    c, l, a = torch.rand(1, 2, 32, 32), torch.rand(1, 1, 32, 32), torch.rand(1, 7, 32, 32)
    with torch.no_grad():
        y0 = m(c, l, a)[0]
        y1 = m(c, torch.rand(1, 1, 32, 32), a)[0]
    chroma = list(range(N, 2 * N)) + [2 * N + 1]
    luma = list(range(N)) + [2 * N]
    assert torch.equal(y0[:, chroma], y1[:, chroma])
    assert not torch.equal(y0[:, luma], y1[:, luma])


def test_unknown_architecture_and_split():
    with pytest.raises(ValueError):
        build("unet", 1.0)
    with pytest.raises(ValueError):
        build("temc2", 1.0, split="three")
    with pytest.raises(ValueError):
        build("temc2", 1.0, kernel=4)


@pytest.mark.parametrize("arch", ARCHS)
def test_guide_heads_add_two_channels_that_start_small_and_nonzero(arch):
    m = build(arch, 0.0625, levels=1, guide=True).eval()
    with torch.no_grad():
        y = m(torch.rand(1, 2, 32, 32), torch.rand(1, 1, 32, 32), torch.rand(1, 7, 32, 32))[0]
    c = filter_channels(KERNEL)
    assert y.shape[1] == filter_channels(KERNEL, True) == c + 2
    assert torch.equal(y[:, :c], torch.zeros_like(y[:, :c]))
    assert 0 < float(y[:, c:].abs().max()) < 1.0
