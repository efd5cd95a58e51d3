"""Compare two per-replication result files of bench_batchcpu (--save): largest alpha difference, same
NaN pattern, identical coverage, Shapiro-Wilk p-values and errors.  ``python -m bench.compare_npz A B``."""
import sys

import numpy as np


def main(a_path, b_path):
    a, b = np.load(a_path), np.load(b_path)
    for k in ("alpha_lr", "alpha_two_sample", "alpha_paper"):
        print(f"{k}: largest |difference| {np.nanmax(np.abs(a[k] - b[k])):.1e}, "
              f"same NaN: {np.array_equal(np.isnan(a[k]), np.isnan(b[k]))}")
    for k in ("covered", "shapiro", "errors"):
        if k in a and k in b:
            print(f"{k} identical: {np.array_equal(a[k], b[k], equal_nan=k != 'errors')}")


if __name__ == "__main__":
    main(*sys.argv[1:3])
