"""Train one architecture on a `temc-render dataset` folder, resumably, on a wall-clock
budget.

    python -m temc_train.drivers.train --data ../data/spectral-v1 --arch temc2 --width 0.125 \\
        --run runs/temc2-w0.125-energy --hours 1.5

The budget counts the CPU seconds (process time) spent in training steps, validation
excluded, so every architecture gets the same compute even when runs share the machine or
other work slows them; with `--threads 1` on an otherwise idle core this equals wall-clock
time. On a CUDA device (`--device cuda`, or `auto` where one is present) process time
means nothing, so there a step counts its wall seconds, kept apart in the checkpoint's
`gpu_seconds` (`train_s` stays CPU seconds); `--hours` then bounds `train_s + gpu_seconds`.
`--minutes` bounds this invocation's wall clock (from start, loading included; the loop
stops after the first step past it, then validates and saves), whichever comes first.
`--shard FILE` trains on a compact shard (`drivers/shard.py`) instead of a data set folder, for a
machine without the renderer. GPU runs (`scripts/train-gpu`, training/README.md) add
`--sampler device` (batches drawn on the device, `device_batches.py`), `--amp bf16`,
`--channels-last 1` and `--schedule onecycle`, and run under torchrun across GPUs and
machines (`distributed.py`). Checkpoints hold CPU tensors, so they
resume and export anywhere. Rerunning the same command resumes from
RUN/checkpoint.pt (model, optimiser, step, clock and random state), saved every
`--save-minutes` and at the end. RUN/log.csv records step, training seconds (what the
budget counts: `train_s + gpu_seconds`), the training and validation loss and the device
the steps ran on, which is what the accuracy report plots as training time against
validation loss. RUN/model.pt is the final checkpoint in the form `export.py --checkpoint`
reads. Both files are written and read as `checkpoint.Checkpoint`, which upgrades older runs.

One invocation is `resume` (the data, the model and optimiser from RUN/checkpoint.pt, the
run's state), then `loop` (each iteration one `step`, validating and saving as it goes),
then the final save in `train`.

Recipe (the paper's where it fits): Adam, random 128x128 crops with flips and rotations,
the L1 + MS-SSIM mix loss (`loss.py`) taken on PQ R'G'B' of the reconstructed output
(`loss.training_loss`), aux dropout (`data.py`). Ours: the network predicts filters that
`reconstruct.py` applies to the noisy linear radiance (`--levels`, `--kernel`, `--split`,
`--demodulate`; docs/reconstruction.md).

The checkpoint is compact enough to commit (issue 15: a run outlives a session): weights
in float32, Adam's moments in bfloat16, and the moments dropped when the file would pass
20 MiB (Adam then re-warms on resume).
"""

import argparse
import contextlib
import csv
import math
import os
import time

import numpy as np
import torch

from .. import data
from ..checkpoint import CHECKPOINT_LIMIT, Checkpoint  # noqa: F401  (CHECKPOINT_LIMIT: re-exported)
from ..loss import ALPHA, WORST_AXES, noise2noise_loss, training_loss
from ..models import ARCHS, KERNEL, LEVELS, SPLITS, FilterHeads, build, checkpoint_recon, count_params  # noqa: F401
from ..reconstruct import RANGE_OPENINGS, UPSAMPLES, options as recon_options, reconstruct
from . import shard
from .distributed import Group


# The reconstruction settings a resumed run may change (recon_settings' keys): the fixed
# range term, the composition's upsampling, the range term's opening, the coarse clamp, its
# gain, radius and rise where samples are sparse, the range term's threshold from local noise.
SWITCHABLE = ("fixed_range", "upsample", "range_opening", "coarse_clamp", "range_noise",
              "coarse_gain", "coarse_radius", "coarse_sparse")


def recon_settings(a) -> dict:
    """The reconstruction a run trains for; stored in its checkpoints and exported."""
    return {"levels": a.levels, "kernel": a.kernel, "split": a.split,
            "demodulate": bool(a.demodulate), "eps": a.eps, "guide": bool(a.guide),
            "fixed_range": bool(a.fixed_range), "upsample": a.upsample,
            "range_opening": a.range_opening, "coarse_clamp": bool(a.coarse_clamp),
            "range_noise": float(a.range_noise), "coarse_gain": float(a.coarse_gain),
            "coarse_radius": int(a.coarse_radius), "coarse_sparse": float(a.coarse_sparse)}


def denoise(model, xs, rs: dict, amp=contextlib.nullcontext()):
    """Network + reconstruction on a batch of make_sample's arrays (as tensors). `amp`
    (an autocast context) covers the network only: the reconstruction stays in float32,
    since it divides and takes powers of radiance that bfloat16's 8 bits would blur."""
    with amp:
        filters = model(*xs[:3])
    return reconstruct(xs[3], xs[4], [f.float() for f in filters], rs["kernel"], rs["demodulate"],
                       rs["eps"], aux=xs[2], **recon_options(rs))


def validate(model, val, alpha, rs, rel=0.0, batch=8, device="cpu") -> float:
    model.eval()
    total, n = 0.0, 0
    with torch.no_grad():
        for i in range(0, len(val[0]), batch):
            xs = [torch.from_numpy(v[i:i + batch]).to(device) for v in val]
            total += float(training_loss(denoise(model, xs, rs), xs[5], alpha, rel)) * len(xs[0])
            n += len(xs[0])
    model.train()
    return total / max(n, 1)


def compact_optimizer_state(opt_state: dict) -> dict:
    """Adam's moments in bfloat16 (float32's range: a squared gradient does not underflow
    as it would in float16)."""
    out = {"param_groups": opt_state["param_groups"], "state": {}}
    for k, v in opt_state["state"].items():
        out["state"][k] = {n: (t.detach().to("cpu", torch.bfloat16) if torch.is_tensor(t) and t.dim() > 0
                               else t.detach().cpu() if torch.is_tensor(t) else t)
                           for n, t in v.items()}
    return out


def restore_optimizer_state(opt, saved: dict) -> None:
    state = {"param_groups": saved["param_groups"], "state": {}}
    for k, v in saved["state"].items():
        state["state"][k] = {n: (t.float() if torch.is_tensor(t) and t.dim() > 0 else t)
                             for n, t in v.items()}
    opt.load_state_dict(state)


def _grow(old: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """`like` with `old` in its first rows (a head conv's old outputs keep their order)."""
    rows = like.clone()
    rows[: old.shape[0]] = old.to(like.dtype)
    return rows


def add_guide(model, ck) -> None:
    """Loads a checkpoint (a Checkpoint, or the dict torch.load gives) trained without guide
    channels into `model` (built with them): every weight is kept and the heads' guide rows
    keep their small random start, so the run goes on where it was (the range term is near
    zero at first). Adam's moments are kept too, zero for the new rows: restarting Adam cost
    a trained model 16 % of its validation loss in ten steps."""
    ck = Checkpoint.from_dict(ck)
    own = model.state_dict()
    for k, v in ck.model.items():
        own[k] = v if own[k].shape == v.shape else _grow(v, own[k])
    model.load_state_dict(own)
    if ck.opt is not None:
        params = [p for p in model.parameters()]
        for i, st in ck.opt["state"].items():
            for n in ("exp_avg", "exp_avg_sq"):
                if n in st and st[n].shape != params[int(i)].shape:
                    st[n] = _grow(st[n], torch.zeros_like(params[int(i)], dtype=st[n].dtype))
    ck.recon = dict(ck.recon, guide=True)


# The finest level's blend logits when coarser levels are added: sigmoid(-4) = 0.018, so the
# grown model starts within 2 % of the old one's output, yet the blend still gets a gradient.
GROWN_BLEND_LOGIT = -4.0


def add_levels(model, ck) -> None:
    """Loads a checkpoint (a Checkpoint, or the dict torch.load gives) with fewer pyramid
    levels into `model` (built with more): every
    weight is kept by name (the decoder already computes the coarser features; only their
    zero-initialised heads are new) and Adam's moments follow their parameters. The finest
    head's blend logits, never used while it was the coarsest level, start at
    GROWN_BLEND_LOGIT, so the run goes on from the old model's output and learns how far to
    take low frequencies from the new, further-reaching levels."""
    ck = Checkpoint.from_dict(ck)
    heads = [m for m in model.modules() if isinstance(m, FilterHeads)]
    if len(heads) != 1 or heads[0].part != "both":
        raise SystemExit(f"growing levels needs one head set predicting both filters ({ck.arch})")
    new_names = [n for n, _ in model.named_parameters()]
    # The old model's parameters in its own order: a state_dict lists them as
    # named_parameters does, with the buffers in between.
    known = set(new_names)
    old_names = [k for k in ck.model if k in known]
    own = model.state_dict()
    own.update(ck.model)
    model.load_state_dict(own)
    set_finest_blend(model, ck.recon["kernel"], GROWN_BLEND_LOGIT)
    if ck.opt is not None:
        index = {name: i for i, name in enumerate(new_names)}
        ck.opt["state"] = {index[old_names[int(i)]]: st for i, st in ck.opt["state"].items()}
        ck.opt["param_groups"][0]["params"] = list(range(len(new_names)))
    ck.recon = dict(ck.recon, levels=model.levels)


def set_finest_blend(model, kernel: int, logit: float) -> None:
    """Sets the biases of the finest level's luma and chroma blend logits (how much of the
    coarser levels' low frequencies it takes: sigmoid of the logit)."""
    heads = [m for m in model.modules() if isinstance(m, FilterHeads)]
    n = kernel * kernel
    with torch.no_grad():
        heads[0].convs[0].bias[2 * n:2 * n + 2] = logit


LR_FLOOR = 0.05


def finite_step(loss, model) -> bool:
    """Whether the loss and every gradient are finite (an optimiser step is safe)."""
    if not torch.isfinite(loss):
        return False
    grads = [p.grad for p in model.parameters() if p.grad is not None]
    return bool(torch.isfinite(torch.stack([g.abs().max() for g in grads])).all()) if grads else True


def learning_rate(a, trained_s: float, cycle=(0.0, 0.0), world: int = 1) -> float:
    """The step's learning rate at `trained_s` of the run's cumulative training time.

    halflife: `--lr`, halved every `--lr-half-life` hours (so the schedule survives
    resumes), down to LR_FLOOR of it; constant without a half-life.
    onecycle (GPU runs): the peak is `--lr` scaled by the square root of the global batch
    over `--lr-batch`, the batch `--lr` was tuned for (Adam's square-root rule). `cycle` is
    (training seconds where the cycle began, its length in seconds): over the first
    `--warmup` of it the rate rises linearly from 1/25 of the peak, then falls along a
    cosine to 1/1000 of it at its end and stays there. Training time, not steps, drives it,
    so a resumed run continues the same curve on any device."""
    if a.schedule == "halflife":
        if not a.lr_half_life:
            return a.lr
        return a.lr * max(LR_FLOOR, 0.5 ** (trained_s / 3600.0 / a.lr_half_life))
    peak = a.lr * ((a.batch * world) / (a.lr_batch or a.batch)) ** 0.5
    start, span = cycle
    t = min(max((trained_s - start) / span, 0.0), 1.0) if span > 0 else 1.0
    if t < a.warmup:
        return peak * (1 / 25 + (1 - 1 / 25) * t / a.warmup)
    fall = (t - a.warmup) / max(1.0 - a.warmup, 1e-9)
    return peak * (1e-3 + (1 - 1e-3) * 0.5 * (1 + math.cos(math.pi * fall)))


def start_cycle(a, state: dict, used: float) -> tuple:
    """The one-cycle schedule's (start, length) in training seconds, kept in the state: a
    cycle begins where a run first trains with it, or anew with `--new-cycle`, and spans
    `--cycle-hours` (default: what is left of `--hours`); resumes continue it."""
    if a.schedule == "onecycle" and (a.new_cycle or "cycle" not in state):
        span = (a.cycle_hours * 3600.0) if a.cycle_hours else max(a.hours * 3600.0 - used, 0.0)
        state["cycle"] = [used, span]
    return tuple(state.get("cycle", (0.0, 0.0)))


def pick_device(name: str) -> torch.device:
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" and not torch.cuda.is_available():
        raise SystemExit("--device cuda: no CUDA device")
    return torch.device(name)


def cpu_state(sd: dict) -> dict:
    return {k: (v.detach().cpu() if torch.is_tensor(v) else v) for k, v in sd.items()}


LOG_COLUMNS = ["step", "train_seconds", "train_loss", "val_loss", "device"]


def open_log(path: str):
    """RUN/log.csv for appending. A log from before the device column gets it (its rows ran
    on the CPU: train.py had no other device then)."""
    if os.path.exists(path):
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
        if rows and rows[0] and "device" not in rows[0]:
            n = len(rows[0])
            tmp = path + f".tmp-{os.getpid()}"
            with open(tmp, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(rows[0] + ["device"])
                w.writerows(r + [""] * (n - len(r)) + ["cpu"] for r in rows[1:] if r)
            os.replace(tmp, path)
    new = not os.path.exists(path) or os.path.getsize(path) == 0
    log = open(path, "a", newline="")
    w = csv.writer(log)
    if new:
        w.writerow(LOG_COLUMNS)
    return log, w


class Batches(torch.utils.data.IterableDataset):
    """Training batches made in DataLoader worker processes (`--workers`), each worker with
    its own random stream (seed, step at start, worker): on a GPU the numpy sampling would
    otherwise be the bottleneck."""

    def __init__(self, scenes, n, crop, seed, target_spp=0):
        super().__init__()
        self.scenes, self.n, self.crop, self.seed = scenes, n, crop, seed
        self.target_spp = target_spp or None

    def __iter__(self):
        info = torch.utils.data.get_worker_info()
        rng = np.random.default_rng(self.seed + [info.id if info else 0])
        while True:
            yield data.batch(self.scenes, rng, self.n, self.crop, target_spp=self.target_spp)


class BatchSource:
    """Where a run's batches come from (`--sampler`): numpy in this process (the random
    stream is checkpointed, so a CPU run resumes exactly), numpy in `--workers` DataLoader
    processes, or `device_batches.DeviceSet` on the training device (GPU runs: the scenes
    live there and a batch is a few tensor operations). Scenes that land while the run
    trains join through `refresh`."""

    def __init__(self, a, scenes, device, rng, seed):
        self.a, self.device, self.rng, self.scenes, self.loader = a, device, rng, scenes, None
        self.reader = None  # data.SceneLoader, made on the first refresh
        if a.sampler == "device":
            if a.target_spp:
                raise SystemExit("--sampler device does not do Noise2Noise targets (--target-spp)")
            from ..device_batches import DeviceSet

            self.set = DeviceSet(device, a.max_input_spp, a.spp_weights)
            self.set.add(scenes)
            self.gen = torch.Generator(device).manual_seed(int(np.random.SeedSequence(seed).generate_state(1)[0]))
        elif a.workers > 0:
            self._start_workers(seed)

    def _start_workers(self, seed):
        dl = torch.utils.data.DataLoader(Batches(self.scenes, self.a.batch, self.a.crop, seed, self.a.target_spp),
                                         batch_size=None, num_workers=self.a.workers,
                                         pin_memory=self.device.type == "cuda", prefetch_factor=4,
                                         persistent_workers=False)
        self.loader = iter(dl)

    def next(self) -> list:
        if self.a.sampler == "device":
            return self.set.batch(self.a.batch, self.a.crop, self.gen)
        arrays = (data.batch(self.scenes, self.rng, self.a.batch, self.a.crop, target_spp=self.a.target_spp or None)
                  if self.loader is None else next(self.loader))
        return [(torch.from_numpy(v) if isinstance(v, np.ndarray) else v).to(self.device, non_blocking=True)
                for v in arrays]

    def refresh(self, seed) -> None:
        """Adds the data set's training scenes finished since the last call; on the device
        sampler they are read in worker processes and join once read (never waiting)."""
        if self.a.sampler == "device":
            if self.reader is None:
                self.reader = data.SceneLoader(self.a.data, "train", [s.name for s in self.scenes])
            new = self.reader.poll()
            if new:
                self.scenes = self.scenes + new
                self.set.add(new)
                print(f"{len(new)} new train scene(s), {len(self.scenes)} in all", flush=True)
            return
        n = len(self.scenes)
        self.scenes = data.refresh_split(self.a.data, "train", self.scenes, self.a.target_spp)
        if len(self.scenes) != n and self.loader is not None:
            self._start_workers(seed)

    def close(self) -> None:
        if self.reader is not None:
            self.reader.close()


def load_data(a):
    """(training scenes, validation scenes, data set name, source) of `--data` or `--shard`."""
    if a.shard:
        train_scenes, val_scenes = shard.load(a.shard)
        return train_scenes, val_scenes, shard.read_manifest(a.shard)["dataset"], a.shard
    return (data.load_split(a.data, "train", a.target_spp), data.load_split(a.data, "val"),
            os.path.basename(os.path.normpath(a.data)), a.data)


def resume_model(a, model, ckpt_path, rs):
    """Loads RUN/checkpoint.pt into `model` when there is one, adding guide channels or
    pyramid levels the command asks for; returns the Checkpoint (None for a new run)."""
    if not os.path.exists(ckpt_path):
        return None
    ck = Checkpoint.read(ckpt_path)
    held_recon = dict(ck.recon)
    upgrade = a.guide and not held_recon["guide"]
    if upgrade:
        held_recon["guide"] = True
    grow = a.levels > held_recon["levels"]
    if grow:
        held_recon["levels"] = a.levels
    for key in SWITCHABLE:
        # Fixed functions of the reconstruction (no weights to learn or load): a run may
        # switch any of them at any step; the checkpoint records where.
        if held_recon[key] != rs[key]:
            held_recon[key] = rs[key]
            ck.recon = dict(ck.recon, **{key: rs[key]})
            ck.state[f"{key}_from_step"] = ck.state["step"]
    held = (ck.arch, ck.width, held_recon)
    if held != (a.arch, a.width, rs):
        raise SystemExit(f"{ckpt_path} holds {held}, not {(a.arch, a.width, rs)}")
    if upgrade:
        add_guide(model, ck)
        ck.state["guide_from_step"] = ck.state["step"]
        print(f"{ckpt_path}: adding the guide channels", flush=True)
    elif grow:
        from_levels = ck.recon["levels"]
        add_levels(model, ck)
        ck.state["levels_from"] = [ck.state["step"], from_levels]
        print(f"{ckpt_path}: growing from {from_levels} to {a.levels} levels", flush=True)
    else:
        model.load_state_dict(ck.model)
    if a.blend_logit is not None and (ck.state.get("blend_reset") or [None, None])[1] != a.blend_logit:
        set_finest_blend(model, ck.recon["kernel"], a.blend_logit)
        ck.state["blend_reset"] = [ck.state["step"], a.blend_logit]
        print(f"{ckpt_path}: the finest level's blend biases set to {a.blend_logit:g}", flush=True)
    return ck


# Loss terms (`--TERM-weight`) a resumed run may add; the state keeps the step each joined
# at as TERM_from_step.
LATE_TERMS = ("mean", "dark", "worst", "chroma")


def hparams(a, world: int) -> dict:
    """The recipe, as the model card reads it from the checkpoint."""
    return {"lr": a.lr, "lr_half_life": a.lr_half_life, "batch": a.batch, "crop": a.crop,
            "threads": a.threads, "alpha": a.alpha, "rel_weight": a.rel_weight,
            "mean_weight": a.mean_weight, "dark_weight": a.dark_weight,
            "worst_weight": a.worst_weight, "worst_axis": a.worst_axis,
            "chroma_weight": a.chroma_weight,
            "target_spp": a.target_spp,
            "max_input_spp": a.max_input_spp, "spp_weights": a.spp_weights, "loss": a.loss,
            "sampler": a.sampler, "amp": a.amp, "schedule": a.schedule, "lr_batch": a.lr_batch,
            "warmup": a.warmup, "cycle_hours": a.cycle_hours, "processes": world}


class Session:
    """One invocation of `train`: what `resume` sets up and `step`, `loop` and the final
    save share. `state` is the run's (step, clock, random state, what the card reads);
    `meter` this invocation's throughput."""

    def __init__(self, **kw):
        self.__dict__.update(kw)
        self.batches = self.log = self.w = None
        self.meter = {"crops": 0, "seconds": 0.0}
        self.amp = torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=self.a.amp == "bf16")
        self.layout = torch.channels_last if self.a.channels_last else torch.contiguous_format

    def used(self) -> float:
        """Training seconds so far, what `--hours` bounds: CPU seconds plus GPU seconds."""
        return self.state["train_s"] + self.state["gpu_seconds"]

    def throughput(self) -> dict:
        """This session's throughput: crops over the wall seconds of its steps (validation
        and checkpoints excluded), every process counted; the card reports it."""
        a, m = self.a, self.meter
        return {"crops_per_s": m["crops"] / max(m["seconds"], 1e-9), "device": self.device.type,
                "processes": self.group.world, "batch": a.batch, "amp": a.amp,
                "steps": m["crops"] // (a.batch * self.group.world)}

    def checkpoint(self) -> None:
        """Saves RUN/checkpoint.pt (Checkpoint.write: refused with non-finite weights,
        without Adam's moments past CHECKPOINT_LIMIT)."""
        state = self.state
        state["rng"] = self.rng.bit_generator.state
        # The model card says what the run saw. Sessions on fresh machines train on the
        # part of the set rendered there, so the count kept is the largest set seen at once.
        prior = state.get("train_scenes")
        state["train_scenes"] = max(len(self.batches.scenes), prior if isinstance(prior, int) else 0)
        state["session_scenes"] = len(self.batches.scenes)
        state["hparams"] = hparams(self.a, self.group.world)
        if self.meter["crops"]:
            state["throughput"] = self.throughput()
        Checkpoint(model=cpu_state(self.model.state_dict()),
                   opt=compact_optimizer_state(self.opt.state_dict()), state=state,
                   arch=self.a.arch, width=self.a.width, recon=self.rs,
                   dataset=self.dataset).write(self.ckpt_path)


def resume(a) -> Session:
    """Starts the invocation: the device (and the process group), the data, the model,
    loaded from RUN/checkpoint.pt where there is one (grown as the command asks), Adam with
    its moments, and the run's state and random stream; a new run starts at step 0."""
    start = time.monotonic()
    torch.set_num_threads(a.threads)
    group = Group()
    device = group.start(pick_device(a.device))
    if device.type == "cuda":
        torch.backends.cudnn.benchmark = True
    os.makedirs(a.run, exist_ok=True)
    ckpt_path = os.path.join(a.run, "checkpoint.pt")
    train_scenes, val_scenes, dataset, source = load_data(a)
    if not train_scenes:
        raise SystemExit(f"{source}: no finished training scenes yet")
    val = data.validation_set(val_scenes or train_scenes[:2], a.crop)
    torch.manual_seed(a.seed)
    rs = recon_settings(a)
    model = build(a.arch, a.width, a.levels, a.kernel, a.split, bool(a.guide))
    state = {"step": 0, "train_s": 0.0, "gpu_seconds": 0.0,
             "rng": np.random.default_rng(a.seed).bit_generator.state}
    ck = resume_model(a, model, ckpt_path, rs)
    model.to(device, memory_format=torch.channels_last if a.channels_last else torch.contiguous_format)
    opt = torch.optim.Adam(model.parameters(), lr=a.lr)
    if ck is not None:
        if ck.opt is not None:
            restore_optimizer_state(opt, ck.opt)  # moves the moments to the parameters' device
        state = ck.state  # Checkpoint.read gave an old run its gpu_seconds
        for term in LATE_TERMS:  # the card says when the term joined
            if getattr(a, f"{term}_weight") and not state.get("hparams", {}).get(f"{term}_weight"):
                state[f"{term}_from_step"] = state["step"]
        if group.leader:
            print(f"resuming at step {state['step']}, {state['train_s']:.0f} CPU s + "
                  f"{state['gpu_seconds']:.0f} GPU s trained", flush=True)
        del ck
    net = group.wrap(model, device)
    rng = np.random.default_rng()
    rng.bit_generator.state = state["rng"]
    if group.rank:  # every process its own crops
        rng = np.random.default_rng([a.seed, state["step"], group.rank])
    return Session(a=a, start=start, group=group, device=device, ckpt_path=ckpt_path,
                   train_scenes=train_scenes, source=source, dataset=dataset, val=val, rs=rs,
                   model=model, net=net, opt=opt, state=state, rng=rng)


def step(s: Session) -> float:
    """One optimiser step on the next batch; returns its loss. A non-finite loss or
    gradient skips the update (counted in the state)."""
    a, state = s.a, s.state
    xs = s.batches.next()
    xs[:3] = [x.contiguous(memory_format=s.layout) for x in xs[:3]]
    out = denoise(s.net, xs, s.rs, s.amp)
    loss = (noise2noise_loss(out, xs[5]) if a.loss == "relmse"
            else training_loss(out, xs[5], a.alpha, a.rel_weight, a.mean_weight,
                                  a.dark_weight, a.worst_weight, a.chroma_weight,
                                  a.worst_axis))
    s.opt.zero_grad(set_to_none=True)
    loss.backward()
    if finite_step(loss, s.model):
        s.opt.step()
    else:
        # One NaN gradient would poison every weight and then the checkpoint: the
        # batch is dropped (its time still counts) and the count goes in the card.
        state["skipped_steps"] = state.get("skipped_steps", 0) + 1
        print(f"step {state['step']}: non-finite loss or gradient, skipped "
              f"({state['skipped_steps']} so far)", flush=True)
    return float(loss.detach())  # waits for the device: the step's time is all in


def loop(s: Session) -> None:
    """Steps until the budget (`--hours`), `--max-steps` or `--minutes` is reached, every
    process stopping together; validates (and takes in newly rendered scenes) every
    `--val-minutes` and saves every `--save-minutes`, both at the end too. Opens RUN/log.csv
    (s.log, closed by `train`) and leaves the batch source closed."""
    a, state, group, device = s.a, s.state, s.group, s.device
    cuda = device.type == "cuda"
    if group.leader:
        s.log, s.w = open_log(os.path.join(a.run, "log.csv"))
    budget = a.hours * 3600.0
    wall = float("inf") if a.minutes is None else a.minutes * 60.0
    last_save = last_val = time.monotonic()
    ema = None
    if state["step"] == 0:
        state["first_train_scenes"] = len(s.train_scenes)
        if group.leader:
            s.w.writerow([0, 0.0, "", f"{validate(s.model, s.val, a.alpha, s.rs, a.rel_weight, device=device):.6f}",
                          device.type])
            s.log.flush()
    s.model.train()
    s.batches = BatchSource(a, s.train_scenes, device, s.rng, [a.seed, state["step"], group.rank])
    if group.leader:
        print(f"training on {device.type} x {group.world} ({len(s.train_scenes)} scenes from {s.source}, "
              f"sampler {a.sampler})", flush=True)
    done = s.used() >= budget or state["step"] >= a.max_steps
    cycle = start_cycle(a, state, s.used())
    while not group.any(done, device):
        wall0 = time.monotonic()
        t0 = wall0 if cuda else time.process_time()
        for g in s.opt.param_groups:
            g["lr"] = learning_rate(a, s.used(), cycle, group.world)
        loss = step(s)
        # Device seconds of every process: a budget is compute, however it is split.
        if cuda:
            state["gpu_seconds"] += (time.monotonic() - t0) * group.world
        else:
            state["train_s"] += (time.process_time() - t0) * group.world
        state["step"] += 1
        s.meter["crops"] += a.batch * group.world
        s.meter["seconds"] += time.monotonic() - wall0
        ema = loss if ema is None else 0.98 * ema + 0.02 * loss
        now = time.monotonic()
        done = s.used() >= budget or state["step"] >= a.max_steps or now - s.start >= wall
        if now - last_val >= a.val_minutes * 60 or done:
            if not a.shard:
                s.batches.refresh([a.seed, state["step"], group.rank])
            if group.leader:
                v = validate(s.model, s.val, a.alpha, s.rs, a.rel_weight, device=device)
                s.w.writerow([state["step"], f"{s.used():.1f}", f"{ema:.6f}", f"{v:.6f}", device.type])
                s.log.flush()
                print(f"step {state['step']}  {s.used():.0f}/{budget:.0f} s  "
                      f"train {ema:.4f}  val {v:.4f}  lr {s.opt.param_groups[0]['lr']:.2e}  "
                      f"{s.throughput()['crops_per_s']:.0f} crops/s", flush=True)
            last_val = time.monotonic()
        if group.leader and (now - last_save >= a.save_minutes * 60 or done):
            s.checkpoint()
            last_save = time.monotonic()
    s.batches.close()


def train(a) -> dict:
    """One invocation: `resume`, `loop`, then the final checkpoint, RUN/model.pt and the
    ONNX file (`--export`). Returns model.pt's dict."""
    s = resume(a)
    loop(s)
    st = s.state
    final = Checkpoint(model=cpu_state(s.model.state_dict()), arch=a.arch, width=a.width, recon=s.rs,
                       dataset=s.dataset,
                       summary={"train_steps": st["step"], "train_seconds": st["train_s"],
                                "gpu_seconds": st["gpu_seconds"], "params": count_params(s.model)})
    if s.group.leader:
        s.checkpoint()
        s.log.close()
        final.write(os.path.join(a.run, "model.pt"))
        if a.export:
            export_onnx(s.model, final.to_dict(), a.export)
    s.group.barrier()
    s.group.stop()
    return final.to_dict()


def export_onnx(model, final: dict, path: str) -> None:
    """The run's ONNX file, checked against onnxruntime (export.py)."""
    from ..onnx_export import export, metadata

    meta = metadata(final["arch"], final["width"], final["recon"], final["dataset"], final["train_steps"])
    diff = export(model.cpu().float(), path, meta)
    print(f"exported {path} (onnxruntime vs PyTorch {diff:.1e})", flush=True)


def spp_weights(text: str) -> list:
    """--spp-weights' value: comma-separated numbers (DeviceSet checks them against the
    data set's spp)."""
    try:
        return [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"not comma-separated numbers: {text!r}") from None


def arg_parser() -> argparse.ArgumentParser:
    """train.py's command line (apart from main, so a test can read a script's flags as
    a run would: tests/test_run_recipes.py)."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--data", help="a temc-render dataset folder")
    src.add_argument("--shard", help="a shard file (shard.py) instead of --data")
    ap.add_argument("--arch", choices=ARCHS, required=True)
    ap.add_argument("--width", type=float, required=True)
    ap.add_argument("--levels", type=int, default=LEVELS, help="pyramid levels of the reconstruction")
    ap.add_argument("--kernel", type=int, default=KERNEL, help="taps per side of each level's kernel")
    ap.add_argument("--split", choices=SPLITS, default="both",
                    help="both: separate luma and chroma filters; one: a single filter")
    ap.add_argument("--demodulate", type=int, choices=(0, 1), default=0,
                    help="filter radiance / (albedo + eps) and multiply back")
    ap.add_argument("--eps", type=float, default=0.01, help="demodulation's epsilon")
    ap.add_argument("--guide", type=int, choices=(0, 1), default=0,
                    help="predict a guide per filter whose differences reject taps (the range "
                         "term); a run trained without it gains it on resume")
    ap.add_argument("--fixed-range", type=int, choices=(0, 1), default=0,
                    help="add the fixed range term on opened log luminance, which keeps lamps' "
                         "energy out of their dark neighbours (docs/reconstruction.md); a run "
                         "may switch it at any step")
    ap.add_argument("--range-opening", choices=RANGE_OPENINGS, default="plain",
                    help="what the fixed range term opens: each level's luminance (plain) or "
                         "the full-resolution luminance over each pixel's neighbours on its own "
                         "surface (aux; docs/reconstruction.md, \"Aux-guided opening\"); a run "
                         "may switch it at any step")
    ap.add_argument("--coarse-clamp", type=int, choices=(0, 1), default=0,
                    help="cap each coarse level's correction at --coarse-gain times the finer "
                         "value (docs/reconstruction.md, step 4); a run may switch it at any step")
    ap.add_argument("--coarse-gain", type=float, default=1.0,
                    help="temc.coarse_gain: the coarse clamp's gain; a run may switch it")
    ap.add_argument("--coarse-radius", type=int, default=0,
                    help="temc.coarse_radius: cap against the fine values' (2r+1)^2 mean, not "
                         "the pixel's own (docs/reconstruction.md, \"The coarse cap against a "
                         "local mean\"); a run may switch it")
    ap.add_argument("--coarse-sparse", type=float, default=0.0,
                    help="temc.coarse_sparse: raise the coarse clamp where fewer than this "
                         "share of a window's pixels are lit (docs/reconstruction.md, \"The "
                         "coarse cap where samples are sparse\"); a run may switch it")
    ap.add_argument("--range-noise", type=float, default=0.0,
                    help="the fixed range term's threshold from local noise, K of "
                         "temc.range_noise (0: RANGE_TAU everywhere; docs/reconstruction.md, "
                         "\"Range threshold from local noise\"); a run may switch it at any step")
    ap.add_argument("--blend-logit", type=float, default=None,
                    help="on resume, set the finest level's blend biases to this once (a grown "
                         "run starts them at GROWN_BLEND_LOGIT, where lr-limited steps leave them "
                         "for CPU-hours); recorded in the checkpoint as blend_reset")
    ap.add_argument("--upsample", choices=UPSAMPLES, default="nearest",
                    help="how the level composition upsamples a coarse level's correction "
                         "(docs/reconstruction.md, step 4); a run may switch it on resume")
    ap.add_argument("--run", "--run-dir", dest="run", required=True,
                    help="folder for checkpoints and the log (--run-dir: the same, for torchrun, "
                         "whose own parser takes --run for an abbreviation of its --run-path)")
    ap.add_argument("--hours", type=float, default=1.0,
                    help="cumulative training budget: CPU hours spent in steps, plus wall hours of "
                         "steps on CUDA")
    ap.add_argument("--minutes", type=float, default=None,
                    help="wall-clock limit of this invocation (loading included)")
    ap.add_argument("--device", choices=("auto", "cpu", "cuda"), default="cpu",
                    help="where the steps run (auto: CUDA if present)")
    ap.add_argument("--workers", type=int, default=0,
                    help="DataLoader processes making batches (0: in this process, the "
                         "checkpointed random stream; >0 is for GPUs: their CPU time is not "
                         "counted in the CPU budget)")
    ap.add_argument("--max-steps", type=int, default=10**9)
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--crop", type=int, default=data.CROP)
    ap.add_argument("--lr", type=float, default=1e-4)
    ap.add_argument("--lr-half-life", type=float, default=0.0,
                    help="halve the learning rate every this many hours of cumulative training "
                         "(0: constant)")
    ap.add_argument("--alpha", type=float, default=ALPHA,
                    help="MS-SSIM weight of the mix loss (the paper's 0.84; 0 = L1 only)")
    ap.add_argument("--rel-weight", type=float, default=0.0,
                    help="weight of the relative L1 on linear values added to the mix loss")
    ap.add_argument("--mean-weight", type=float, default=0.0,
                    help="weight of the block-mean energy term (loss.block_mean_error) added to "
                         "the mix loss")
    ap.add_argument("--dark-weight", type=float, default=0.0,
                    help="weight of the block log-ratio energy term (loss.block_log_error), "
                         "which charges darkened dark regions")
    ap.add_argument("--worst-weight", type=float, default=0.0,
                    help="weight of the worst-pixel PQ error (loss.worst_pixel_error: each "
                         "crop's worst 0.2 %% of pixels), which charges kept fireflies")
    ap.add_argument("--worst-axis", choices=WORST_AXES, default="rgb",
                    help="what the worst-pixel term reads: PQ R'G'B' averaged over channels, "
                         "or ICtCp's intensity (loss.worst_intensity_error), which leaves hue alone")
    ap.add_argument("--chroma-weight", type=float, default=0.0,
                    help="weight of the chroma error (loss.chroma_error: Delta E ITP's Ct and Cp "
                         "axes), which holds the colour the worst-pixel term moves")
    ap.add_argument("--max-input-spp", type=int, default=0,
                    help="--sampler device: draw noisy inputs only up to this spp (0: every "
                         "spp; validation still covers every spp). Measured 2026-12-05 (64 "
                         "against 512-spp references): worse on the Cycles family at every spp, "
                         "most at 64 (docs/reconstruction.md, 'More cycles on new scenes')")
    ap.add_argument("--spp-weights", type=spp_weights, default=None,
                    help="--sampler device: the relative share of draws of each noisy spp, in the "
                         "data set's order (e.g. 1,1,1,3,3 for 1,4,16,64,256); default: equal")
    ap.add_argument("--target-spp", type=int, default=0,
                    help="Noise2Noise: train against the reference render's prefix at this spp "
                         "(written by `temc-render dataset --ref-prefix-spp`); validation still "
                         "uses the clean references and the mix loss. 0: the clean references")
    ap.add_argument("--loss", choices=("mix", "relmse"), default=None,
                    help="mix: the paper's L1 + MS-SSIM on PQ (loss.training_loss); relmse: "
                         "loss.noise2noise_loss, unbiased under zero-mean target noise. "
                         "Default: relmse with --target-spp, else mix")
    ap.add_argument("--sampler", choices=("numpy", "device"), default="numpy",
                    help="numpy: data.make_sample's crops (here or in --workers); device: "
                         "device_batches.DeviceSet, the scenes on the training device (GPU runs)")
    ap.add_argument("--amp", choices=("off", "bf16"), default="off",
                    help="bf16: the network under bfloat16 autocast (reconstruction and loss stay float32)")
    ap.add_argument("--channels-last", type=int, choices=(0, 1), default=0,
                    help="the network's weights and inputs in channels-last layout (faster on GPUs)")
    ap.add_argument("--schedule", choices=("halflife", "onecycle"), default="halflife",
                    help="learning-rate schedule (see learning_rate)")
    ap.add_argument("--lr-batch", type=int, default=0,
                    help="onecycle: the global batch --lr was tuned for (0: --batch, no scaling)")
    ap.add_argument("--warmup", type=float, default=0.05,
                    help="onecycle: the share of the cycle spent warming up")
    ap.add_argument("--cycle-hours", type=float, default=0.0,
                    help="onecycle: the cycle's length in training hours (0: what is left of --hours)")
    ap.add_argument("--new-cycle", type=int, choices=(0, 1), default=0,
                    help="onecycle: begin a new cycle here instead of continuing the run's")
    ap.add_argument("--export", help="also write the final model as ONNX here (export.py's checks)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--val-minutes", type=float, default=5.0)
    ap.add_argument("--save-minutes", type=float, default=5.0)
    return ap


def main(argv=None):
    ap = arg_parser()
    a = ap.parse_args(argv)
    a.loss = a.loss or ("relmse" if a.target_spp else "mix")
    if a.max_input_spp and a.sampler != "device":
        ap.error("--max-input-spp needs --sampler device")
    if a.spp_weights and a.sampler != "device":
        ap.error("--spp-weights needs --sampler device")
    f = train(a)
    print(f"done: {f['train_steps']} steps, {f['train_seconds']:.0f} CPU s + "
          f"{f['gpu_seconds']:.0f} GPU s -> {a.run}/model.pt")


if __name__ == "__main__":
    main()
