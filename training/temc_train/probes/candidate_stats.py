"""A candidate against the shipped file, scene by scene, from `scripts/candidate-report`'s
measurements: per family and spp, the geometric mean of candidate / shipped RelMSE with its
standard error over the scenes, and the worst scene. The ship rule compares geometric
means cell by cell; this says which of those differences the scenes can tell apart from
noise, and catches one scene that breaks (docs/reconstruction.md, "Which differences the
families can see").

    python -m temc_train.probes.candidate_stats ../bench-out/candidate/NAME \\
        [../bench-out/candidate/NAME-test ...]

Reads OUT/img-cycles/measurements.csv and OUT/img-test/measurements.csv where present.
"""

import argparse
import collections
import csv
import math
import os
import statistics

# The test split's kinds by scene-name prefix, and the Cycles family (every scene).
FAMILIES = {"cycles": ("img-cycles", ""), "held-out": ("img-test", "holdout-"),
            "hand-written": ("img-test", "named-"), "generated": ("img-test", "scene-")}
SPPS = ("1", "4", "16", "64")


def read(path: str) -> dict:
    """{(spp, denoiser): {scene: RelMSE}} of one measurements.csv."""
    by = collections.defaultdict(dict)
    with open(path) as f:
        for r in csv.DictReader(f):
            by[(r["spp"], r["denoiser"])][r["scene"]] = float(r["RelMSE"])
    return by


def labels(by: dict) -> tuple:
    """The candidate's and the shipped file's denoiser labels (candidate-report names
    them after the files)."""
    names = {d for _, d in by}
    pick = [[d for d in names if tag in d] for tag in ("(candidate-", "(shipped-")]
    if any(len(p) != 1 for p in pick):
        raise ValueError(f"expected one candidate and one shipped denoiser, got {sorted(names)}")
    return pick[0][0], pick[1][0]


def paired(cand: dict, ship: dict) -> tuple:
    """(scenes, geometric-mean ratio, its standard error as a factor - 1, worst ratio, worst
    scene) over the scenes both hold; the error is 0 for one scene."""
    scenes = sorted(set(cand) & set(ship))
    logs = [math.log(cand[s] / ship[s]) for s in scenes]
    se = statistics.stdev(logs) / math.sqrt(len(logs)) if len(logs) > 1 else 0.0
    worst, scene = max(zip(logs, scenes))
    return len(scenes), math.exp(statistics.fmean(logs)), math.expm1(se), math.exp(worst), scene


def rows(report_dirs: list) -> list:
    """[(family, spp, scenes, ratio, se, worst ratio, worst scene)] over the reports; each
    report kind (img-cycles, img-test) is read from the first folder that has it, once."""
    tables = {}
    for sub in {sub for sub, _ in FAMILIES.values()}:
        paths = [os.path.join(d, sub, "measurements.csv") for d in report_dirs]
        found = next((p for p in paths if os.path.exists(p)), None)
        if found:
            by = read(found)
            tables[sub] = (by, *labels(by))
    out = []
    for family, (sub, prefix) in FAMILIES.items():
        if sub not in tables:
            continue
        by, cand, ship = tables[sub]
        for spp in SPPS:
            c = {k: v for k, v in by.get((spp, cand), {}).items() if k.startswith(prefix)}
            s = {k: v for k, v in by.get((spp, ship), {}).items() if k.startswith(prefix)}
            if c and s:
                out.append((family, spp, *paired(c, s)))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("reports", nargs="+", help="candidate-report output folders")
    a = ap.parse_args(argv)
    print("| family | spp | scenes | candidate / shipped RelMSE | standard error | worst scene |")
    print("|---|---:|---:|---:|---:|---|")
    for fam, spp, n, ratio, se, worst, scene in rows(a.reports):
        print(f"| {fam} | {spp} | {n} | {ratio:.4f} | {100 * se:.2f} % | {worst:.3g} ({scene}) |")


if __name__ == "__main__":
    main()
