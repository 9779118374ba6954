"""Writes tests/data/keep_mean_vectors.json: the keep-mean stage's cases
(keep_mean.vector_cases) with the float64 result, which src/keep_mean.rs's tests and
tests/test_keep_mean.py read.

Run from training/: python -m temc_train.vectors.keep_mean
"""

import argparse
import json

from ..keep_mean import VECTORS, vector_cases


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.parse_args(argv)  # --help; no options
    VECTORS.write_text(json.dumps(vector_cases()) + "\n")
    print(f"wrote {VECTORS}")


if __name__ == "__main__":
    main()
