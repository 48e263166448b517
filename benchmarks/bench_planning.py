"""Two-layer planning (seed 003) against grid A* on the reference household and on large household-like maps.

For each map: build time of both layers (nine-square decomposition, layer 1 with its edges, layer 2 regions
with their adjacency) and of the query structure (portal graph), then the same random start/goal pairs (free
cells of one connected component) planned by holoslam's two-layer planner and by pyastar2d's compiled
8-connected grid A* (dev/benchmark dependency) in the same run, each over all pairs in its own loop, the two
loops alternating three times (once above 2000 cells; the machine is shared, so a load change mid-run
should not fall on one planner only): median query times, their ratio, and path length ratios (two-layer /
A*). The numba kernels are loaded (or compiled
on the very first run) by a warm-up before the measured rows. Large maps tile the household (outer walls opened between tiles where both
sides are free) and crop to the size.

    .venv/bin/python benchmarks/bench_planning.py [--sizes 1000,2000,4000] [--queries 200]
    [--large-queries 10]
"""

from __future__ import annotations

import argparse
import statistics
import time

import cv2
import numpy as np


def household_free(resolution: float = 0.05) -> np.ndarray:
    from holoslam.sim.world import free_space, reference_household

    return free_space(reference_household(), resolution).clearance > 0


def tiled(free: np.ndarray, size: int) -> np.ndarray:
    h, w = free.shape
    big = np.tile(free, (size // h + 1, size // w + 1))
    for c in range(w, big.shape[1] - 1, w):  # open the outer walls between tiles where both sides are free
        rows = big[:, c - 3] & big[:, c + 2]
        big[rows, c - 2 : c + 2] = True
    for r in range(h, big.shape[0] - 1, h):
        cols = big[r - 3, :] & big[r + 2, :]
        big[r - 2 : r + 2, cols] = True
    return np.ascontiguousarray(big[:size, :size])


def query_pairs(free: np.ndarray, n: int, seed: int = 0) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    _, cc = cv2.connectedComponents(free.astype(np.uint8), connectivity=8)
    big = np.argmax(np.bincount(cc[free].ravel()))
    cells = np.argwhere(cc == big)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, cells.shape[0], size=(n, 2))
    return [(tuple(map(int, cells[i])), tuple(map(int, cells[j]))) for i, j in idx]


def run(
    name: str, free: np.ndarray, n_queries: int, res: float = 0.05, repeats: int = 3, rounds: int = 3
) -> dict:
    import pyastar2d

    import holoslam.planning._fast  # noqa: F401  (numba import and kernel cache load: once per process)
    from holoslam.maps.grid import OccupancyGrid
    from holoslam.planning.routes import build_planner, path_length, plan_path
    from holoslam.planning.twolayer import build_two_layer

    grid = OccupancyGrid.from_free_mask(free, res)
    builds, pbuilds = [], []
    for _ in range(repeats):
        t = time.perf_counter()
        tl = build_two_layer(grid, 1)
        builds.append(time.perf_counter() - t)
        t = time.perf_counter()
        planner = build_planner(tl)
        pbuilds.append(time.perf_counter() - t)
    weights = np.where(free, 1.0, np.inf).astype(np.float32)
    pairs = query_pairs(free, n_queries)
    xy = [
        (
            np.array([(a[1] + 0.5) * res, (a[0] + 0.5) * res]),
            np.array([(b[1] + 0.5) * res, (b[0] + 0.5) * res]),
        )
        for a, b in pairs
    ]
    # each planner runs over all pairs in its own loop (so neither evicts the other's data from the caches);
    # the two loops alternate ``rounds`` times and the medians pool all rounds, so a change of the machine's
    # load during the run (it is shared) does not land on one planner only
    tq, ta, lengths, ratios = [], [], [], []
    for k in range(rounds):
        for s, g in xy:
            t = time.perf_counter()
            route = plan_path(planner, s, g)
            tq.append(time.perf_counter() - t)
            if k == 0:
                lengths.append(route.length)
        for (a, b), ours in zip(pairs, lengths, strict=True):
            t = time.perf_counter()
            p = pyastar2d.astar_path(weights, a, b, allow_diagonal=True)
            ta.append(time.perf_counter() - t)
            ref = path_length(p) * res
            if k == 0 and ref > 0:
                ratios.append(ours / ref)
    return {
        "map": name,
        "cells": f"{free.shape[0]}x{free.shape[1]}",
        "blocks": tl.n_blocks,
        "regions": tl.n_regions,
        "build_s": statistics.median(builds),
        "planner_s": statistics.median(pbuilds),
        "queries": len(pairs),
        "ours_ms": statistics.median(tq) * 1e3,
        "astar_ms": statistics.median(ta) * 1e3,
        "speedup": statistics.median(ta) / statistics.median(tq),
        "len_med": statistics.median(ratios) if ratios else float("nan"),
        "len_max": max(ratios) if ratios else float("nan"),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1000,2000,4000")
    ap.add_argument("--queries", type=int, default=200)
    ap.add_argument("--large-queries", type=int, default=10)
    args = ap.parse_args()
    rows = []
    house = household_free()
    # loads / compiles the kernels outside the measured rows
    warm = run("warm-up", house, 5, repeats=1, rounds=1)
    del warm
    rows.append(run("household", house, args.queries))
    for size in [int(s) for s in args.sizes.split(",") if s]:
        rows.append(
            run(
                f"tiled {size}",
                tiled(house, size),
                args.large_queries,
                repeats=1 if size > 2000 else 3,
                rounds=1 if size > 2000 else 3,
            )
        )
    cols = [
        ("map", "{:<14}"),
        ("cells", "{:>10}"),
        ("blocks", "{:>8}"),
        ("regions", "{:>8}"),
        ("build_s", "{:>8.3f}"),
        ("planner_s", "{:>9.3f}"),
        ("queries", "{:>7}"),
        ("ours_ms", "{:>8.3f}"),
        ("astar_ms", "{:>9.2f}"),
        ("speedup", "{:>8.1f}"),
        ("len_med", "{:>7.3f}"),
        ("len_max", "{:>7.3f}"),
    ]
    print(" ".join(f"{c:>{len(f.format(rows[0][c]))}}" for c, f in cols))
    for r in rows:
        print(" ".join(f.format(r[c]) for c, f in cols))
    print(
        "build_s: both layers (median of 3; 1 run above 2000 cells); planner_s: port graph + ALT landmarks + "
        "query structures; ours/astar: median query ms over the same pairs (3 alternating rounds of each, 1 "
        "above 2000 cells); speedup = astar / ours; "
        "len = two-layer length / A* length"
    )


if __name__ == "__main__":
    main()
