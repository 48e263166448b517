"""Is a benchmark relation what the two scans it joins say? A check of the ground truth itself.

The Freiburg relations (``../shared/realdata``) were made from a SLAM result and checked by hand; a relation
along a featureless corridor can be off along it. This script takes the two laser scans at a relation's stamps and
aligns them with a plain point-to-point ICP (nearest neighbours by scipy's k-d tree, the closed-form SVD step; no
holoslam code: an independent measure), started from each candidate relative pose: the relation file's, a run's
(its ``trajectory.tum``), the odometry's, or given ones. For each start it prints the fit at the start and where
ICP ends, with the median nearest-point distance and the share of points within 5 cm. A candidate the scans
prefer fits better at its start and stays put; a corridor shows as several ends that fit alike.

    python benchmarks/relation_scans.py ../shared/realdata/aces.mcap 1037.06 1037.54 \\
        --relations ../shared/realdata/aces.relations --run RUN_FOLDER [--pose NAME=x,y,theta ...]

Measured 2026-12-06 (aces, whose laser frame is its base frame; the run of ``bench_realdata.py``): 1037.06 ->
1037.54 s, the truth 0.755 m (median 0.044 m and 56 % within 5 cm at its start; ICP moves it to 0.707 m, 0.035 m /
66 %), holoslam's run 0.348 m (0.033 m / 69 %; after ICP 0.324 m, 0.032 m / 71 %); 1030.75 -> 1031.31 s, the truth
0.635 m (after ICP 0.568 m, 0.034 m / 69 %), the run 0.417 m (after ICP 0.399 m, 0.031 m / 76 %); 95.24 -> 95.75 s:
ends 0.30-0.44 m apart that fit alike (0.036-0.041 m): a corridor.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

INLIER_M = 0.05  # m: a point "fits" within this of the other scan's nearest point (a 5 cm grid cell)


def scan_points(log, t_s: float) -> tuple[np.ndarray, float]:
    """The (N, 2) points (scan frame) of the log's scan nearest ``t_s`` (seconds), and that scan's stamp."""
    stamps = np.array([s.stamp_ns for s in log.scans], np.int64)
    s = log.scans[int(np.argmin(np.abs(stamps - round(t_s * 1e9))))]
    r = np.asarray(s.ranges, float)
    a = s.angle_min + s.angle_increment * np.arange(r.size)
    ok = np.asarray(s.valid, bool) & np.isfinite(r)
    return np.c_[r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])], s.stamp_ns / 1e9


def transform(aTb: np.ndarray, pts: np.ndarray) -> np.ndarray:
    c, s = np.cos(aTb[2]), np.sin(aTb[2])
    return pts @ np.array([[c, s], [-s, c]]) + aTb[:2]


def icp(a_pts: np.ndarray, b_pts: np.ndarray, aTb: np.ndarray, iterations: int = 50) -> np.ndarray:
    """b's pose in a's frame by point-to-point ICP from ``aTb``: each step pairs b's points with a's nearest and
    solves the rigid motion in closed form (SVD), the worst 20 % of pairs beyond 0.3 m left out."""
    tree = cKDTree(a_pts)
    x = np.asarray(aTb, float).copy()
    for _ in range(iterations):
        bt = transform(x, b_pts)
        d, i = tree.query(bt)
        keep = d < max(0.3, float(np.percentile(d, 80)))
        p, q = bt[keep], a_pts[i[keep]]
        pc, qc = p.mean(0), q.mean(0)
        u, _s, vt = np.linalg.svd((p - pc).T @ (q - qc))
        r = vt.T @ u.T
        if np.linalg.det(r) < 0:
            vt[1] *= -1
            r = vt.T @ u.T
        t = qc - r @ pc
        x = np.array([*(r @ x[:2] + t), x[2] + np.arctan2(r[1, 0], r[0, 0])])
    return x


def fit(a_pts: np.ndarray, b_pts: np.ndarray, aTb: np.ndarray) -> tuple[float, float]:
    """(median nearest-point distance m, share within ``INLIER_M``) of b placed at ``aTb`` on a."""
    d, _ = cKDTree(a_pts).query(transform(aTb, b_pts))
    return float(np.median(d)), float(np.mean(d < INLIER_M))


def between_at(path: Path, t1: float, t2: float) -> np.ndarray:
    """The relative pose between a TUM trajectory's poses nearest t1 and t2 (seconds)."""
    from holoslam import geometry as g
    from holoslam.io.trajectory import read_tum

    st, wTb = read_tum(path)
    i, j = (int(np.argmin(np.abs(st / 1e9 - t))) for t in (t1, t2))
    return g.between(wTb[i], wTb[j])


def relation_at(path: Path, t1: float, t2: float) -> np.ndarray | None:
    """The relation file's (x, y, yaw) from t1 to t2 (its first line within 1 ms of both), or None."""
    for line in path.read_text().splitlines():
        f = line.split()
        if len(f) >= 8 and abs(float(f[0]) - t1) < 1e-3 and abs(float(f[1]) - t2) < 1e-3:
            return np.array([float(f[2]), float(f[3]), float(f[7])])
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("t1", type=float, help="s, the relation's first stamp")
    ap.add_argument("t2", type=float, help="s, its second")
    ap.add_argument("--relations", type=Path, help="the log's .relations file: its relation t1 -> t2 as a start")
    ap.add_argument("--run", type=Path, help="a run folder: its trajectory's and dead reckoning's relations")
    ap.add_argument("--pose", action="append", default=[], metavar="NAME=x,y,theta", help="another start")
    a = ap.parse_args()
    from holoslam.io.mcap import read_log

    log, _ = read_log(a.log)
    starts: dict[str, np.ndarray] = {}
    if a.relations is not None and (rel := relation_at(a.relations, a.t1, a.t2)) is not None:
        starts["relation"] = rel
    if a.run is not None:
        starts["run"] = between_at(a.run / "trajectory.tum", a.t1, a.t2)
        starts["dead reckoning"] = between_at(a.run / "dead_reckoning.tum", a.t1, a.t2)
    for p in a.pose:
        name, _, v = p.partition("=")
        starts[name] = np.array([float(x) for x in v.split(",")])
    if not starts:
        sys.exit("no start: give --relations, --run or --pose")
    a_pts, sa = scan_points(log, a.t1)
    b_pts, sb = scan_points(log, a.t2)
    print(f"scans at {sa:.3f} s ({len(a_pts)} points) and {sb:.3f} s ({len(b_pts)} points)")
    print(f"{'start':<16}{'x, y m, yaw deg':>26}{'median m':>10}{'<5cm':>6}   {'after ICP':>26}{'median m':>10}{'<5cm':>6}")
    for name, x0 in starts.items():
        x1 = icp(a_pts, b_pts, x0)
        m0, f0 = fit(a_pts, b_pts, x0)
        m1, f1 = fit(a_pts, b_pts, x1)
        print(f"{name:<16}{_pose(x0):>26}{m0:>10.3f}{f0:>6.2f}   {_pose(x1):>26}{m1:>10.3f}{f1:>6.2f}")


def _pose(x: np.ndarray) -> str:
    return f"{x[0]:.3f}, {x[1]:.3f}, {np.degrees(x[2]):.2f}"


if __name__ == "__main__":
    main()
