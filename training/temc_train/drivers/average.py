"""Averages checkpoints of one run into another (Checkpoint.averaged): the weights' mean,
the first checkpoint's state and steps, no Adam moments. How high's shipped weights
were made on 2026-12-05 (docs/reconstruction.md, "A second cycle, averaged"):

    python -m temc_train.drivers.average END.pt START.pt runs/temc2-w0.125-l3/checkpoint.pt

END first: the result carries its steps, and the run's log continues from them. More than
two average alike (snapshots along one cycle: `END.pt MID.pt START.pt OUT.pt`).

`--branches`: the checkpoints before the last are ends of separate runs from the last one,
their common start (a model soup, Wortsman et al. 2022). The result's CPU and GPU seconds
are then the start's plus every branch's own, not the first end's alone:

    python -m temc_train.drivers.average --branches END1.pt END2.pt START.pt OUT.pt

One checkpoint alone is written without its Adam moments: how a run's end ships within the
tree budget (tests/tree_size.rs) when it is not averaged with anything:

    python -m temc_train.drivers.average END.pt runs/temc2-w0.0625-single/checkpoint.pt
"""

import argparse

from ..checkpoint import Checkpoint


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("first", help="checkpoint whose state, steps and dataset the result keeps")
    ap.add_argument("others", nargs="*", metavar="other",
                    help="checkpoints of the same network to average with (none: the first "
                         "without Adam's moments)")
    ap.add_argument("out", help="where to write the averaged checkpoint")
    ap.add_argument("--branches", action="store_true",
                    help="the others but the last are ends of other runs from the last one; "
                         "the result's training time sums every branch's")
    a = ap.parse_args(argv)
    others = [Checkpoint.read(p) for p in a.others]
    if not others:
        if a.branches:
            ap.error("--branches needs the branches' start")
        Checkpoint.read(a.first).without_moments("left out for the tree budget").write(a.out)
        print(f"wrote {a.out}: {a.first} without Adam's moments")
        return
    mean = Checkpoint.read(a.first).averaged(*others)
    if a.branches:
        mean = mean.with_branch_time(others[-1], *others[:-1])
    mean.write(a.out)
    print(f"wrote {a.out}: the mean of {a.first} and {', '.join(a.others)}")


if __name__ == "__main__":
    main()
