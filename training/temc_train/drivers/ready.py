"""Whether a data set that is still rendering has enough finished scenes to train on
(data.ready); scripts/train-gpu waits on it:

    python -m temc_train.drivers.ready DIR N_TRAIN N_VAL

exits 0 once DIR has N_TRAIN training and N_VAL validation scenes finished, else 1."""

import argparse

from ..data import ready


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir")
    ap.add_argument("n_train", type=int)
    ap.add_argument("n_val", type=int)
    a = ap.parse_args(argv)
    raise SystemExit(0 if ready(a.dir, a.n_train, a.n_val) else 1)


if __name__ == "__main__":
    main()
