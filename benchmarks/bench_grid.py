"""Occupancy-grid ray casting: holoslam's exact traversal (numba) next to the former numpy sampler.

    .venv/bin/python benchmarks/bench_grid.py [--quick] [--repeat N]

Scan sets (sensor poses = the log's ground truth at each scan stamp composed with the base->laser transform;
clearing distance and margin of the pipeline's defaults, ``holoslam.config.GridConfig``, 5 cm cells):
- household: every scan of the bundled household log (``datasets/household_small.mcap``);
- household x4: those scans four times, the copies at poses jittered by 1 cm / 0.5 deg (seeded), a 4x longer
  log over the same rooms (``--quick`` skips it).

Rows: median wall and CPU (time.process_time) seconds of ``build_grid`` over --repeat runs in this process
(after one untimed warm-up call, whose time - numba import and loading the compiled kernel from its cache - is
printed as ``first_s``), the same for the reference (``numpy_sampler`` below: the previous implementation,
kept verbatim, beams sampled every half cell), the ratios reference / new, and how the two maps differ: the
fraction of all cells (and of the cells known in either map) whose class - free, occupied, unknown at the
map_server thresholds - differs, and the occupied / free / unknown counts of each.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from holoslam.errors import MapError
from holoslam.maps.grid import OccupancyGrid
from holoslam.maps.occupancy import _logit, beam_endpoints, build_grid


def numpy_sampler(
    wTs, scans, resolution=0.05, *, margin_m=0.5, bounds=None, no_return_clear_m=None, p_hit=0.75,
    p_miss=0.4, l_max=6.0, step=0.5, occupied_thresh=0.65, free_thresh=0.196, chunk_beams=8000,
) -> OccupancyGrid:
    """The former ``build_grid`` (the reference): samples at ``step`` cells along each beam, consecutive
    repeats of a cell dropped, misses before the end cell counted with np.bincount in chunks of beams."""
    if not 0 < step <= 1:
        raise MapError(f"ray sampling step must be in (0, 1] cells, got {step}")
    origins, ends, hit = beam_endpoints(wTs, scans, no_return_clear_m)
    if bounds is None:
        pts = np.concatenate([np.asarray(wTs, dtype=np.float64).reshape(-1, 3)[:, :2], ends])
        lo = pts.min(axis=0) - margin_m
        hi = pts.max(axis=0) + margin_m
    else:
        lo, hi = np.array(bounds[:2], dtype=float), np.array(bounds[2:], dtype=float)
    lo = np.floor(lo / resolution + 1e-6) * resolution
    w = int(np.ceil((hi[0] - lo[0]) / resolution - 1e-9))
    h = int(np.ceil((hi[1] - lo[1]) / resolution - 1e-9))
    w, h = max(w, 1), max(h, 1)
    ncell = h * w
    hits = np.zeros(ncell, dtype=np.int64)
    misses = np.zeros(ncell, dtype=np.int64)

    def cell_index(xy: np.ndarray) -> np.ndarray:
        col = np.floor((xy[..., 0] - lo[0]) / resolution).astype(np.int64)
        row = np.floor((xy[..., 1] - lo[1]) / resolution).astype(np.int64)
        inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
        return np.where(inside, row * w + col, -1)

    he = cell_index(ends[hit])
    hits += np.bincount(he[he >= 0], minlength=ncell)
    ds = step * resolution
    length = np.linalg.norm(ends - origins, axis=1)
    end_cell = cell_index(ends)
    order = np.argsort(length)
    for c0 in range(0, order.shape[0], chunk_beams):
        sel = order[c0 : c0 + chunk_beams]
        ns = int(np.ceil(length[sel].max() / ds)) + 1 if sel.size else 0
        if ns <= 0:
            continue
        t = np.arange(ns) * ds
        o, e, ln = origins[sel], ends[sel], length[sel]
        u = (e - o) / np.maximum(ln, 1e-12)[:, None]
        pts = o[:, None, :] + t[None, :, None] * u[:, None, :]
        idx = cell_index(pts)
        valid = (t[None, :] < ln[:, None]) & (idx >= 0) & (idx != end_cell[sel][:, None])
        first = np.ones_like(valid)
        first[:, 1:] = idx[:, 1:] != idx[:, :-1]
        take = valid & first
        misses += np.bincount(idx[take], minlength=ncell)

    L = np.clip(hits * _logit(p_hit) + misses * _logit(p_miss), -l_max, l_max)
    prob = 100.0 / (1.0 + np.exp(-L))
    occ = np.where((hits + misses) > 0, np.rint(prob), -1).astype(np.int8).reshape(h, w)
    return OccupancyGrid(occ, float(resolution), float(lo[0]), float(lo[1]),
                         occupied_thresh=occupied_thresh, free_thresh=free_thresh)


def household_scans(copies: int):
    from holoslam import geometry as g
    from holoslam.evaluate import truth_at
    from holoslam.io.datasets import bundled_household_log
    from holoslam.io.mcap import read_log
    from holoslam.submaps.frontend import base_to_laser

    log, _ = read_log(bundled_household_log())
    gt_t, gt = log.ground_truth_arrays()
    wTb = truth_at(np.array([s.stamp_ns for s in log.scans], dtype=np.int64), gt_t, gt)
    wTs = g.compose(wTb, np.broadcast_to(base_to_laser(log, log.scans[0].frame_id), wTb.shape))
    rng = np.random.default_rng(7)
    poses = [wTs] + [wTs + rng.normal(0.0, [0.01, 0.01, np.radians(0.5)], wTs.shape) for _ in range(copies - 1)]
    return np.concatenate(poses), list(log.scans) * copies


def timed(fn, repeat: int) -> tuple[float, float, object]:
    """Median wall and CPU seconds of fn() over ``repeat`` runs, and its last result."""
    wall, cpu, out = [], [], None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    return statistics.median(wall), statistics.median(cpu), out


def classes(grid: OccupancyGrid) -> np.ndarray:
    return np.where(grid.occupied, 2, np.where(grid.free, 1, 0))


def main() -> None:
    from holoslam.config import GridConfig

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the household scans only, 3 runs each")
    ap.add_argument("--repeat", type=int, default=5, help="timed runs per implementation and scan set")
    args = ap.parse_args()
    repeat = 3 if args.quick else max(args.repeat, 1)
    cfg = GridConfig()
    kw = dict(margin_m=cfg.margin_m, no_return_clear_m=cfg.no_return_clear_m)
    sets = [("household", 1)] + ([] if args.quick else [("household x4", 4)])
    head = (f"{'scans':<14}{'beams':>9}{'cells':>8}{'first_s':>9}{'new_s':>8}{'new_cpu':>9}{'ref_s':>8}"
            f"{'ref_cpu':>9}{'ratio':>7}{'cpu_ratio':>10}{'diff':>8}{'diff_known':>11}  occ/free/unk new | ref")
    print(f"build_grid at {cfg.resolution} m, no_return_clear_m={cfg.no_return_clear_m}, medians of {repeat}")
    print(head)
    for name, copies in sets:
        wTs, scans = household_scans(copies)
        nbeams = beam_endpoints(wTs, scans, cfg.no_return_clear_m)[0].shape[0]
        t0 = time.perf_counter()
        build_grid(wTs, scans, cfg.resolution, **kw)
        first = time.perf_counter() - t0
        new_s, new_cpu, new = timed(lambda: build_grid(wTs, scans, cfg.resolution, **kw), repeat)  # noqa: B023
        ref_s, ref_cpu, ref = timed(lambda: numpy_sampler(wTs, scans, cfg.resolution, **kw), repeat)  # noqa: B023
        if new.shape != ref.shape or (new.origin_x, new.origin_y) != (ref.origin_x, ref.origin_y):
            raise SystemExit(f"{name}: grids differ in extent: {new.shape} vs {ref.shape}")
        a, b = classes(new), classes(ref)
        known = (a > 0) | (b > 0)
        diff, diff_known = float((a != b).mean()), float((a != b)[known].mean())
        counts = " | ".join("/".join(str(int((c == k).sum())) for k in (2, 1, 0)) for c in (a, b))
        print(f"{name:<14}{nbeams:>9}{a.size:>8}{first:>9.3f}{new_s:>8.3f}{new_cpu:>9.3f}{ref_s:>8.3f}"
              f"{ref_cpu:>9.3f}{ref_s / new_s:>7.1f}{ref_cpu / new_cpu:>10.1f}{diff:>8.2%}{diff_known:>11.2%}"
              f"  {counts}")


if __name__ == "__main__":
    main()
