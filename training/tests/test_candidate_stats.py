"""probes.candidate_stats on a hand-made report: the paired ratio, its error and the worst scene."""
import csv
import math

import pytest

from temc_train.probes import candidate_stats as cs

CAND, SHIP = "TEMC-2 (candidate-temc2-balanced)", "TEMC-2 (shipped-temc2-balanced)"


def write(path, rows):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scene", "spp", "denoiser", "RelMSE"])
        w.writerows(rows)


def test_paired_ratio_error_and_worst_scene(tmp_path):
    ratios = {"a": 0.9, "b": 1.0, "c": 1.2}
    rows = []
    for scene, r in ratios.items():
        rows += [(scene, "4", SHIP, 0.01), (scene, "4", CAND, 0.01 * r), (scene, "4", "OIDN high", 0.005)]
    write(tmp_path / "img-cycles" / "measurements.csv", rows)
    (fam, spp, n, ratio, se, worst, scene), = cs.rows([str(tmp_path)])
    logs = [math.log(r) for r in ratios.values()]
    assert (fam, spp, n, scene) == ("cycles", "4", 3, "c")
    assert ratio == pytest.approx(math.exp(sum(logs) / 3))
    mean = sum(logs) / 3
    sd = math.sqrt(sum((x - mean) ** 2 for x in logs) / 2)
    assert se == pytest.approx(math.expm1(sd / math.sqrt(3)))
    assert worst == pytest.approx(1.2)


def test_kinds_split_the_test_report_by_prefix(tmp_path):
    rows = [("holdout-x", "16", SHIP, 0.02), ("holdout-x", "16", CAND, 0.01),
            ("named-y", "16", SHIP, 0.02), ("named-y", "16", CAND, 0.04)]
    write(tmp_path / "img-test" / "measurements.csv", rows)
    got = {r[0]: r[3] for r in cs.rows([str(tmp_path)])}
    assert got == {"held-out": pytest.approx(0.5), "hand-written": pytest.approx(2.0)}


def test_two_candidates_in_one_report_are_refused(tmp_path):
    write(tmp_path / "img-cycles" / "measurements.csv",
          [("a", "4", CAND, 1.0), ("a", "4", SHIP, 1.0), ("a", "4", "X (candidate-other)", 1.0)])
    with pytest.raises(ValueError):
        cs.rows([str(tmp_path)])
