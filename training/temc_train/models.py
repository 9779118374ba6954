"""TEMC-2, TEMC-1, DEMC and the TEMC autoencoder, following
docs/reference/temc-architecture.md layer by layer.

Every model takes the same three inputs (docs/contracts.md §2): chroma (H, S) [N,2,H,W],
luma V [N,1,H,W] and aux (albedo 3, normal 3, depth 1) [N,7,H,W]. `width` scales every
internal channel count (1.0 = the paper's network); inputs and the 1-channel detail map
keep their sizes.

Output (our deviation from the paper, the same for every architecture; docs/reconstruction.md):
the network predicts filters, not pixels. At each of `levels` pyramid levels (full, 1/2,
1/4 resolution) a 1x1 conv over the decoder's features at that resolution predicts a luma
kernel, a chroma kernel (k x k logits each) and two blend logits; the core
(src/reconstruct.rs, and reconstruct.py for training) normalises them and applies them to the
noisy linear radiance. Weights that sum to one keep the image's mean; averaging PQ values
did not (Jensen), and the paper's sigmoid head, trained on our ~10^3x smaller budget,
returned a desaturated prior. The heads start at zero, so an untrained network is a box
filter at every level. `split="one"` predicts a single kernel used for luma and chroma
alike (the design comparison of docs/reconstruction-design.md).
"""

import torch
from torch import nn

ARCHS = ("ae", "demc", "temc1", "temc2")
ALIGNMENT = 32  # five 2x2 poolings
CHROMA, LUMA, AUX = 2, 1, 7
LEVELS = 3   # pyramid levels of the reconstruction (full, 1/2, 1/4 resolution)
KERNEL = 5   # k x k taps per level
SPLITS = ("both", "one")
# What a checkpoint was trained for when its "recon" (train.recon_settings) lacks a key:
# runs from before guides (temc2-w0.125, temc2-w0.0625) hold no "guide" and have no guide
# rows. train.py and export.py both fill the gaps from here, so a checkpoint loads alike.
RECON_DEFAULTS = {"levels": LEVELS, "kernel": KERNEL, "split": "both", "demodulate": False,
                  "eps": 0.01, "guide": False, "fixed_range": False, "upsample": "nearest",
                  "range_opening": "plain", "coarse_clamp": False, "range_noise": 0.0,
                  "coarse_gain": 1.0, "coarse_radius": 0, "coarse_sparse": 0.0}
# The architectures' names in the paper, the accuracy report and the model cards.
ARCH_NAMES = {"ae": "AE", "demc": "DEMC", "temc1": "TEMC-1", "temc2": "TEMC-2"}

# VGG16's convolutional part: (channels, convs) per level.
VGG_LEVELS = ((64, 2), (128, 2), (256, 3), (512, 3), (512, 3))
AE_DOWN = (32, 48, 56, 80, 104)
AE_UP = ((152, 152), (112, 112), (88, 88), (64, 64), (64, 32))


def scaled(c: int, width: float) -> int:
    return max(1, int(round(c * width)))


def conv3(cin: int, cout: int) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, 3, padding=1)


def filter_channels(kernel: int = KERNEL, guide: bool = False) -> int:
    """Channels of one level's filter output: luma taps, chroma taps, two blend logits and,
    with `guide`, a luma and a chroma guide (reconstruct.py: the range term)."""
    return 2 * kernel * kernel + (4 if guide else 2)


class FilterHeads(nn.Module):
    """Zero-initialised 1x1 convs from decoder features (finest level first) to filter
    logits, one per level. `part` says which half of a level's channels this network
    predicts: "both", "luma" or "chroma" (TEMC-1's two branches), or "one" (a single kernel
    and blend for luma and chroma, expanded to the full layout). With `guide` each part also
    predicts its guide channel(s), last; those start small and random rather than zero: the
    range term's gradient vanishes where all guides are equal."""

    def __init__(self, widths: list, levels: int, kernel: int, part: str = "both",
                 guide: bool = False):
        super().__init__()
        self.n = kernel * kernel
        self.part, self.guide = part, guide
        self.cout = filter_channels(kernel, guide) if part == "both" else self.n + 1 + guide
        self.convs = nn.ModuleList()
        for cin in widths[:levels]:
            c = nn.Conv2d(cin, self.cout, 1)
            nn.init.zeros_(c.weight)
            nn.init.zeros_(c.bias)
            if guide:
                init_guide_rows(c, self.cout - (2 if part == "both" else 1))
            c.is_head = True  # found by export.randomize_untrained
            self.convs.append(c)

    def forward(self, feats: list) -> list:
        outs = [conv(f) for conv, f in zip(self.convs, feats)]
        if self.part == "one":
            n = self.n
            outs = [torch.cat([o[:, :n], o[:, :n], o[:, n:n + 1], o[:, n:n + 1], o[:, n + 1:],
                               o[:, n + 1:]], dim=1) for o in outs]
        return outs


GUIDE_INIT_STD = 1e-2


def init_guide_rows(conv: nn.Conv2d, first: int) -> None:
    """Small random weights for the guide outputs `first`.. of a head conv (see FilterHeads)."""
    with torch.no_grad():
        g = torch.Generator().manual_seed(1234 + first)
        w = conv.weight[first:]
        w.copy_(GUIDE_INIT_STD * torch.randn(w.shape, generator=g))
        conv.bias[first:].zero_()


def join_luma_chroma(luma: list, chroma: list, kernel: int) -> list:
    """TEMC-1: the luma branch's (taps, blend[, guide]) and the chroma branch's, in the
    layout of filter_channels."""
    n = kernel * kernel
    return [torch.cat([l[:, :n], c[:, :n], l[:, n:n + 1], c[:, n:n + 1], l[:, n + 1:],
                       c[:, n + 1:]], dim=1)
            for l, c in zip(luma, chroma)]


class FFS(nn.Module):
    """DEMC's feature-fusion sub-network: aux buffers -> a 1-channel detail map D >= 0."""

    def __init__(self, cin: int, width: float):
        super().__init__()
        c = scaled(64, width)
        self.net = nn.Sequential(
            conv3(cin, c), nn.ReLU(),
            conv3(c, c), nn.BatchNorm2d(c, eps=1e-3, momentum=0.01), nn.ReLU(),
            conv3(c, c), nn.BatchNorm2d(c, eps=1e-3, momentum=0.01), nn.ReLU(),
            conv3(c, 1), nn.ReLU(),
        )

    def forward(self, x):
        return self.net(x)


class VGGEncoder(nn.Module):
    """VGG16's conv layers without BN; returns the five pre-pool skips and the latent."""

    def __init__(self, cin: int, width: float):
        super().__init__()
        self.levels = nn.ModuleList()
        c_prev = cin
        for c, n in VGG_LEVELS:
            c = scaled(c, width)
            layers = []
            for _ in range(n):
                layers += [conv3(c_prev, c), nn.ReLU()]
                c_prev = c
            self.levels.append(nn.Sequential(*layers))
        self.pool = nn.MaxPool2d(2)
        self.widths = [scaled(c, width) for c, _ in VGG_LEVELS]

    def forward(self, x):
        skips = []
        for level in self.levels:
            x = level(x)
            skips.append(x)
            x = self.pool(x)
        return skips, x


def up(cin: int, cout: int) -> nn.Sequential:
    """DEMC's up block: transposed conv k4 s2 p1 (exactly 2x), BN, ReLU."""
    return nn.Sequential(
        nn.ConvTranspose2d(cin, cout, 4, stride=2, padding=1),
        nn.BatchNorm2d(cout, eps=1e-3, momentum=0.01),
        nn.ReLU(),
    )


class Decoder(nn.Module):
    """DEMC's decoder over any number of encoders: at each level the previous decoder output
    and every encoder's skip are concatenated and fused by a linear 1x1 conv."""

    def __init__(self, skip_widths: list, n_encoders: int, levels: int, kernel: int, part: str,
                 guide: bool = False):
        super().__init__()
        w = skip_widths  # per level, the same for every encoder
        self.up1 = up(w[4], w[4])
        # levels 5..1: fuse(prev, skips) -> width of prev, then up (except after level 1)
        outs = [w[4], w[3], w[2], w[1], w[0]]  # decoder width entering each level
        ups = [w[3], w[2], w[1], w[0], None]
        self.fuse = nn.ModuleList()
        self.ups = nn.ModuleList()
        for lvl, (c, u) in enumerate(zip(outs, ups)):
            skip = w[4 - lvl]
            self.fuse.append(nn.Conv2d(c + n_encoders * skip, c, 1))
            if u is not None:
                self.ups.append(up(c, u))
        self.levels = levels
        self.heads = FilterHeads(w, levels, kernel, part, guide)

    def forward(self, z, skips_per_encoder: list) -> list:
        x = self.up1(z)
        feats = []
        for lvl, fuse in enumerate(self.fuse):
            level = 4 - lvl
            x = fuse(torch.cat([x] + [s[level] for s in skips_per_encoder], dim=1))
            if level < self.levels:
                feats.insert(0, x)
            if lvl < len(self.ups):
                x = self.ups[lvl](x)
        return self.heads(feats)


def latent_block(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(conv3(cin, cout), nn.BatchNorm2d(cout, eps=1e-3, momentum=0.01), nn.ReLU())


class DEMCNet(nn.Module):
    """One DEMC: HDR encoder on x, FFS on aux feeding a feature encoder whose latent is
    discarded (as in DEMC's code), latent conv, decoder with both encoders' skips."""

    def __init__(self, cin: int, width: float, levels: int, kernel: int, part: str, aux: int = AUX,
                 guide: bool = False):
        super().__init__()
        self.ffs = FFS(aux, width)
        self.hdr = VGGEncoder(cin, width)
        self.feat = VGGEncoder(1, width)
        w = self.hdr.widths
        self.latent = latent_block(w[4], w[4])
        self.decoder = Decoder(w, 2, levels, kernel, part, guide)

    def forward(self, x, aux):
        hs, z = self.hdr(x)
        fs, _ = self.feat(self.ffs(aux))
        return self.decoder(self.latent(z), [hs, fs])


class AENet(nn.Module):
    """The TEMC autoencoder (Chaitanya et al. 2017 without recurrence). Skips are taken
    before pooling; up5 uses a1 (our choice, recorded in the architecture note)."""

    def __init__(self, cin: int, width: float, levels: int, kernel: int, part: str,
                 guide: bool = False):
        super().__init__()
        d = [scaled(c, width) for c in AE_DOWN]
        u = [(scaled(a, width), scaled(b, width)) for a, b in AE_UP]
        c0 = scaled(32, width)
        self.c0 = nn.Sequential(conv3(cin, c0), nn.ReLU())
        self.down = nn.ModuleList()
        prev = c0
        for c in d:
            self.down.append(nn.Sequential(conv3(prev, c), nn.ReLU()))
            prev = c
        self.pool = nn.MaxPool2d(2)
        self.upsample = nn.Upsample(scale_factor=2, mode="nearest")
        self.up = nn.ModuleList()
        for (a, b), skip in zip(u, reversed(d)):
            self.up.append(nn.Sequential(conv3(prev + skip, a), nn.ReLU(), conv3(a, b), nn.ReLU()))
            prev = b
        out_widths = [b for _, b in reversed(u)]  # finest level first
        self.levels = levels
        self.heads = FilterHeads(out_widths, levels, kernel, part, guide)

    def forward(self, x) -> list:
        x = self.c0(x)
        skips = []
        for down in self.down:
            x = down(x)
            skips.append(x)
            x = self.pool(x)
        feats = []
        for block, skip in zip(self.up, reversed(skips)):
            x = block(torch.cat([self.upsample(x), skip], dim=1))
            feats.insert(0, x)
        return self.heads(feats[:self.levels])


class Denoiser(nn.Module):
    """What every architecture shares: the reconstruction it predicts filters for."""

    def __init__(self, levels: int, kernel: int, split: str, guide: bool = False):
        super().__init__()
        if split not in SPLITS:
            raise ValueError(f"unknown split {split!r}; expected one of {SPLITS}")
        if kernel % 2 != 1 or not 1 <= levels <= 5:
            raise ValueError(f"need an odd kernel and 1..5 levels, got {kernel}, {levels}")
        self.levels, self.kernel, self.split, self.guide = levels, kernel, split, guide


class AE(Denoiser):
    """Autoencoder baseline: chroma || luma || aux (10 channels) -> filters."""

    def __init__(self, width=1.0, levels=LEVELS, kernel=KERNEL, split="both", guide=False):
        super().__init__(levels, kernel, split, guide)
        self.net = AENet(CHROMA + LUMA + AUX, width, levels, kernel, split, guide)

    def forward(self, chroma, luma, aux):
        return self.net(torch.cat([chroma, luma, aux], dim=1))


class DEMC(Denoiser):
    """DEMC baseline on HSV = chroma || luma, with aux through its FFS."""

    def __init__(self, width=1.0, levels=LEVELS, kernel=KERNEL, split="both", guide=False):
        super().__init__(levels, kernel, split, guide)
        self.net = DEMCNet(CHROMA + LUMA, width, levels, kernel, split, guide=guide)

    def forward(self, chroma, luma, aux):
        return self.net(torch.cat([chroma, luma], dim=1), aux)


class TEMC1(Denoiser):
    """TEMC-1: a DEMC on chroma (+ aux) predicts the chroma filters; the autoencoder on luma
    predicts the luma filters. Nothing is shared between the two. (split "one" has no
    meaning here: the two branches are the split.)"""

    def __init__(self, width=1.0, levels=LEVELS, kernel=KERNEL, split="both", guide=False):
        super().__init__(levels, kernel, split, guide)
        self.chroma = DEMCNet(CHROMA, width, levels, kernel, "chroma", guide=guide)
        self.luma = AENet(LUMA, width, levels, kernel, "luma", guide)

    def forward(self, chroma, luma, aux):
        return join_luma_chroma(self.luma(luma), self.chroma(chroma, aux), self.kernel)


class TEMC2(Denoiser):
    """TEMC-2: chroma, luma and fused-aux VGG encoders; the chroma and luma latents are
    concatenated and stabilised by two convs; one decoder takes every encoder's skips."""

    def __init__(self, width=1.0, levels=LEVELS, kernel=KERNEL, split="both", guide=False):
        super().__init__(levels, kernel, split, guide)
        self.ffs = FFS(AUX, width)
        self.enc_c = VGGEncoder(CHROMA, width)
        self.enc_l = VGGEncoder(LUMA, width)
        self.enc_a = VGGEncoder(1, width)
        w = self.enc_c.widths
        self.stab = nn.Sequential(latent_block(2 * w[4], w[4]), latent_block(w[4], w[4]))
        self.decoder = Decoder(w, 3, levels, kernel, split, guide)

    def forward(self, chroma, luma, aux):
        cs, zc = self.enc_c(chroma)
        ls, zl = self.enc_l(luma)
        as_, _ = self.enc_a(self.ffs(aux))  # the aux latent is discarded, as in DEMC
        z = self.stab(torch.cat([zc, zl], dim=1))
        return self.decoder(z, [cs, ls, as_])


def build(arch: str, width: float = 1.0, levels: int = LEVELS, kernel: int = KERNEL,
          split: str = "both", guide: bool = False) -> nn.Module:
    """The model named `arch` (one of ARCHS) at `width`, predicting filters for `levels`
    levels of `kernel` x `kernel` taps; it returns a list of `levels` tensors
    [N, filter_channels(kernel, guide), H / 2^l, W / 2^l]."""
    classes = {"ae": AE, "demc": DEMC, "temc1": TEMC1, "temc2": TEMC2}
    if arch not in classes:
        raise ValueError(f"unknown architecture {arch!r}; expected one of {ARCHS}")
    return classes[arch](width, levels, kernel, split, guide)


def checkpoint_recon(ckpt: dict) -> dict:
    """The reconstruction a checkpoint's model was trained for (RECON_DEFAULTS where it
    does not say)."""
    return {**RECON_DEFAULTS, **(ckpt.get("recon") or {})}


def label(arch: str, width, levels: int = 1, passes: int = 1) -> str:
    """A model's name in the accuracy report and its model card, e.g. "TEMC-2 w0.125", with
    its pyramid levels where there are several ("TEMC-2 w0.125, 3 levels") and its flip
    passes where there are several ("..., 2 passes": balanced and high share a network),
    since the report keys its rows by this name."""
    name = f"{ARCH_NAMES[arch]} w{float(width):g}"
    if int(levels) > 1:
        name += f", {int(levels)} levels"
    return name if int(passes) == 1 else f"{name}, {int(passes)} passes"


def count_params(model: nn.Module) -> tuple:
    """(conv/deconv parameters, batch-norm gamma/beta) as the architecture note counts them."""
    bn = sum(p.numel() for m in model.modules() if isinstance(m, nn.BatchNorm2d)
             for p in m.parameters())
    total = sum(p.numel() for p in model.parameters())
    return total - bn, bn
