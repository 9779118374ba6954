"""Denoising time at one size: temc's models beside OIDN 2.5, in one run, alternated.

Issue 36's speed targets are ratios measured in one run (the machine is shared and noisy):
balanced at most 1.20x OIDN high's time at 1920x1080, fast at or below OIDN's. Each round
times every temc model with `temc bench` (a warm-up, then `--repeat 2`, median; all aux
buffers) and OIDN high and fast through pyoidn (HDR, albedo + normal), so every denoiser
sees the same load; the table gives each one's median over the rounds and its ratio to
OIDN high and to OIDN fast. docs/speed.md keeps the latest run and what was tried.

    cd training && python -m temc_train.probes.speed --temc ../target/release/temc \\
        --model ../onnx/temc2-balanced.onnx --model ../onnx/temc2-fast.onnx
"""

import argparse
import os
import statistics

from .report import oidn_timing, temc_bench

OIDN_QUALITIES = ("high", "fast")


def measure(temc, models, size, threads, rounds):
    """{denoiser: [seconds per round]}, the denoisers timed in turn within each round."""
    w, h = (int(v) for v in size.split("x"))
    benches = {os.path.basename(m): temc_bench(temc, m, size) for m in models}
    times = {name: [] for name in [*benches, *(f"OIDN {q}" for q in OIDN_QUALITIES)]}
    for _ in range(rounds):
        for name, bench in benches.items():
            times[name].append(bench(threads))
        for q in OIDN_QUALITIES:
            times[f"OIDN {q}"].append(oidn_timing((w, h), threads, q))
    return times


def table(times, size, threads):
    med = {name: statistics.median(t) for name, t in times.items()}
    lines = [f"Denoising time at {size}, {threads} thread(s), median of {len(next(iter(times.values())))} "
             "alternated rounds:", "",
             "| denoiser | seconds | / OIDN high | / OIDN fast |", "|---|---:|---:|---:|"]
    for name, s in med.items():
        lines.append(f"| {name} | {s:.3f} | {s / med['OIDN high']:.2f}x | {s / med['OIDN fast']:.2f}x |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--temc", required=True, help="the temc binary")
    ap.add_argument("--model", action="append", required=True, help="a temc ONNX model (repeatable)")
    ap.add_argument("--size", default="1920x1080", help='"WxH"')
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    print(table(measure(a.temc, a.model, a.size, a.threads, a.rounds), a.size, a.threads))


if __name__ == "__main__":
    main()
