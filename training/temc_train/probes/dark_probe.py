"""Where do dark regions lose their light? The shipped balanced model leaves the Cycles
family's darkest regions well below their reference at low spp while the image's mean holds
(docs/keep-mean.md). This probe denoises every test scene in PyTorch, through the network
and the reconstruction the core runs, once as trained and once with one part of the
reconstruction switched off, and prints per spp the darkest quarter's light over the
reference's there (before and after the keep-mean stage) and the geometric-mean RelMSE.

    python -m temc_train.probes.dark_probe --data ../data/cycles-family \\
        --checkpoint runs/temc2-w0.125-energy/checkpoint.pt --fixed-range 1

Variants: `trained`; `no-guide` (the learned guides' range term off: guide logits 0);
`no-fixed` (the fixed range term on log luminance off); `flat` (every kernel logit 0, the
guides and the fixed term kept: what the range terms alone do); `box` (all of them off: a
plain 5x5 box per level, blends as trained); `conserve` (as trained, then the light each
input pixel's weights do not hand on, (1 - its weights' column sum) times its value, spread
evenly over its kernel's taps inside the image: every input pixel then gives exactly its
light, a sketch of the splatting form, done here only); `conserve-own` (the same light
splatted by the pixel's own gather weights instead of evenly). `--variants` picks some.

    python -m temc_train.probes.dark_probe --train-conserving -- TRAIN-ARGS

runs `drivers.train` with the conserving level filter (for trying whether training learns
the form; the core cannot run such a model: export refuses nothing, so do not ship one).
"""

import argparse
import contextlib

import numpy as np
import torch
import torch.nn.functional as F

from .. import data, evaluate
from .. import reconstruct as rc
from ..checkpoint import Checkpoint
from ..onnx_export import recon_of
from ..reconstruct import LUMA
from .probe import denoise

DARK_SHARE = 0.25
VARIANTS = ("trained", "no-guide", "no-fixed", "flat", "box", "conserve", "conserve-own")


def _handed_on(weights, kernel):
    """[N, 1, H, W]: the weight each input pixel gives over all outputs (the column sums of
    the gather weights [N, k^2, H, W]; fold is unfold's transpose)."""
    n, kk, h, w = weights.shape
    return F.fold(weights.reshape(n, kk, h * w), (h, w), kernel, padding=kernel // 2)


def _spread(d, kernel):
    """Each pixel of `d` [N, C, H, W] shared evenly over its kernel's taps inside the image."""
    ones = torch.ones(1, 1, *d.shape[-2:], dtype=d.dtype)
    box = lambda v: F.avg_pool2d(v, kernel, 1, kernel // 2, count_include_pad=True) * kernel ** 2  # noqa: E731
    return box(d / box(ones))


def _conserving_level(x, logits, kernel, guide=False, fixed_range=False, scale=1.0, opened_y=None,
                      noise=0.0):
    """reconstruct._filter_level plus the spread of what each input pixel did not hand on."""
    kk = kernel * kernel
    luma_w, chroma_w, y, logits = rc.level_weights(x, logits, kernel, guide, fixed_range, scale,
                                                   opened_y, noise)
    fy = rc._apply(y, luma_w, kernel) + _spread((1 - _handed_on(luma_w, kernel)) * y, kernel)
    fc = rc._apply(x, chroma_w, kernel) + _spread((1 - _handed_on(chroma_w, kernel)) * x, kernel)
    return fy, fc, logits[:, 2 * kk:2 * kk + 1], logits[:, 2 * kk + 1:2 * kk + 2]


def _splat(d, weights, kernel):
    """Each pixel of `d` [N, C, H, W] scattered to its taps by its own gather weights
    [N, k^2, H, W] (which sum to one over the taps inside: nothing leaves the image)."""
    n, c, h, w = d.shape
    cols = (d.unsqueeze(2) * weights.unsqueeze(1)).reshape(n, c * kernel * kernel, h * w)
    return F.fold(cols, (h, w), kernel, padding=kernel // 2)


def _conserving_own_level(x, logits, kernel, guide=False, fixed_range=False, scale=1.0,
                          opened_y=None, noise=0.0):
    """As _conserving_level, the unhanded light splatted by the pixel's own kernel (toward
    the neighbours its guides call alike) instead of a box."""
    kk = kernel * kernel
    luma_w, chroma_w, y, logits = rc.level_weights(x, logits, kernel, guide, fixed_range, scale,
                                                   opened_y, noise)
    fy = rc._apply(y, luma_w, kernel) + _splat((1 - _handed_on(luma_w, kernel)) * y, luma_w, kernel)
    fc = rc._apply(x, chroma_w, kernel) + _splat((1 - _handed_on(chroma_w, kernel)) * x, chroma_w, kernel)
    return fy, fc, logits[:, 2 * kk:2 * kk + 1], logits[:, 2 * kk + 1:2 * kk + 2]


@contextlib.contextmanager
def conserving(level=None):
    """reconstruct.py's level filter swapped for `level` (`_conserving_level`) while inside."""
    held = rc._filter_level
    rc._filter_level = level or _conserving_level
    try:
        yield
    finally:
        rc._filter_level = held


class Switched(torch.nn.Module):
    """The model with parts of its logits replaced, per `variant` (module docs)."""

    def __init__(self, model, kernel, variant):
        super().__init__()
        self.model, self.kk, self.variant = model, kernel * kernel, variant

    def forward(self, *inputs):
        outs = []
        for f in self.model(*inputs):
            f = f.clone()
            if self.variant in ("no-guide", "box"):
                f[:, 2 * self.kk + 2:] = 0.0
            if self.variant in ("flat", "box"):
                f[:, :2 * self.kk] = 0.0
            outs.append(f)
        return outs


def dark_ratio(out, ref):
    """Light in the reference's darkest quarter of pixels (by luminance), over the
    reference's light there."""
    lum = ref @ np.asarray(LUMA, ref.dtype)
    mask = lum <= np.quantile(lum, DARK_SHARE)
    o, r = (x[mask] @ np.asarray(LUMA, x.dtype) for x in (out, ref))
    return float(o.sum() / max(float(r.sum()), 1e-12))


def run(model, recon, scenes, variant, spps):
    """{spp: (gmean RelMSE, mean dark ratio raw, mean dark ratio kept)} of one variant."""
    recon = dict(recon, fixed_range=recon.get("fixed_range", False) and variant not in ("no-fixed", "box"))
    switched = Switched(model, recon["kernel"], variant)
    res = {}
    for sc in scenes:
        for s, spp in enumerate(sc.spp):
            if spp not in spps:
                continue
            ref = sc.a["reference"]
            level = {"conserve": _conserving_level, "conserve-own": _conserving_own_level}.get(variant)
            with conserving(level) if level else contextlib.nullcontext():
                kept = denoise(switched, recon, sc, s, keep=True)
                raw = denoise(switched, recon, sc, s, keep=False)
            res.setdefault(spp, []).append((evaluate.relmse(kept, ref), dark_ratio(raw, ref),
                                            dark_ratio(kept, ref)))
    return {spp: (float(np.exp(np.mean(np.log([v[0] for v in rows])))),
                  float(np.mean([v[1] for v in rows])), float(np.mean([v[2] for v in rows])))
            for spp, rows in res.items()}


def main(argv=None):
    import sys
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--train-conserving"]:
        from ..drivers import train
        with conserving():
            return train.main(argv[2:] if argv[1:2] == ["--"] else argv[1:])
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--checkpoint", required=True)
    ap.add_argument("--spp", default="4,16,64")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated, of VARIANTS")
    ap.add_argument("--fixed-range", type=int, choices=(0, 1), default=None,
                    help="the fixed range term on or off (default: as the checkpoint trained; "
                         "shipped models have it on, ship.SHIP_RECON)")
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    spps = {int(v) for v in a.spp.split(",")}
    scenes = data.load_split(a.data, "test")
    model = Checkpoint.read(a.checkpoint).build()[0].eval()
    recon = recon_of(model)
    if a.fixed_range is not None:
        recon = dict(recon, fixed_range=bool(a.fixed_range))
    noisy = {spp: np.mean([dark_ratio(sc.a["color"][s], sc.a["reference"])
                           for sc in scenes for s, v in enumerate(sc.spp) if v == spp])
             for spp in sorted(spps)}
    print(f"{len(scenes)} scenes; the darkest {DARK_SHARE:.0%} of each reference's pixels; "
          "dark: their light over the reference's (raw: before keep-mean; kept: after)\n")
    print("| variant | spp | RelMSE | dark raw | dark kept | noisy input's dark |")
    print("|---|---:|---:|---:|---:|---:|")
    for variant in a.variants.split(","):
        for spp, (rel, raw, kept) in sorted(run(model, recon, scenes, variant, spps).items()):
            print(f"| {variant} | {spp} | {rel:.4g} | {raw:.3f} | {kept:.3f} | {noisy[spp]:.3f} |",
                  flush=True)


if __name__ == "__main__":
    main()
