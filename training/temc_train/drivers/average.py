"""Averages checkpoints of one run into another (Checkpoint.averaged): the weights' mean,
the first checkpoint's state and steps, no Adam moments. How high's shipped weights
were made on 2026-12-05 (docs/reconstruction.md, "A second cycle, averaged"):

    python -m temc_train.drivers.average END.pt START.pt runs/temc2-w0.125-l3/checkpoint.pt

END first: the result carries its steps, and the run's log continues from them. More than
two average alike (snapshots along one cycle: `END.pt MID.pt START.pt OUT.pt`).
"""

import argparse

from ..checkpoint import Checkpoint


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("first", help="checkpoint whose state, steps and dataset the result keeps")
    ap.add_argument("others", nargs="+", metavar="other",
                    help="checkpoints of the same network to average with")
    ap.add_argument("out", help="where to write the averaged checkpoint")
    a = ap.parse_args(argv)
    Checkpoint.read(a.first).averaged(*map(Checkpoint.read, a.others)).write(a.out)
    print(f"wrote {a.out}: the mean of {a.first} and {', '.join(a.others)}")


if __name__ == "__main__":
    main()
