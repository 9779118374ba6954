"""Training across processes: one per GPU, on one machine or several, under `torchrun`
(DistributedDataParallel). Without torchrun's environment everything here is a no-op and
training runs in one process as before.

    torchrun --standalone --nproc-per-node 8 -m temc_train.drivers.train --sampler device ...
    torchrun --nnodes 2 --node-rank R --master-addr HOST --nproc-per-node 8 -m temc_train.drivers.train ...

Every process draws its own batches (its own random stream), so the global batch is
`--batch` times the number of processes; rank 0 alone validates, logs and writes the
checkpoint, which holds the plain model's weights and so resumes on any number of
processes, GPUs or none. NCCL joins CUDA processes, gloo CPU ones (the CI test runs two
gloo processes on the CPU).
"""

import os

import torch
import torch.distributed as dist


class Group:
    """This process's place: `rank` of `world`, its `local` rank on its machine."""

    def __init__(self):
        self.world = int(os.environ.get("WORLD_SIZE", "1"))
        self.rank = int(os.environ.get("RANK", "0"))
        self.local = int(os.environ.get("LOCAL_RANK", "0"))

    @property
    def active(self) -> bool:
        return self.world > 1

    @property
    def leader(self) -> bool:
        return self.rank == 0

    def start(self, device: torch.device) -> torch.device:
        """Joins the process group; returns this process's device (its own GPU)."""
        if not self.active:
            return device
        if device.type == "cuda":
            device = torch.device("cuda", self.local)
            torch.cuda.set_device(device)
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
        return device

    def wrap(self, model: torch.nn.Module, device: torch.device) -> torch.nn.Module:
        if not self.active:
            return model
        ids = [device.index] if device.type == "cuda" else None
        return torch.nn.parallel.DistributedDataParallel(model, device_ids=ids)

    def any(self, flag: bool, device: torch.device) -> bool:
        """Whether `flag` holds on any process: every process stops at the same step."""
        if not self.active:
            return flag
        t = torch.tensor([1.0 if flag else 0.0], device=device)
        dist.all_reduce(t, op=dist.ReduceOp.MAX)
        return bool(t.item() > 0)

    def barrier(self) -> None:
        if self.active:
            dist.barrier()

    def stop(self) -> None:
        if self.active and dist.is_initialized():
            dist.destroy_process_group()


def unwrap(model: torch.nn.Module) -> torch.nn.Module:
    """The plain model inside a DistributedDataParallel (what checkpoints hold)."""
    return model.module if isinstance(model, torch.nn.parallel.DistributedDataParallel) else model
