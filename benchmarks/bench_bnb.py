"""Branch-and-bound scan matching (holoslam.submaps.bnb) against brute force, in the same process.

    .venv/bin/python benchmarks/bench_bnb.py [--quick] [--repeat N] [--scans K]

Worlds: a seeded square building of rooms (interior walls with doorways, furniture boxes) of 18 m and 38 m in
0.05 m grids of 400 x 400 (20 m) and 800 x 800 cells (40 m); the grid is what a well-filled submap looks like:
0.1 + 0.8 exp(-d^2 / 2) at d cells from the nearest wall (unknown / free 0.1, walls 0.9). Scans: 360 beams,
12 m range, ray-cast at K seeded free poses (--scans, default 5), no noise.

Rows:
- precompute: median ms of ``precompute(prob, 7)`` (levels 2^0..2^6), and the bytes it holds;
- small (+-0.3 m, +-10 deg, seed 0.12 m / 4 deg off the truth, min_score 0.1) and loop (+-7 m, +-30 deg,
  seed 3-5 m and 20 deg off, min_score 0.5) windows: median candidates per scan (angles x offsets), median
  over the scans of the per-scan median wall ms (and CPU ms) of ``search`` (B&B, --repeat calls), the wall
  ms of the compiled exhaustive search (``_bnb_fast.exhaustive``: the same scoring kernel over every
  candidate, the fair measure of what the bounds save) and of the numpy ``brute_force``, one call each (on
  the loop window they take seconds: the compiled one runs on 2 scans, the numpy one on 1; --quick: 1 and
  none), the ratios exhaustive / B&B and numpy / B&B, whether every result's score equals the references'
  (``same``), and how many results lie within one cell and one angular step of the truth (``found``).
The first call of each kernel (numba cache load or compile) is untimed.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np
from scipy import ndimage

from holoslam.sim.world import raycast
from holoslam.submaps import _bnb_fast, bnb

RES = 0.05
ORIGIN = (-1.0, -1.0)  # the grids start 1 m outside the building


def building(size_m: float, seed: int) -> np.ndarray:
    """Wall segments (M, 4) of a square building [0, size_m]^2: outer walls, rooms of 4-7 m with 1 m
    doorways, boxes."""
    rng = np.random.default_rng(seed)
    segs = [[0, 0, size_m, 0], [size_m, 0, size_m, size_m], [size_m, size_m, 0, size_m], [0, size_m, 0, 0]]
    for axis in range(2):
        pos = rng.uniform(4.0, 7.0)
        while pos < size_m - 3.0:
            cuts = np.sort(rng.uniform(0.5, size_m - 1.5, max(1, int(size_m / 6))))
            start = 0.0
            for c in cuts:  # a wall from start to c, a 1 m doorway, ...
                if c > start + 0.3:
                    seg = [start, pos, c, pos] if axis == 0 else [pos, start, pos, c]
                    segs.append(seg)
                start = c + 1.0
            segs.append([start, pos, size_m, pos] if axis == 0 else [pos, start, pos, size_m])
            pos += rng.uniform(4.0, 7.0)
    for _ in range(int(size_m * size_m / 25)):
        x, y = rng.uniform(1, size_m - 1, 2)
        a, b = rng.uniform(0.3, 1.2, 2)
        segs += [[x, y, x + a, y], [x + a, y, x + a, y + b], [x + a, y + b, x, y + b], [x, y + b, x, y]]
    return np.array(segs, dtype=np.float64)


def blurred_grid(segs: np.ndarray, cells: int) -> np.ndarray:
    """prob (cells, cells) of the walls, origin (-1, -1): 0.1 + 0.8 exp(-d^2 / 2), d in cells from the
    nearest wall cell."""
    wall = np.zeros((cells, cells), dtype=bool)
    for x0, y0, x1, y1 in segs:
        n = int(math.hypot(x1 - x0, y1 - y0) / (RES / 4)) + 2
        t = np.linspace(0.0, 1.0, n)
        c = np.floor((x0 + t * (x1 - x0) - ORIGIN[0]) / RES).astype(int)
        r = np.floor((y0 + t * (y1 - y0) - ORIGIN[1]) / RES).astype(int)
        ok = (r >= 0) & (r < cells) & (c >= 0) & (c < cells)
        wall[r[ok], c[ok]] = True
    d = ndimage.distance_transform_edt(~wall)
    return (0.1 + 0.8 * np.exp(-0.5 * d * d)).astype(np.float32)


def scan(segs: np.ndarray, wTb: np.ndarray, beams: int = 360, max_range: float = 12.0) -> np.ndarray:
    ang = np.linspace(-math.pi, math.pi, beams, endpoint=False)
    r = raycast(segs, wTb[None, :2], (ang + wTb[2])[None], max_range)[0]
    ok = np.isfinite(r)
    return np.column_stack([r[ok] * np.cos(ang[ok]), r[ok] * np.sin(ang[ok])])


def free_poses(prob: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """k poses in free space, at least 0.5 m from any wall and 2 m inside the building."""
    size_m = prob.shape[0] * RES - 2.0
    out = []
    while len(out) < k:
        x, y = rng.uniform(2.0, size_m - 2.0, 2)
        r, c = int((y - ORIGIN[1]) / RES), int((x - ORIGIN[0]) / RES)
        if prob[max(r - 10, 0):r + 11, max(c - 10, 0):c + 11].max() < 0.11:
            out.append([x, y, rng.uniform(-math.pi, math.pi)])
    return np.array(out)


def timed(fn, repeat: int, cpu: list | None = None) -> tuple[float, object]:
    """Median wall seconds of ``repeat`` calls and the last result; the median CPU seconds appended to cpu."""
    times, cpus, out = [], [], None
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        times.append(time.perf_counter() - t)
        cpus.append(time.process_time() - c)
    if cpu is not None:
        cpu.append(statistics.median(cpus))
    return statistics.median(times), out


def seeds(truth: np.ndarray, loop: bool, rng: np.random.Generator) -> np.ndarray:
    if loop:
        d, phi = rng.uniform(3.0, 5.0), rng.uniform(-math.pi, math.pi)
        return truth + [d * math.cos(phi), d * math.sin(phi), rng.choice([-1, 1]) * math.radians(20)]
    return truth + [0.12 * rng.choice([-1, 1]), -0.09, math.radians(4)]


def case(grids, segs, poses, loop: bool, repeat: int, ref_scans: tuple[int, int], rng) -> dict:
    """One window over the scans at ``poses``; the references run on the first ref_scans = (compiled,
    numpy) scans."""
    wxy, wth, min_score = (7.0, math.radians(30), 0.5) if loop else (0.3, math.radians(10), 0.1)
    t_bnb, c_bnb, t_exh, t_np, same, found, ncand = [], [], [], [], [], [], []
    for k, truth in enumerate(poses):
        pts = scan(segs, truth)
        seed = seeds(truth, loop, rng)
        args = (grids, pts, seed, wxy, wth, min_score)
        t, m = timed(lambda a=args: bnb.search(*a), repeat, c_bnb)
        t_bnb.append(t)
        cand = bnb._candidates(grids, pts, seed, wxy, wth, None)
        ncand.append(cand.angles.size * (cand.box[1] * 2 + 1) * (cand.box[3] * 2 + 1))
        ref = []
        if k < ref_scans[0]:
            t, e = timed(lambda c=cand: _bnb_fast.exhaustive(grids.prob, c.rows, c.cols, c.cells_box, c.box,
                                                             float(bnb.OUTSIDE)), 1)
            t_exh.append(t)
            ref.append(e[0] / pts.shape[0])
        if k < ref_scans[1]:
            t, b = timed(lambda a=args: bnb.brute_force(*a), 1)
            t_np.append(t)
            ref.append(b.score if b else -1.0)
        same.append(m is not None and all(r == m.score for r in ref))
        dth = abs(cand.angles[1] - cand.angles[0])
        err = np.abs(m.aTb - truth) if m is not None else np.full(3, np.inf)
        err[2] = abs((err[2] + math.pi) % (2 * math.pi) - math.pi)
        found.append(bool(err[0] <= RES and err[1] <= RES and err[2] <= dth + 1e-12))
    ms = 1e3 * statistics.median(t_bnb)
    exh = 1e3 * statistics.median(t_exh)
    npy = 1e3 * statistics.median(t_np) if t_np else float("nan")
    return {"cand": int(statistics.median(ncand)), "bnb": ms, "cpu": 1e3 * statistics.median(c_bnb), "exh": exh, "np": npy, "same": all(same), "found": sum(found),
            "n": len(found)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="400x400 only, no numpy brute force on the loop window")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--scans", type=int, default=5)
    args = ap.parse_args()
    rng = np.random.default_rng(7)
    sizes = [400] if args.quick else [400, 800]
    warm = bnb.precompute(np.full((20, 20), 0.5, np.float32), 7, origin=(0.0, 0.0), res=RES)
    bnb.search(warm, np.ones((3, 2)), np.zeros(3), 0.1, 0.1, 0.0)
    c = bnb._candidates(warm, np.ones((3, 2)), np.zeros(3), 0.1, 0.1, None)
    _bnb_fast.exhaustive(warm.prob, c.rows, c.cols, c.cells_box, c.box, 0.1)
    print(f"branch and bound vs brute force: {RES} m grids, 360-beam scans, medians of {args.repeat} "
          f"(B&B) over {args.scans} scans; ms per call")
    print(f"{'grid':<9}{'precompute_ms':>14}{'MB':>7}  {'window':<7}{'candidates':>11}{'bnb_ms':>9}{'cpu_ms':>8}"
          f"{'exhaustive_ms':>14}{'ratio':>8}{'numpy_ms':>10}{'ratio':>8}  same  found")
    for cells in sizes:
        segs = building(cells * RES - 2.0, seed=cells)
        prob = blurred_grid(segs, cells)
        t_pre, grids = timed(lambda p=prob: bnb.precompute(p, 7, origin=ORIGIN, res=RES), args.repeat)
        poses = free_poses(prob, args.scans, rng)
        for loop in (False, True):
            refs = ((1, 0) if args.quick else (2, 1)) if loop else (args.scans, args.scans)
            r = case(grids, segs, poses, loop, args.repeat, refs, rng)
            print(f"{cells}x{cells:<5}{1e3 * t_pre:>14.2f}{grids.nbytes / 1e6:>7.2f}  "
                  f"{'loop' if loop else 'small':<7}{r['cand']:>11,}{r['bnb']:>9.2f}{r['cpu']:>8.2f}{r['exh']:>14.1f}"
                  f"{r['exh'] / r['bnb']:>8.0f}{r['np']:>10.0f}{r['np'] / r['bnb']:>8.0f}  "
                  f"{'yes' if r['same'] else 'NO':<6}{r['found']}/{r['n']}")


if __name__ == "__main__":
    main()
