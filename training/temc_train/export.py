"""Export temc models to ONNX with their metadata, checked against onnxruntime.

    python -m temc_train.export --arch temc2 --width 0.125 --out m.onnx [--seed S] [--variant fused]
    python -m temc_train.export --checkpoint run.pt --out m.onnx [--dataset D --train-steps N --test-relmse X]
    python -m temc_train.export --golden ../tests/data

The first form writes one model with random weights (benchmarks use this), the second a
trained one (see load_checkpoint). The third writes the untrained test models of every
architecture and their golden input/output tensors for the Rust parity tests
(docs/contracts.md §3). The graph's outputs are the filter logits `filters0` ..
`filters{L-1}` (docs/reconstruction.md); the reconstruction itself runs in the core."""

import argparse
import os
import warnings

import numpy as np
import onnx
import torch
from torch import nn

from . import color, fuse, receptive
from .models import ALIGNMENT, ARCHS, AUX, CHROMA, LUMA, RECON_DEFAULTS, build, checkpoint_recon

OPSET = 17
INPUTS = ("chroma", "luma", "aux")
CHANNELS = (CHROMA, LUMA, AUX)
GOLDEN_WIDTH = 0.0625
GOLDEN_SIZE = (64, 96)
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
            "fixed_range": bool(getattr(model, "fixed_range", d["fixed_range"]))}


def metadata(arch: str, width: float, recon: dict, dataset: str = "none", steps: int = 0,
             test_relmse=None, description: str = "", tile_overlap=None) -> dict:
    """The contract's metadata_props (docs/contracts.md §2), all values strings.
    `tile_overlap` is the measured one (receptive.effective_overlap) for trained models; by
    default the theoretical bound (network receptive field plus reconstruction reach)."""
    if tile_overlap is None:
        tile_overlap = receptive.tile_overlap(arch, recon["levels"], recon["kernel"])
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
        "temc.chroma_encoding": "hs",
        "temc.aux_layout": "albedo:3,normal:3,depth:1",
        "temc.pq_nits_per_unit": f"{color.NITS_PER_UNIT:g}",
        "temc.dataset": dataset,
        "temc.train_steps": str(int(steps)),
        "temc.test_relmse": "none" if test_relmse is None else repr(float(test_relmse)),
        "temc.description": description,
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


def write_golden(root: str, seed: int = 7) -> None:
    """Writes tests/data/models/<arch>_w0.0625.onnx and tests/data/golden/<arch>_w0.0625/."""
    os.makedirs(os.path.join(root, "models"), exist_ok=True)
    for i, arch in enumerate(ARCHS):
        torch.manual_seed(seed + i)
        model = build(arch, GOLDEN_WIDTH)
        randomize_untrained(model, seed + i)
        name = f"{arch}_w{GOLDEN_WIDTH}"
        path = os.path.join(root, "models", name + ".onnx")
        meta = metadata(arch, GOLDEN_WIDTH, recon_of(model), description=(
            f"untrained {arch} at width {GOLDEN_WIDTH}, random weights (seed {seed + i}); "
            "for parity tests only"))
        diff = export(model, path, meta)
        xs = example_inputs(*GOLDEN_SIZE, seed=seed + 100 + i)
        out = run_ort(path, xs)
        gdir = os.path.join(root, "golden", name)
        os.makedirs(gdir, exist_ok=True)
        for n, x in zip(INPUTS, xs):
            np.save(os.path.join(gdir, n + ".npy"), x.numpy().astype("<f4"))
        for name_l, o in zip(output_names(model.levels), out):
            np.save(os.path.join(gdir, name_l + ".npy"), o.astype("<f4"))
        print(f"{name}: onnxruntime vs PyTorch {diff:.2e}, RF {meta['temc.receptive_field']} px")


def load_checkpoint(path: str, arch=None, width=None):
    """A model from a checkpoint: torch.save of either a bare state_dict (then arch and
    width must be given) or a dict {"model": state_dict, "arch", "width", and optionally
    "dataset", "train_steps", "test_relmse"}. Returns (model, arch, width, info) where info
    holds the optional fields found."""
    ckpt = torch.load(path, map_location="cpu", weights_only=True)
    if "model" in ckpt and isinstance(ckpt["model"], dict):
        state = ckpt["model"]
        for key, given in (("arch", arch), ("width", width)):
            if given is not None and key in ckpt and ckpt[key] != given:
                raise ValueError(f"{path}: checkpoint has {key} {ckpt[key]!r}, not {given!r}")
        arch = ckpt.get("arch", arch)
        width = ckpt.get("width", width)
        info = {k: ckpt[k] for k in ("dataset", "train_steps", "test_relmse") if k in ckpt}
        if "state" in ckpt:  # a training checkpoint (train.py): steps from its state
            info.setdefault("train_steps", ckpt["state"]["step"])
        recon = checkpoint_recon(ckpt)
    else:
        state, info, recon = ckpt, {}, dict(RECON_DEFAULTS)
    if arch is None or width is None:
        raise ValueError(f"{path}: a bare state_dict needs --arch and --width")
    model = build(arch, float(width), recon["levels"], recon["kernel"], recon["split"],
                  recon["guide"])
    model.load_state_dict(state)
    model.demodulate, model.eps = recon["demodulate"], recon["eps"]
    model.fixed_range = recon["fixed_range"]
    return model, arch, float(width), info


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--arch", choices=ARCHS)
    ap.add_argument("--width", type=float, help="width multiplier (default 1.0, or the checkpoint's)")
    ap.add_argument("--out")
    ap.add_argument("--checkpoint", help="trained weights (see load_checkpoint); random if absent")
    ap.add_argument("--seed", type=int, default=0, help="seed of the random weights")
    ap.add_argument("--variant", choices=("plain", "fused"), default="plain")
    ap.add_argument("--dataset", help="temc.dataset (default: the checkpoint's, else none)")
    ap.add_argument("--train-steps", type=int, help="temc.train_steps")
    ap.add_argument("--test-relmse", type=float, help="temc.test_relmse")
    ap.add_argument("--description", help="temc.description")
    ap.add_argument("--golden", metavar="DIR", help="write test models and goldens under DIR")
    a = ap.parse_args()
    torch.set_num_threads(2)
    if a.golden:
        write_golden(a.golden)
        return
    if not a.out or not (a.arch or a.checkpoint):
        ap.error("--out and --arch (or --checkpoint) are required, or --golden DIR")
    if a.checkpoint:
        model, arch, width, info = load_checkpoint(a.checkpoint, a.arch, a.width)
        what = f"{arch} at width {width} from {os.path.basename(a.checkpoint)}"
    else:
        arch, width, info = a.arch, 1.0 if a.width is None else a.width, {}
        torch.manual_seed(a.seed)
        model = build(arch, width)
        randomize_untrained(model, a.seed)
        what = f"untrained {arch} at width {width} (seed {a.seed}); for benchmarks only"
    overrides = {"dataset": a.dataset, "train_steps": a.train_steps, "test_relmse": a.test_relmse}
    info.update({k: v for k, v in overrides.items() if v is not None})
    recon = recon_of(model)
    # Trained weights carry their measured reach; random ones the theoretical bound.
    overlap = receptive.effective_overlap(model, recon) if a.checkpoint else None
    meta = metadata(arch, width, recon, dataset=info.get("dataset", "none"),
                    steps=info.get("train_steps", 0), test_relmse=info.get("test_relmse"),
                    description=a.description if a.description is not None else what,
                    tile_overlap=overlap)
    diff = export(model, a.out, meta, variant=a.variant)
    print(f"{a.out}: onnxruntime vs PyTorch {diff:.2e}, RF {meta['temc.receptive_field']} px, "
          f"overlap {meta['temc.tile_overlap']} px")


if __name__ == "__main__":
    main()
