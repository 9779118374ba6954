"""The --hours a resumed run gets when a session caps what it adds:

    python -m temc_train.drivers.budget RUN TARGET_HOURS SESSION_CAP_HOURS

prints min(TARGET, done + CAP), where done is the CPU hours the run's checkpoint holds."""

import argparse
import os

from ..checkpoint import Checkpoint


def hours_for(run: str, target: float, cap: float) -> float:
    ck = os.path.join(run, "checkpoint.pt")
    done = 0.0
    if os.path.exists(ck):
        done = Checkpoint.read(ck).state["train_s"] / 3600
    return min(target, done + cap)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run")
    ap.add_argument("target_hours", type=float)
    ap.add_argument("session_cap_hours", type=float)
    a = ap.parse_args(argv)
    print(f"{hours_for(a.run, a.target_hours, a.session_cap_hours):.4f}")


if __name__ == "__main__":
    main()
