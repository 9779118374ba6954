"""CPU time of one training step of a recipe, on random crops: what a change to the
loss, the reconstruction or the network costs the trainer, without data or a run.

    cd training && python -m temc_train.probes.train_step --steps 40 -- --arch temc2 \\
        --width 0.125 --levels 3 --guide 1 --fixed-range 1 --range-opening aux --range-noise 6

Everything after `--` is the trainer's own flags (drivers/train.py; --data and --run-dir
are filled in, unused). One thread, as the CPU trainer runs; the crops are uniform noise
of the trainer's batch and crop size (no step's cost depends on the pixels' values).
Prints the CPU milliseconds per step (forward, loss, backward, Adam) and of the training
loss alone (forward and backward), each the median of `--rounds` rounds. To time two
versions of the code against each other, copy this file into the other checkout and run
both in turn, or under `farm-bench --vs` (docs/reconstruction.md).
"""

import argparse
import statistics
import sys
import time

import torch

from temc_train.drivers import train


def recipe(flags):
    """The trainer's parsed flags for `flags`."""
    return train.arg_parser().parse_args(["--data", "unused", "--run-dir", "unused", *flags])


def random_batch(a, seed=0):
    """The six tensors of a training batch (chroma, luma, aux, noisy, albedo, reference)."""
    g = torch.Generator().manual_seed(seed)
    n, c = a.batch, a.crop
    return [torch.rand(n, k, c, c, generator=g) * scale
            for k, scale in ((2, 1), (1, 1), (7, 1), (3, 2), (3, 1), (3, 2))]


def per_call_ms(fn, calls):
    start = time.process_time()
    for _ in range(calls):
        fn()
    return 1000 * (time.process_time() - start) / calls


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    cut = argv.index("--") if "--" in argv else len(argv)
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=20, help="steps per round")
    ap.add_argument("--rounds", type=int, default=3)
    own = ap.parse_args(argv[:cut])
    a = recipe(argv[cut + 1:])
    torch.set_num_threads(1)
    torch.manual_seed(a.seed)
    rs = train.recon_settings(a)
    model = train.build(a.arch, a.width, a.levels, a.kernel, a.split, bool(a.guide))
    opt = torch.optim.Adam(model.parameters(), lr=a.lr)
    xs = random_batch(a)
    terms = (a.alpha, a.rel_weight, a.mean_weight, a.dark_weight, a.worst_weight,
             a.chroma_weight, a.worst_axis)

    def step():
        loss = train.training_loss(train.denoise(model, xs, rs), xs[5], *terms)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    out = train.denoise(model, xs, rs).detach().requires_grad_()
    loss_only = lambda: train.training_loss(out, xs[5], *terms).backward()  # noqa: E731
    for _ in range(3):
        step()  # warm-up: allocator and kernels' first calls
    steps, losses = [], []
    for _ in range(own.rounds):
        steps.append(per_call_ms(step, own.steps))
        losses.append(per_call_ms(loss_only, own.steps))
    print(f"step {statistics.median(steps):.1f} ms CPU, of which the loss (forward and backward) "
          f"{statistics.median(losses):.1f} ms; rounds: " + ", ".join(f"{v:.0f}" for v in steps))


if __name__ == "__main__":
    main()
