"""ONNX export of temc models with their metadata, checked against onnxruntime (the
library half of drivers/export.py, which is the command line; drivers/train.py and
drivers/ship.py export through it too). The graph's outputs are the filter logits
`filters0` .. `filters{L-1}` (docs/reconstruction.md); the reconstruction itself runs in
the core."""

import os
import warnings

import numpy as np
import onnx
import torch
from torch import nn

from . import color, fuse, receptive
from .models import ALIGNMENT, AUX, CHROMA, LUMA, RECON_DEFAULTS

OPSET = 17
INPUTS = ("chroma", "luma", "aux")
CHANNELS = (CHROMA, LUMA, AUX)
GOLDEN_WIDTH = 0.0625
# Non-square (a transposed axis shows), a multiple of ALIGNMENT, and small: the goldens of
# four baselines count in the tree budget (tests/tree_size.rs).
GOLDEN_SIZE = (32, 64)
PARITY_TOL = 1e-4


def example_inputs(h: int, w: int, seed: int = 0, batch: int = 1) -> list:
    g = torch.Generator().manual_seed(seed)
    return [torch.rand(batch, c, h, w, generator=g) for c in CHANNELS]


def output_names(levels: int) -> list:
    return [f"filters{l}" for l in range(levels)]


def recon_of(model) -> dict:
    """The reconstruction settings a model was built for (RECON_DEFAULTS for what a model
    does not carry, as for checkpoints: demodulation off)."""
    d = RECON_DEFAULTS
    return {"levels": model.levels, "kernel": model.kernel, "split": model.split,
            "demodulate": bool(getattr(model, "demodulate", d["demodulate"])),
            "eps": float(getattr(model, "eps", d["eps"])), "guide": bool(getattr(model, "guide", d["guide"])),
            "fixed_range": bool(getattr(model, "fixed_range", d["fixed_range"])),
            "upsample": getattr(model, "upsample", d["upsample"]),
            "range_opening": getattr(model, "range_opening", d["range_opening"]),
            "coarse_clamp": bool(getattr(model, "coarse_clamp", d["coarse_clamp"])),
            "range_noise": float(getattr(model, "range_noise", d["range_noise"])),
            "coarse_gain": float(getattr(model, "coarse_gain", d["coarse_gain"])),
            "coarse_radius": int(getattr(model, "coarse_radius", d["coarse_radius"])),
            "coarse_sparse": float(getattr(model, "coarse_sparse", d["coarse_sparse"]))}


def metadata(arch: str, width: float, recon: dict, dataset: str = "none", steps: int = 0,
             test_relmse=None, description: str = "", tile_overlap=None, passes: int = 1) -> dict:
    """The contract's metadata_props (docs/contracts.md §2), all values strings. `passes`
    is how many flip passes a filter runs the model over by default (`temc.passes`).
    `tile_overlap` is the measured one (receptive.effective_overlap) for trained models; by
    default the theoretical bound (network receptive field plus reconstruction reach)."""
    if tile_overlap is None:
        tile_overlap = receptive.tile_overlap(arch, recon["levels"], recon["kernel"],
                                              recon.get("upsample", "nearest"))
    return {
        "temc.format": "2",
        "temc.architecture": arch,
        "temc.width": repr(float(width)),
        "temc.alignment": str(ALIGNMENT),
        "temc.receptive_field": str(receptive.receptive_field(arch)),
        "temc.tile_overlap": str(int(tile_overlap)),
        "temc.levels": str(recon["levels"]),
        "temc.kernel": str(recon["kernel"]),
        "temc.split": recon["split"],
        "temc.demodulate": "1" if recon["demodulate"] else "0",
        "temc.demod_eps": repr(float(recon["eps"])),
        "temc.guide": "1" if recon.get("guide") else "0",
        "temc.fixed_range": "1" if recon.get("fixed_range") else "0",
        "temc.upsample": recon.get("upsample", "nearest"),
        "temc.range_opening": recon.get("range_opening", "plain"),
        "temc.coarse_clamp": "1" if recon.get("coarse_clamp") else "0",
        "temc.range_noise": repr(float(recon.get("range_noise", 0.0))),
        "temc.coarse_gain": repr(float(recon.get("coarse_gain", 1.0))),
        "temc.coarse_radius": str(int(recon.get("coarse_radius", 0))),
        "temc.coarse_sparse": repr(float(recon.get("coarse_sparse", 0.0))),
        "temc.chroma_encoding": "hs",
        "temc.aux_layout": "albedo:3,normal:3,depth:1",
        "temc.pq_nits_per_unit": f"{color.NITS_PER_UNIT:g}",
        "temc.dataset": dataset,
        "temc.train_steps": str(int(steps)),
        "temc.test_relmse": "none" if test_relmse is None else repr(float(test_relmse)),
        "temc.description": description,
        "temc.passes": str(int(passes)),
    }


class _Wrapper(nn.Module):
    """Gives the exported graph named inputs in the contract's order."""

    def __init__(self, model):
        super().__init__()
        self.model = model

    def forward(self, chroma, luma, aux):
        return tuple(self.model(chroma, luma, aux))


def max_diff(a: list, b: list) -> float:
    """Max abs difference over every level's filter logits, relative to the level's largest
    logit when that exceeds 1: trained logits reach tens, where float32 rounding alone is
    ~1e-5 of them, and a logit error e scales a weight by exp(e)."""
    out = 0.0
    for x, y in zip(a, b):
        x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
        out = max(out, float(np.abs(x - y).max() / max(1.0, np.abs(y).max())))
    return out


@torch.no_grad()
def randomize_untrained(model: nn.Module, seed: int) -> None:
    """Gives an untrained test or benchmark model non-trivial weights where a fresh one is
    trivial: every BN gets random statistics and affine parameters (so the folded BN
    arithmetic is exercised), every output head random weights (a fresh head is zero, so
    the model would return its input unchanged)."""
    g = torch.Generator().manual_seed(seed)
    for m in model.modules():
        if getattr(m, "is_head", False):
            bound = 1.0 / np.sqrt(m.weight[0].numel())
            m.weight.copy_((torch.rand(m.weight.shape, generator=g) * 2 - 1) * bound)
            m.bias.copy_((torch.rand(m.bias.shape, generator=g) * 2 - 1) * bound)
        if isinstance(m, nn.BatchNorm2d):
            n = m.num_features
            m.running_mean.copy_(torch.rand(n, generator=g) * 0.2 - 0.1)
            m.running_var.copy_(torch.rand(n, generator=g) * 1.5 + 0.5)
            m.weight.copy_(torch.rand(n, generator=g) * 1.0 + 0.5)
            m.bias.copy_(torch.rand(n, generator=g) * 0.2 - 0.1)


def ort_session(path: str):
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_DISABLE_ALL
    opts.intra_op_num_threads = 2
    return ort.InferenceSession(path, opts, providers=["CPUExecutionProvider"])


def run_ort(path: str, xs: list) -> list:
    """Every level's filter logits, as onnxruntime computes them."""
    sess = ort_session(path)
    names = [o.name for o in sess.get_outputs()]
    return sess.run(names, {n: x.numpy() for n, x in zip(INPUTS, xs)})


def export(model: nn.Module, path: str, meta: dict, variant: str = "plain",
           check_size=(64, 64)) -> float:
    """Exports `model` (put in eval mode) to `path` and checks onnxruntime against PyTorch
    on a random input; returns the max abs difference, raising if above PARITY_TOL.

    variant "fused" applies the exact graph rewrites of fuse.py first."""
    model = model.eval()
    xs = example_inputs(*check_size, seed=123)
    net = _Wrapper(model).eval()  # a new module starts in training mode
    if variant == "fused":
        net = fuse.fuse_for_inference(net, xs)
    elif variant != "plain":
        raise ValueError(f"unknown variant {variant!r}")
    meta = dict(meta, **{"temc.export_variant": variant})
    outs = output_names(model.levels)
    tmp = path + ".tmp"
    with torch.no_grad(), warnings.catch_warnings():
        # The legacy exporter is chosen on purpose (docs/contracts.md §2); it says it is.
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        torch.onnx.export(
            net, tuple(xs), tmp, opset_version=OPSET, dynamo=False,
            do_constant_folding=True, input_names=list(INPUTS), output_names=outs,
            dynamic_axes={n: {0: "N", 2: "H", 3: "W"} for n in list(INPUTS) + outs},
        )
    m = onnx.load(tmp)
    del m.metadata_props[:]
    for k, v in meta.items():
        m.metadata_props.add(key=k, value=v)
    onnx.checker.check_model(m)
    onnx.save(m, tmp)
    with torch.no_grad():
        want = [f.numpy() for f in model(*xs)]
    got = run_ort(tmp, xs)
    diff = max_diff(got, want)
    if not diff <= PARITY_TOL:
        os.remove(tmp)
        raise RuntimeError(f"{path}: onnxruntime differs from PyTorch by {diff:.3g}")
    os.replace(tmp, path)
    return diff

