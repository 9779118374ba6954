"""TEMC-2, TEMC-1, DEMC and the TEMC autoencoder, following
../shared/reference/temc-architecture.md layer by layer.

Every model takes the same three inputs (docs/contracts.md §2): chroma (H, S) [N,2,H,W],
luma V [N,1,H,W] and aux (albedo 3, normal 3, depth 1) [N,7,H,W], and returns HSV in [0,1]
[N,3,H,W]. `width` scales every internal channel count (1.0 = the paper's network);
inputs, outputs and the 1-channel detail map keep their sizes.
"""

import torch
from torch import nn

ARCHS = ("ae", "demc", "temc1", "temc2")
ALIGNMENT = 32  # five 2x2 poolings
CHROMA, LUMA, AUX = 2, 1, 7

# VGG16's convolutional part: (channels, convs) per level.
VGG_LEVELS = ((64, 2), (128, 2), (256, 3), (512, 3), (512, 3))
AE_DOWN = (32, 48, 56, 80, 104)
AE_UP = ((152, 152), (112, 112), (88, 88), (64, 64), (64, 32))


def scaled(c: int, width: float) -> int:
    return max(1, int(round(c * width)))


def conv3(cin: int, cout: int) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, 3, padding=1)


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

    def __init__(self, skip_widths: list, n_encoders: int, cout: int):
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
        self.out = conv3(w[0], cout)

    def forward(self, z, skips_per_encoder: list):
        x = self.up1(z)
        for lvl, fuse in enumerate(self.fuse):
            level = 4 - lvl
            x = fuse(torch.cat([x] + [s[level] for s in skips_per_encoder], dim=1))
            if lvl < len(self.ups):
                x = self.ups[lvl](x)
        return torch.sigmoid(self.out(x))


def latent_block(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(conv3(cin, cout), nn.BatchNorm2d(cout, eps=1e-3, momentum=0.01), nn.ReLU())


class DEMCNet(nn.Module):
    """One DEMC: HDR encoder on x, FFS on aux feeding a feature encoder whose latent is
    discarded (as in DEMC's code), latent conv, decoder with both encoders' skips."""

    def __init__(self, cin: int, cout: int, width: float, aux: int = AUX):
        super().__init__()
        self.ffs = FFS(aux, width)
        self.hdr = VGGEncoder(cin, width)
        self.feat = VGGEncoder(1, width)
        w = self.hdr.widths
        self.latent = latent_block(w[4], w[4])
        self.decoder = Decoder(w, 2, cout)

    def forward(self, x, aux):
        hs, z = self.hdr(x)
        fs, _ = self.feat(self.ffs(aux))
        return self.decoder(self.latent(z), [hs, fs])


class AENet(nn.Module):
    """The TEMC autoencoder (Chaitanya et al. 2017 without recurrence). Skips are taken
    before pooling; up5 uses a1 (our choice, recorded in the architecture note)."""

    def __init__(self, cin: int, cout: int, width: float):
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
        self.final = conv3(prev, cout)

    def forward(self, x):
        x = self.c0(x)
        skips = []
        for down in self.down:
            x = down(x)
            skips.append(x)
            x = self.pool(x)
        for block, skip in zip(self.up, reversed(skips)):
            x = block(torch.cat([self.upsample(x), skip], dim=1))
        return torch.sigmoid(self.final(x))


class AE(nn.Module):
    """Autoencoder baseline: chroma || luma || aux (10 channels) -> HSV."""

    def __init__(self, width: float = 1.0):
        super().__init__()
        self.net = AENet(CHROMA + LUMA + AUX, 3, width)

    def forward(self, chroma, luma, aux):
        return self.net(torch.cat([chroma, luma, aux], dim=1))


class DEMC(nn.Module):
    """DEMC baseline on HSV = chroma || luma, with aux through its FFS."""

    def __init__(self, width: float = 1.0):
        super().__init__()
        self.net = DEMCNet(CHROMA + LUMA, 3, width)

    def forward(self, chroma, luma, aux):
        return self.net(torch.cat([chroma, luma], dim=1), aux)


class TEMC1(nn.Module):
    """TEMC-1: a DEMC on chroma (+ aux) predicts (H, S); the autoencoder on luma predicts V.
    Nothing is shared between the two."""

    def __init__(self, width: float = 1.0):
        super().__init__()
        self.chroma = DEMCNet(CHROMA, 2, width)
        self.luma = AENet(LUMA, 1, width)

    def forward(self, chroma, luma, aux):
        return torch.cat([self.chroma(chroma, aux), self.luma(luma)], dim=1)


class TEMC2(nn.Module):
    """TEMC-2: chroma, luma and fused-aux VGG encoders; the chroma and luma latents are
    concatenated and stabilised by two convs; one decoder takes every encoder's skips."""

    def __init__(self, width: float = 1.0):
        super().__init__()
        self.ffs = FFS(AUX, width)
        self.enc_c = VGGEncoder(CHROMA, width)
        self.enc_l = VGGEncoder(LUMA, width)
        self.enc_a = VGGEncoder(1, width)
        w = self.enc_c.widths
        self.stab = nn.Sequential(latent_block(2 * w[4], w[4]), latent_block(w[4], w[4]))
        self.decoder = Decoder(w, 3, 3)

    def forward(self, chroma, luma, aux):
        cs, zc = self.enc_c(chroma)
        ls, zl = self.enc_l(luma)
        as_, _ = self.enc_a(self.ffs(aux))  # the aux latent is discarded, as in DEMC
        z = self.stab(torch.cat([zc, zl], dim=1))
        return self.decoder(z, [cs, ls, as_])


def build(arch: str, width: float = 1.0) -> nn.Module:
    """The model named `arch` (one of ARCHS) at `width`."""
    classes = {"ae": AE, "demc": DEMC, "temc1": TEMC1, "temc2": TEMC2}
    if arch not in classes:
        raise ValueError(f"unknown architecture {arch!r}; expected one of {ARCHS}")
    return classes[arch](width)


def count_params(model: nn.Module) -> tuple:
    """(conv/deconv parameters, batch-norm gamma/beta) as the architecture note counts them."""
    bn = sum(p.numel() for m in model.modules() if isinstance(m, nn.BatchNorm2d)
             for p in m.parameters())
    total = sum(p.numel() for p in model.parameters())
    return total - bn, bn
