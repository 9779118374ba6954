"""The --hours a resumed run gets when a session caps what it adds:

    python -m temc_train.budget RUN TARGET_HOURS SESSION_CAP_HOURS

prints min(TARGET, done + CAP), where done is the CPU hours the run's checkpoint holds."""

import os
import sys

import torch


def hours_for(run: str, target: float, cap: float) -> float:
    ck = os.path.join(run, "checkpoint.pt")
    done = 0.0
    if os.path.exists(ck):
        done = torch.load(ck, map_location="cpu", weights_only=False)["state"]["train_s"] / 3600
    return min(target, done + cap)


if __name__ == "__main__":
    print(f"{hours_for(sys.argv[1], float(sys.argv[2]), float(sys.argv[3])):.4f}")
