"""benchmarks/bench_household_accuracy.py compares a corrupted run with the clean one over the same objects and
says how many each located (issue 13: 35 -> 32 matched went unreported, and the ratio was over the survivors)."""

from __future__ import annotations

import pytest
from repo_paths import benchmark_module


@pytest.fixture(scope="module")
def bench():
    return benchmark_module("bench_household_accuracy")


def test_a_corrupted_run_that_loses_objects_says_so(bench):
    clean = {"pos": 0.01, "obj_errors": {f"O{k:02d}": 0.01 for k in range(1, 36)}}
    clean["obj_errors"].update({"O01": 0.05, "O02": 0.05, "O03": 0.05})  # the three worst of the clean run
    worse = {"pos": 0.012, "obj_errors": {k: 2 * v for k, v in clean["obj_errors"].items() if k not in ("O01", "O02", "O03")}}
    c = bench.compare_to_clean(worse, clean)
    assert (c["matched"], c["clean_matched"], c["lost"]) == (32, 35, ["O01", "O02", "O03"])
    # over the objects both located the variant is twice as far off; its survivors against the whole clean run (the
    # old ratio) said 1.14x, the lost objects being the clean run's worst
    assert c["obj_ratio"] == pytest.approx(2.0)
    assert c["pos_ratio"] == pytest.approx(1.2)
