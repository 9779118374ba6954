"""Export temc models to ONNX with their metadata, checked against onnxruntime.

    python -m temc_train.export --arch temc2 --width 0.125 --out m.onnx [--variant fused]
    python -m temc_train.export --golden ../tests/data

The first form writes one model (random weights unless --checkpoint is given; benchmarks use
this). The second writes the untrained test models of every architecture and their golden
input/output tensors for the Rust parity tests (docs/contracts.md §3).
"""

import argparse
import functools
import math
import os

import numpy as np
import onnx
import torch
from torch import nn

from . import fuse
from .models import ALIGNMENT, ARCHS, AUX, CHROMA, LUMA, build

OPSET = 17
INPUTS = ("chroma", "luma", "aux")
CHANNELS = (CHROMA, LUMA, AUX)
GOLDEN_WIDTH = 0.0625
GOLDEN_SIZE = (64, 96)
PARITY_TOL = 1e-4


def example_inputs(h: int, w: int, seed: int = 0, batch: int = 1) -> list:
    g = torch.Generator().manual_seed(seed)
    return [torch.rand(batch, c, h, w, generator=g) for c in CHANNELS]


@functools.lru_cache(maxsize=None)
def receptive_field(arch: str) -> int:
    """The theoretical receptive field in pixels, measured: the extent of the input region
    whose gradient on the centre output pixel is non-zero, united over several random
    inputs (max-pooling routes each gradient through one pixel only). It does not depend on
    the width, so a narrow instance is used."""
    torch.manual_seed(0)
    model = build(arch, GOLDEN_WIDTH).eval()
    size = 512
    while True:
        hit = torch.zeros(size, size, dtype=torch.bool)
        for seed in range(4):
            xs = [x.requires_grad_() for x in example_inputs(size, size, seed)]
            out = model(*xs)
            out[0, :, size // 2, size // 2].sum().backward()
            for x in xs:
                hit |= (x.grad[0].abs() > 0).any(dim=0)
        rows = hit.any(dim=1).nonzero()
        cols = hit.any(dim=0).nonzero()
        touches = rows.min() == 0 or cols.min() == 0 or rows.max() == size - 1 or cols.max() == size - 1
        if not touches:
            return int(max(rows.max() - rows.min(), cols.max() - cols.min()) + 1)
        size *= 2


def tile_overlap(rf: int) -> int:
    """Half the receptive field, rounded up to the alignment."""
    return int(math.ceil(rf / 2 / ALIGNMENT) * ALIGNMENT)


def metadata(arch: str, width: float, dataset: str = "none", steps: int = 0,
             test_relmse: str = "none", description: str = "") -> dict:
    rf = receptive_field(arch)
    return {
        "temc.format": "1",
        "temc.architecture": arch,
        "temc.width": repr(float(width)),
        "temc.alignment": str(ALIGNMENT),
        "temc.receptive_field": str(rf),
        "temc.tile_overlap": str(tile_overlap(rf)),
        "temc.chroma_encoding": "hs",
        "temc.aux_layout": "albedo:3,normal:3,depth:1",
        "temc.pq_nits_per_unit": "100",
        "temc.dataset": dataset,
        "temc.train_steps": str(steps),
        "temc.test_relmse": test_relmse,
        "temc.description": description,
    }


class _Wrapper(nn.Module):
    """Gives the exported graph named inputs in the contract's order."""

    def __init__(self, model):
        super().__init__()
        self.model = model

    def forward(self, chroma, luma, aux):
        return self.model(chroma, luma, aux)


@torch.no_grad()
def randomize_batchnorm(model: nn.Module, seed: int) -> None:
    """Gives every BN non-trivial statistics and affine parameters, so that an untrained
    test model exercises the folded BN arithmetic instead of an identity."""
    g = torch.Generator().manual_seed(seed)
    for m in model.modules():
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


def run_ort(path: str, xs: list) -> np.ndarray:
    sess = ort_session(path)
    return sess.run(["hsv"], {n: x.numpy() for n, x in zip(INPUTS, xs)})[0]


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
    tmp = path + ".tmp"
    with torch.no_grad():
        torch.onnx.export(
            net, tuple(xs), tmp, opset_version=OPSET, dynamo=False,
            do_constant_folding=True, input_names=list(INPUTS), output_names=["hsv"],
            dynamic_axes={n: {0: "N", 2: "H", 3: "W"} for n in list(INPUTS) + ["hsv"]},
        )
    m = onnx.load(tmp)
    del m.metadata_props[:]
    for k, v in meta.items():
        m.metadata_props.add(key=k, value=v)
    onnx.checker.check_model(m)
    onnx.save(m, tmp)
    with torch.no_grad():
        want = model(*xs).numpy()
    got = run_ort(tmp, xs)
    diff = float(np.abs(got - want).max())
    if not diff <= PARITY_TOL:
        os.remove(tmp)
        raise RuntimeError(f"{path}: onnxruntime differs from PyTorch by {diff:.3g}")
    os.replace(tmp, path)
    return diff


def write_golden(root: str, seed: int = 7) -> None:
    """Writes tests/data/models/<arch>_w0.0625.onnx and tests/data/golden/<arch>_w0.0625/."""
    os.makedirs(os.path.join(root, "models"), exist_ok=True)
    for i, arch in enumerate(ARCHS):
        torch.manual_seed(seed + i)
        model = build(arch, GOLDEN_WIDTH)
        randomize_batchnorm(model, seed + i)
        name = f"{arch}_w{GOLDEN_WIDTH}"
        path = os.path.join(root, "models", name + ".onnx")
        meta = metadata(arch, GOLDEN_WIDTH, description=(
            f"untrained {arch} at width {GOLDEN_WIDTH}, random weights (seed {seed + i}); "
            "for parity tests only"))
        diff = export(model, path, meta)
        xs = example_inputs(*GOLDEN_SIZE, seed=seed + 100 + i)
        out = run_ort(path, xs)
        gdir = os.path.join(root, "golden", name)
        os.makedirs(gdir, exist_ok=True)
        for n, x in zip(INPUTS, xs):
            np.save(os.path.join(gdir, n + ".npy"), x.numpy().astype("<f4"))
        np.save(os.path.join(gdir, "hsv.npy"), out.astype("<f4"))
        print(f"{name}: onnxruntime vs PyTorch {diff:.2e}, RF {meta['temc.receptive_field']} px")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--arch", choices=ARCHS)
    ap.add_argument("--width", type=float, default=1.0)
    ap.add_argument("--out")
    ap.add_argument("--variant", choices=("plain", "fused"), default="plain")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--golden", metavar="DIR", help="write test models and goldens under DIR")
    a = ap.parse_args()
    torch.set_num_threads(2)
    if a.golden:
        write_golden(a.golden)
        return
    if not (a.arch and a.out):
        ap.error("--arch and --out are required (or --golden DIR)")
    torch.manual_seed(a.seed)
    model = build(a.arch, a.width)
    randomize_batchnorm(model, a.seed)
    meta = metadata(a.arch, a.width, description=f"untrained {a.arch} at width {a.width} "
                    f"(seed {a.seed}); for benchmarks only")
    diff = export(model, a.out, meta, variant=a.variant)
    print(f"{a.out}: onnxruntime vs PyTorch {diff:.2e}")


if __name__ == "__main__":
    main()
