"""TEMC-2, TEMC-1, DEMC and the TEMC autoencoder, following
../shared/reference/temc-architecture.md layer by layer.

Every model takes the same three inputs (docs/contracts.md §2): chroma (H, S) [N,2,H,W],
luma V [N,1,H,W] and aux (albedo 3, normal 3, depth 1) [N,7,H,W], and returns HSV in [0,1]
[N,3,H,W]. `width` scales every internal channel count (1.0 = the paper's network);
inputs, outputs and the 1-channel detail map keep their sizes.

Output head (our deviation from the paper, the same for every architecture): a
kernel-predicting head (Bako et al. 2017). The last conv predicts, per pixel, KERNEL x KERNEL
weights (softmax) that average the noisy input's R'G'B' (the core's PQ-encoded RGB) over the
pixel's neighbourhood; the result goes back to HSV inside the graph. The last conv starts at
zero, so an untrained network is a box filter. The paper's sigmoid head has to learn the
image itself; on our ~10^3x smaller training budget (2 CPU cores instead of 4 GPUs for 8
hours) networks trained that way returned a smoothed, desaturated prior that lost the
input's colour (ΔE-ITP worse than the noisy input, the same error at 4 and 256 spp), and a
residual head (a correction to H, S, V) stayed at its noisy input. Averaging never invents
colour, and R'G'B' averages hue without a wrap-around. `head="direct"` builds the paper's
sigmoid head, for training on real compute.
"""

import torch
from torch import nn

ARCHS = ("ae", "demc", "temc1", "temc2")
ALIGNMENT = 32  # five 2x2 poolings
CHROMA, LUMA, AUX = 2, 1, 7
KERNEL = 5  # the head's neighbourhood; 5x5 costs ~2.5k multiply-adds per pixel in tract
HEADS = ("kernel", "direct")

# VGG16's convolutional part: (channels, convs) per level.
VGG_LEVELS = ((64, 2), (128, 2), (256, 3), (512, 3), (512, 3))
AE_DOWN = (32, 48, 56, 80, 104)
AE_UP = ((152, 152), (112, 112), (88, 88), (64, 64), (64, 32))


def scaled(c: int, width: float) -> int:
    return max(1, int(round(c * width)))


def conv3(cin: int, cout: int) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, 3, padding=1)


def head(cin: int, cout: int) -> nn.Conv2d:
    """The last conv. It starts at zero: the kernel head is then a box filter."""
    c = conv3(cin, cout)
    nn.init.zeros_(c.weight)
    nn.init.zeros_(c.bias)
    c.is_head = True  # found by export.randomize_untrained
    return c


def hsv_to_rgb(hsv: torch.Tensor) -> torch.Tensor:
    """[N, 3, H, W] HSV in [0,1] -> the core's R'G'B' (the 6-sector formula of
    src/color/hsv.rs). Periodic in H."""
    h, s, v = hsv[:, 0:1], hsv[:, 1:2], hsv[:, 2:3]
    out = []
    for n in (5.0, 3.0, 1.0):  # R, G, B
        k = n + 6.0 * h
        k = k - 6.0 * torch.floor(k / 6.0)
        out.append(v - v * s * torch.clamp(torch.minimum(k, 4.0 - k), 0.0, 1.0))
    return torch.cat(out, dim=1)


def rgb_to_hsv(rgb: torch.Tensor) -> torch.Tensor:
    """[N, 3, H, W] R'G'B' in [0,1] -> HSV as src/color/hsv.rs computes it (H = 0 where
    max == min, S = 0 where max == 0), with no division by zero in either branch."""
    r, g, b = rgb[:, 0:1], rgb[:, 1:2], rgb[:, 2:3]
    mx = torch.maximum(torch.maximum(r, g), b)
    mn = torch.minimum(torch.minimum(r, g), b)
    d = mx - mn
    grey = d <= 0
    d1 = torch.where(grey, torch.ones_like(d), d)
    h6 = torch.where(mx == r, (g - b) / d1, torch.where(mx == g, (b - r) / d1 + 2.0, (r - g) / d1 + 4.0))
    h6 = torch.where(h6 < 0, h6 + 6.0, h6)
    h = torch.where(grey, torch.zeros_like(h6), h6 / 6.0)
    s = torch.where(mx > 0, d / torch.where(mx > 0, mx, torch.ones_like(mx)), torch.zeros_like(mx))
    return torch.cat([h, s, mx], dim=1)


class KernelApply(nn.Module):
    """Averages an image's channels over each pixel's KERNEL x KERNEL neighbourhood with
    per-pixel weights. Taps outside the image get no weight (the rest are renormalised), so
    borders are not darkened. The neighbourhood is gathered by a conv with one-hot kernels:
    plain Conv is what every ONNX runtime runs fast."""

    def __init__(self, k: int = KERNEL):
        super().__init__()
        taps = torch.zeros(k * k, 1, k, k)
        for i in range(k * k):
            taps[i, 0, i // k, i % k] = 1.0
        self.register_buffer("taps", taps)
        self.pad = k // 2

    def forward(self, logits: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """logits [N, k*k, H, W] (softmaxed here), x [N, 3, H, W] -> [N, 3, H, W]. (Three
        channels spelled out: torch.fx, which fuse.py uses, cannot loop over a shape.)"""
        gather = lambda c: nn.functional.conv2d(c, self.taps, padding=self.pad)  # noqa: E731
        # The softmax spelled out and renormalised over the taps inside the image in one
        # division: tract's Softmax over the channel axis took 3/4 of the whole network's
        # time; ReduceMax, Exp, ReduceSum and Div are fast.
        e = torch.exp(logits - logits.amax(dim=1, keepdim=True))
        e = e * gather(torch.ones_like(x[:, :1]))
        w = e / e.sum(dim=1, keepdim=True)
        return torch.cat([(gather(x[:, i:i + 1]) * w).sum(dim=1, keepdim=True)
                          for i in range(3)], dim=1)


class Output(nn.Module):
    """The output head over the decoder's features (module doc): `kernel` filters the noisy
    input, `direct` is the paper's sigmoid."""

    def __init__(self, cin: int, cout: int, kind: str):
        super().__init__()
        if kind not in HEADS:
            raise ValueError(f"unknown head {kind!r}; expected one of {HEADS}")
        self.kind = kind
        self.conv = head(cin, KERNEL * KERNEL) if kind == "kernel" else conv3(cin, cout)
        self.cout = cout
        if kind == "kernel":
            self.apply_kernel = KernelApply()

    def forward(self, feat: torch.Tensor, noisy_hsv: torch.Tensor) -> torch.Tensor:
        """HSV, or its last `cout` channels' source: (H, S) for 2, V for 1."""
        if self.kind == "direct":
            return torch.sigmoid(self.conv(feat))
        hsv = rgb_to_hsv(self.apply_kernel(self.conv(feat), hsv_to_rgb(noisy_hsv)))
        return hsv if self.cout == 3 else hsv[:, :2] if self.cout == 2 else hsv[:, 2:]


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

    def __init__(self, skip_widths: list, n_encoders: int, cout: int, head_kind: str):
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
        self.out = Output(w[0], cout, head_kind)

    def forward(self, z, skips_per_encoder: list, noisy_hsv):
        x = self.up1(z)
        for lvl, fuse in enumerate(self.fuse):
            level = 4 - lvl
            x = fuse(torch.cat([x] + [s[level] for s in skips_per_encoder], dim=1))
            if lvl < len(self.ups):
                x = self.ups[lvl](x)
        return self.out(x, noisy_hsv)


def latent_block(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(conv3(cin, cout), nn.BatchNorm2d(cout, eps=1e-3, momentum=0.01), nn.ReLU())


class DEMCNet(nn.Module):
    """One DEMC: HDR encoder on x, FFS on aux feeding a feature encoder whose latent is
    discarded (as in DEMC's code), latent conv, decoder with both encoders' skips."""

    def __init__(self, cin: int, cout: int, width: float, head_kind: str, aux: int = AUX):
        super().__init__()
        self.ffs = FFS(aux, width)
        self.hdr = VGGEncoder(cin, width)
        self.feat = VGGEncoder(1, width)
        w = self.hdr.widths
        self.latent = latent_block(w[4], w[4])
        self.decoder = Decoder(w, 2, cout, head_kind)

    def forward(self, x, aux, noisy_hsv):
        hs, z = self.hdr(x)
        fs, _ = self.feat(self.ffs(aux))
        return self.decoder(self.latent(z), [hs, fs], noisy_hsv)


class AENet(nn.Module):
    """The TEMC autoencoder (Chaitanya et al. 2017 without recurrence). Skips are taken
    before pooling; up5 uses a1 (our choice, recorded in the architecture note)."""

    def __init__(self, cin: int, cout: int, width: float, head_kind: str):
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
        self.final = Output(prev, cout, head_kind)

    def forward(self, x, noisy_hsv):
        x = self.c0(x)
        skips = []
        for down in self.down:
            x = down(x)
            skips.append(x)
            x = self.pool(x)
        for block, skip in zip(self.up, reversed(skips)):
            x = block(torch.cat([self.upsample(x), skip], dim=1))
        return self.final(x, noisy_hsv)


class AE(nn.Module):
    """Autoencoder baseline: chroma || luma || aux (10 channels) -> HSV."""

    def __init__(self, width: float = 1.0, head: str = "kernel"):
        super().__init__()
        self.net = AENet(CHROMA + LUMA + AUX, 3, width, head)

    def forward(self, chroma, luma, aux):
        hsv = torch.cat([chroma, luma], dim=1)
        return self.net(torch.cat([hsv, aux], dim=1), hsv)


class DEMC(nn.Module):
    """DEMC baseline on HSV = chroma || luma, with aux through its FFS."""

    def __init__(self, width: float = 1.0, head: str = "kernel"):
        super().__init__()
        self.net = DEMCNet(CHROMA + LUMA, 3, width, head)

    def forward(self, chroma, luma, aux):
        hsv = torch.cat([chroma, luma], dim=1)
        return self.net(hsv, aux, hsv)


class TEMC1(nn.Module):
    """TEMC-1: a DEMC on chroma (+ aux) predicts (H, S); the autoencoder on luma predicts V.
    Nothing is shared between the two."""

    def __init__(self, width: float = 1.0, head: str = "kernel"):
        super().__init__()
        self.chroma = DEMCNet(CHROMA, 2, width, head)
        self.luma = AENet(LUMA, 1, width, head)

    def forward(self, chroma, luma, aux):
        hsv = torch.cat([chroma, luma], dim=1)
        return torch.cat([self.chroma(chroma, aux, hsv), self.luma(luma, hsv)], dim=1)


class TEMC2(nn.Module):
    """TEMC-2: chroma, luma and fused-aux VGG encoders; the chroma and luma latents are
    concatenated and stabilised by two convs; one decoder takes every encoder's skips."""

    def __init__(self, width: float = 1.0, head: str = "kernel"):
        super().__init__()
        self.ffs = FFS(AUX, width)
        self.enc_c = VGGEncoder(CHROMA, width)
        self.enc_l = VGGEncoder(LUMA, width)
        self.enc_a = VGGEncoder(1, width)
        w = self.enc_c.widths
        self.stab = nn.Sequential(latent_block(2 * w[4], w[4]), latent_block(w[4], w[4]))
        self.decoder = Decoder(w, 3, 3, head)

    def forward(self, chroma, luma, aux):
        cs, zc = self.enc_c(chroma)
        ls, zl = self.enc_l(luma)
        as_, _ = self.enc_a(self.ffs(aux))  # the aux latent is discarded, as in DEMC
        z = self.stab(torch.cat([zc, zl], dim=1))
        return self.decoder(z, [cs, ls, as_], torch.cat([chroma, luma], dim=1))


def build(arch: str, width: float = 1.0, head: str = "kernel") -> nn.Module:
    """The model named `arch` (one of ARCHS) at `width` with the output `head` (HEADS)."""
    classes = {"ae": AE, "demc": DEMC, "temc1": TEMC1, "temc2": TEMC2}
    if arch not in classes:
        raise ValueError(f"unknown architecture {arch!r}; expected one of {ARCHS}")
    return classes[arch](width, head)


def count_params(model: nn.Module) -> tuple:
    """(conv/deconv parameters, batch-norm gamma/beta) as the architecture note counts them."""
    bn = sum(p.numel() for m in model.modules() if isinstance(m, nn.BatchNorm2d)
             for p in m.parameters())
    total = sum(p.numel() for p in model.parameters())
    return total - bn, bn
