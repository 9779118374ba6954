"""Export temc models to ONNX with their metadata, checked against onnxruntime.

    python -m temc_train.drivers.export --arch temc2 --width 0.125 --out m.onnx [--seed S] [--variant fused]
    python -m temc_train.drivers.export --checkpoint run.pt --out m.onnx [--dataset D --train-steps N --test-relmse X]
    python -m temc_train.drivers.export --golden ../tests/data

The first form writes one model with random weights (benchmarks use this), the second a
trained one (checkpoint.load_checkpoint). The third writes the untrained test models of every
architecture and their golden input/output tensors for the Rust parity tests
(docs/contracts.md §3). The graph's outputs are the filter logits `filters0` ..
`filters{L-1}` (docs/reconstruction.md); the reconstruction itself runs in the core.

The export itself is the library's (onnx_export.py, checkpoint.py); its names are
re-exported here."""

import argparse
import os

import numpy as np
import torch

from .. import receptive
from ..checkpoint import load_checkpoint  # noqa: F401  (re-exported)
from ..models import ARCHS, build
from ..reconstruct import RANGE_OPENINGS, UPSAMPLES
from ..onnx_export import (CHANNELS, GOLDEN_SIZE, GOLDEN_WIDTH, INPUTS, OPSET, PARITY_TOL,  # noqa: F401
                           example_inputs, export, max_diff, metadata, ort_session, output_names,
                           randomize_untrained, recon_of, run_ort)

# The reconstruction settings an export may set instead of the model's own: (flag, its
# argparse type, what it sets).
RECON_FLAGS = (
    ("--upsample", {"choices": UPSAMPLES}, "temc.upsample: the level composition the core runs"),
    ("--range-opening", {"choices": RANGE_OPENINGS},
     "temc.range_opening: what the fixed range term opens"),
    ("--coarse-clamp", {"type": int, "choices": (0, 1)},
     "temc.coarse_clamp: cap each coarse correction"),
    ("--range-noise", {"type": float},
     "temc.range_noise: the fixed range term's threshold from local noise"),
    ("--coarse-gain", {"type": float}, "temc.coarse_gain: the coarse clamp's gain"),
    ("--coarse-radius", {"type": int}, "temc.coarse_radius: the coarse clamp's window radius"),
    ("--coarse-sparse", {"type": float},
     "temc.coarse_sparse: raise the coarse clamp where a level's samples are sparse"),
)


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
    for flag, kind, what in RECON_FLAGS:
        ap.add_argument(flag, **kind, help=f"{what} (default: what the model trained with); "
                        "to measure others without retraining")
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
    dests = (flag[2:].replace("-", "_") for flag, _, _ in RECON_FLAGS)
    chosen = {dest: getattr(a, dest) for dest in dests}
    if chosen["coarse_clamp"] is not None:
        chosen["coarse_clamp"] = bool(chosen["coarse_clamp"])
    recon = dict(recon_of(model), **{k: v for k, v in chosen.items() if v is not None})
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
