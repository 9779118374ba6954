"""The one reader and writer of a run's files: `Checkpoint`.

Three forms are on disk, all `torch.save` of a dict (or of a bare state_dict):

- the training checkpoint RUN/checkpoint.pt (drivers/train.py writes it; it resumes a run
  and ships): {"model", "opt", "state", "arch", "width", "recon", "dataset"};
- the final model RUN/model.pt: {"model", "arch", "width", "recon", "dataset",
  "train_steps", "train_seconds", "gpu_seconds", "params"} (and "test_relmse" where a
  caller adds it);
- a bare state_dict (then arch and width come from the caller).

Reading upgrades older runs in memory, never on disk: a checkpoint from before the
reconstruction settings, guides or the fixed range term gets RECON_DEFAULTS for what it
lacks (models.checkpoint_recon), one from before GPU training gets `gpu_seconds` 0 in its
state, one from before runs named their data set has `dataset` None, and one from before
the recipe was stored reads it as OLD_HPARAMS (`recipe`). Writing puts the current form
back, so a resumed old run is upgraded on its next save. Files are read with
`weights_only=True` (tensors and plain Python values only) onto the CPU.
"""

import os
from dataclasses import dataclass, field, replace

import torch

from .models import RECON_DEFAULTS, build, checkpoint_recon

# A training checkpoint drops Adam's moments when it would pass this (issue 15: a run is
# committed; Adam then re-warms on resume).
CHECKPOINT_LIMIT = 20 * 2**20

# The recipe of runs from before train.py stored it in the checkpoint (scripts/train-all).
OLD_HPARAMS = {"lr": 5e-4, "batch": 4, "crop": 128, "threads": 1, "alpha": 0.84,
               "rel_weight": 0.0, "mean_weight": 0.0, "dark_weight": 0.0, "worst_weight": 0.0,
               "target_spp": 0, "loss": "mix"}

# Top-level keys with a field of their own; any other key of a file is kept in `summary`.
_FIELDS = ("model", "opt", "state", "arch", "width", "recon", "dataset")
_INFO = ("dataset", "train_steps", "test_relmse")


def save_atomic(obj, path: str) -> None:
    """torch.save through a temporary file, so a reader never sees half a file."""
    tmp = path + f".tmp-{os.getpid()}"
    torch.save(obj, tmp)
    os.replace(tmp, path)


@dataclass
class Checkpoint:
    """A run's weights and what it knows about them; see the module doc for the forms.

    `state` is None for a final model and a bare state_dict, `opt` None where the moments
    were dropped (or never saved), `arch` and `width` None for a bare state_dict; `recon` is
    always complete. `summary` holds the final model's fields ("train_steps", ...)."""

    model: dict
    arch: str = None
    width: float = None
    recon: dict = field(default_factory=lambda: dict(RECON_DEFAULTS))
    dataset: str = None
    opt: dict = None
    state: dict = None
    summary: dict = field(default_factory=dict)
    bare: bool = False

    # -- reading -----------------------------------------------------------------------

    @classmethod
    def read(cls, path: str) -> "Checkpoint":
        return cls.from_dict(torch.load(path, map_location="cpu", weights_only=True))

    @classmethod
    def from_dict(cls, raw: dict) -> "Checkpoint":
        """A checkpoint from what torch.load gave, upgraded (the nested dicts are shared,
        not copied). A Checkpoint is returned as it is."""
        if isinstance(raw, cls):
            return raw
        if not ("model" in raw and isinstance(raw["model"], dict)):
            return cls(model=raw, bare=True)
        state = raw.get("state")
        if state is not None:
            state.setdefault("gpu_seconds", 0.0)  # runs from before CUDA training
        return cls(model=raw["model"], arch=raw.get("arch"), width=raw.get("width"),
                   recon=checkpoint_recon(raw), dataset=raw.get("dataset"), opt=raw.get("opt"),
                   state=state, summary={k: v for k, v in raw.items() if k not in _FIELDS})

    @property
    def training(self) -> bool:
        """Whether this is a training checkpoint (it holds the run's state and resumes)."""
        return self.state is not None

    @property
    def steps(self):
        """Training steps taken: the state's for a training checkpoint, else the summary's."""
        return self.state["step"] if self.training else self.summary.get("train_steps")

    def recipe(self) -> dict:
        """The training recipe (hparams) of a training checkpoint, OLD_HPARAMS where the run
        predates storing it."""
        return {**OLD_HPARAMS, **(self.state or {}).get("hparams", {})}

    def info(self) -> dict:
        """The optional facts export metadata reads: "dataset", "train_steps" and
        "test_relmse", those the file has (a training checkpoint's steps from its state)."""
        out = {k: v for k, v in (("dataset", self.dataset), *self.summary.items())
               if k in _INFO and v is not None}
        if self.training:
            out.setdefault("train_steps", self.state["step"])
        return out

    def build(self, arch=None, width=None):
        """(model, arch, width): the network, built as the checkpoint says (`arch`/`width`
        are needed for a bare state_dict and must agree where the checkpoint has them), with
        the weights loaded strictly and the reconstruction settings attached."""
        for key, given in (("arch", arch), ("width", width)):
            held = getattr(self, key)
            if given is not None and held is not None and held != given:
                raise ValueError(f"checkpoint has {key} {held!r}, not {given!r}")
        arch = self.arch if self.arch is not None else arch
        width = self.width if self.width is not None else width
        if arch is None or width is None:
            raise ValueError("a bare state_dict needs --arch and --width")
        r = self.recon
        model = build(arch, float(width), r["levels"], r["kernel"], r["split"], r["guide"])
        model.load_state_dict(self.model)
        model.demodulate, model.eps = r["demodulate"], r["eps"]
        model.fixed_range = r["fixed_range"]
        model.upsample = r["upsample"]
        model.range_opening = r["range_opening"]
        model.coarse_clamp = r["coarse_clamp"]
        model.range_noise = r["range_noise"]
        model.coarse_gain, model.coarse_radius = r["coarse_gain"], r["coarse_radius"]
        model.coarse_sparse = r["coarse_sparse"]
        return model, arch, float(width)

    def averaged(self, *others: "Checkpoint") -> "Checkpoint":
        """This checkpoint with its weights the mean of its own and every one of `others`
        (weight averaging of points of one run, Izmailov et al. 2018); its state, steps and
        log stay this one's, Adam's moments are dropped (they belong to no mean). All must
        be the same network with the same reconstruction."""
        if not others:
            raise ValueError("nothing to average with")
        for other in others:
            for key in ("arch", "width", "recon"):
                if getattr(self, key) != getattr(other, key):
                    raise ValueError(f"checkpoints differ in {key}: {getattr(self, key)!r} "
                                     f"against {getattr(other, key)!r}")
            if self.model.keys() != other.model.keys():
                raise ValueError("checkpoints hold different tensors")
        every = (self, *others)
        mean = {k: (sum(c.model[k].double() for c in every) / len(every)).to(v.dtype)
                if torch.is_floating_point(v) else v for k, v in self.model.items()}
        return replace(self, model=mean).without_moments("weights averaged")

    def without_moments(self, why: str) -> "Checkpoint":
        """This checkpoint without Adam's moments, the state saying why (`opt_dropped`): half
        a fast checkpoint's bytes, and a resume starts the moments afresh."""
        state = None if self.state is None else {**self.state, "opt_dropped": why}
        return replace(self, opt=None, state=state)

    def with_branch_time(self, start: "Checkpoint", *branches: "Checkpoint") -> "Checkpoint":
        """This (averaged) checkpoint with the training time of every branch that `start`
        grew into (this one's and each of `branches`): start's CPU and GPU seconds plus each
        branch's own, so a mean of branches' ends counts all the compute behind it."""
        state = dict(self.state)
        for key in ("train_s", "gpu_seconds"):
            base = start.state[key]
            grown = [c.state[key] - base for c in (self, *branches)]
            if min(grown) < 0:
                raise ValueError(f"a branch has less {key} than its start")
            state[key] = base + sum(grown)
        return replace(self, state=state)

    # -- writing -----------------------------------------------------------------------

    def to_dict(self) -> dict:
        """The on-disk dict of the current form."""
        if self.bare:
            return self.model
        if self.training:
            return {"model": self.model, "opt": self.opt, "state": self.state, "arch": self.arch,
                    "width": self.width, "recon": self.recon, "dataset": self.dataset}
        return {"model": self.model, "arch": self.arch, "width": self.width, "recon": self.recon,
                "dataset": self.dataset, **self.summary}

    def write(self, path: str, limit: int = CHECKPOINT_LIMIT) -> None:
        """Saves atomically. A training checkpoint refuses non-finite weights (the last one
        on disk is kept) and is saved again without Adam's moments when over `limit`, its
        state saying why (`opt_dropped`: a resume starts the moments afresh)."""
        d = self.to_dict()
        if self.training:
            if not all(torch.isfinite(v).all() for v in self.model.values() if v.is_floating_point()):
                raise SystemExit(f"{path}: non-finite weights; the last checkpoint is kept")
        save_atomic(d, path)
        if self.training and os.path.getsize(path) > limit:
            save_atomic(dict(d, opt=None, state=dict(d["state"], opt_dropped=f"over {limit} bytes")),
                        path)


def load_checkpoint(path: str, arch=None, width=None):
    """A model from a checkpoint file (any form, see Checkpoint). Returns
    (model, arch, width, info), info holding the optional facts found (Checkpoint.info)."""
    ck = Checkpoint.read(path)
    try:
        model, arch, width = ck.build(arch, width)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    return model, arch, width, ck.info()
