"""The simulated 350 m building's SLAM (issue 25's welcome extra, the held-out hospital's stand-in): per seed, the
anchors' error against the simulator's truth, dead reckoning's, and the loop closures that were wrong.

    .venv/bin/python benchmarks/bench_building_slam.py [--seeds 26 27 28] [--duration 4800] [--out DIR]
                                                       [--loops '{"agreement_factor": 0}']

Each seed's log is ``holoslam simulate --building --seed S --duration D`` (simulated once into ``--out``, reused
when present). The SLAM part of a run (``holoslam.optimise.map_log``: front end with its loop search, final
solve, keyframe stage) maps it; every closure the loop search returns is recorded and scored against the truth at
its two anchors (wrong: more than 1 m off). Columns: anchors RMSE and max after SE(2) alignment, heading RMSE,
dead reckoning's RMSE at the same stamps, closures returned and wrong, the CPU seconds of the mapping, and the
median over seeds. ``--loops`` overrides ``LoopConfig`` settings (JSON) to compare against the defaults in the same
process. A floor of identical rooms is harder than a real building in one respect (every room has twins) and
easier in another (no clutter, no people): it proves nothing alone; the real logs (``bench_realdata.py``) judge.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def building_log(seed: int, duration_s: float, out: Path) -> Path:
    from holoslam.sim.building import simulate_building_to_file

    path = out / f"building_s{seed}_{duration_s:g}s.mcap"
    if not path.exists():
        simulate_building_to_file(path, duration_s=duration_s, seed=seed)
    return path


def map_building(path: Path, loops: dict, compass: bool = True) -> dict:
    """One seed: map_log with the closures recorded; the errors against the truth. ``compass`` False: the log's
    headings left out (a robot with wheel odometry and a laser only, as the held-out hospital log's)."""
    from holoslam import geometry as g
    from holoslam.evaluate import trajectory_errors, truth_at
    from holoslam.io.mcap import read_log
    from holoslam.optimise import map_log
    from holoslam.submaps import loops as loops_mod
    from holoslam.submaps.frontend import FrontEndConfig

    log, _ = read_log(path)
    if not compass:
        log = replace(log, headings=())
    closures: list[tuple[int, int, np.ndarray]] = []
    search = loops_mod.LoopSearch.search

    def recording(self, *args, **kwargs):
        found = search(self, *args, **kwargs)
        closures.extend((c.old, c.new, np.array(c.mTn)) for c in found)
        return found

    cfg = FrontEndConfig()
    cfg = replace(cfg, loops=replace(cfg.loops, **loops))
    loops_mod.LoopSearch.search = recording  # type: ignore[method-assign]
    try:
        t0 = time.process_time()
        fe, sol = map_log(log, cfg, covariances=False)
        cpu = time.process_time() - t0
    finally:
        loops_mod.LoopSearch.search = search  # type: ignore[method-assign]
    gs, gp = log.ground_truth_arrays()
    truth = truth_at(fe.anchor_stamps_ns, gs, gp)
    err = trajectory_errors(sol.wTa, truth)
    dr = trajectory_errors(truth_at(fe.anchor_stamps_ns, fe.dr_stamps_ns, fe.dr_wTb), truth)
    wrong = sum(float(np.hypot(*g.between(g.between(truth[m], truth[n]), mTn)[:2])) > 1.0 for m, n, mTn in closures)
    return {"rmse": err.rmse_m, "max": err.max_m, "heading": err.heading_rmse_deg, "dr": dr.rmse_m,
            "closures": len(closures), "wrong": wrong, "cpu": cpu, "anchors": len(truth)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[26, 27, 28])
    ap.add_argument("--duration", type=float, default=4800.0, help="s of each drive (default: 80 min)")
    ap.add_argument("--out", type=Path, default=Path("/tmp/holoslam-bench-building"), help="the simulated logs")
    ap.add_argument("--loops", default="{}", help="LoopConfig settings as JSON")
    ap.add_argument("--no-compass", action="store_true",
                    help="leave the compass out: odometry and laser only (dead reckoning then drifts by 100s of m)")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    loops = json.loads(args.loops)
    rows = []
    print(f"{'seed':>5}{'anchors':>9}{'RMSE m':>9}{'max m':>8}{'head deg':>10}{'DR RMSE m':>11}{'closures':>10}"
          f"{'wrong':>7}{'cpu s':>8}", flush=True)
    for seed in args.seeds:
        r = map_building(building_log(seed, args.duration, args.out), loops, compass=not args.no_compass)
        rows.append(r)
        print(f"{seed:>5}{r['anchors']:>9}{r['rmse']:>9.3f}{r['max']:>8.2f}{r['heading']:>10.2f}{r['dr']:>11.3f}"
              f"{r['closures']:>10}{r['wrong']:>7}{r['cpu']:>8.1f}", flush=True)
    med = {k: float(np.median([r[k] for r in rows])) for k in ("rmse", "dr", "cpu")}
    print(f"median RMSE {med['rmse']:.3f} m against dead reckoning {med['dr']:.3f} m "
          f"({med['rmse'] / med['dr']:.2f}x), {med['cpu']:.0f} s CPU; loops {loops or 'defaults'}"
          f"{'; without the compass' if args.no_compass else ''}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
