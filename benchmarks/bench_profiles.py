"""Simulated robots with other noise, mapped with the same defaults (issue 13): anchors against dead reckoning
and their covariance coverage per robot profile.

    .venv/bin/python benchmarks/bench_profiles.py [--profiles default noisy skid-steer] [--seeds 21 22]
                                                  [--duration 500]

Each profile (``holoslam.sim.profiles``: default; noisy = 3x every sensor's noise; skid-steer = another odometry
model that publishes a constant placeholder covariance) simulates one household drive per seed, without images,
written to a temporary MCAP and read back as any log is; holoslam is never told the profile. The SLAM part of a
run maps it (``holoslam.optimise.map_log``: front end, final solve, keyframe solve). Printed per profile, pooled
over the seeds: the anchors' position RMSE against the ground truth at their stamps, dead reckoning's at the same
stamps, their ratio, how many true anchors lie in their 95 % ellipses (after SE(2) alignment), the odometry noise
model used (``log``: the log's own covariance; ``defaults``) and the median CPU seconds of the mapping per log.
tests/test_robot_profiles.py checks the same on two 300 s drives (a short drive leaves dead reckoning only a few
centimetres off, so the ratio there is lower).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np


def map_profile(profile: str, seed: int, duration_s: float, folder: Path) -> dict:
    """One simulated drive of ``profile`` mapped as a run does: squared errors, coverage counts, noise source."""
    from holoslam.evaluate import trajectory_errors, truth_at
    from holoslam.io.mcap import read_log
    from holoslam.optimise import map_log
    from holoslam.sim import simulate_to_file
    from holoslam.sim.profiles import profile_config

    path = folder / f"{profile}_{seed}.mcap"
    simulate_to_file(path, profile_config(profile, seed=seed, duration_s=duration_s, image_rate_hz=0.0))
    log, _ = read_log(path)
    t0 = time.process_time()
    fe, sol = map_log(log)
    cpu = time.process_time() - t0
    gt_t, gt = log.ground_truth_arrays()
    true = truth_at(fe.anchor_stamps_ns, gt_t, gt)
    te = trajectory_errors(sol.wTa, true, sol.cov_wTa)
    de = trajectory_errors(truth_at(fe.anchor_stamps_ns, fe.dr_stamps_ns, fe.dr_wTb), true)
    return {"err2": te.position_errors_m**2, "dr_err2": de.position_errors_m**2,
            "inside": round(te.coverage95 * te.n_coverage), "n": te.n_coverage,
            "noise": fe.odometry_noise.source if fe.odometry_noise is not None else "?", "cpu": cpu}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profiles", nargs="+", default=["default", "noisy", "skid-steer"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[21, 22])
    ap.add_argument("--duration", type=float, default=500.0, help="seconds of each simulated drive")
    a = ap.parse_args()
    print(f"anchors vs dead reckoning per robot profile; seeds {a.seeds}, {a.duration:g} s drives, pooled")
    print(f"{'profile':<12}{'anchors mm':>12}{'DR mm':>8}{'ratio':>8}{'in 95 %':>10}{'noise':>10}{'cpu s':>8}")
    with tempfile.TemporaryDirectory() as tmp:
        for profile in a.profiles:
            runs = [map_profile(profile, s, a.duration, Path(tmp)) for s in a.seeds]
            rmse = float(np.sqrt(np.mean(np.concatenate([r["err2"] for r in runs]))))
            dr = float(np.sqrt(np.mean(np.concatenate([r["dr_err2"] for r in runs]))))
            inside, n = sum(r["inside"] for r in runs), sum(r["n"] for r in runs)
            noise = ",".join(sorted({r["noise"] for r in runs}))
            cpu = float(np.median([r["cpu"] for r in runs]))
            print(f"{profile:<12}{rmse * 1000:>12.1f}{dr * 1000:>8.0f}{dr / rmse:>7.1f}x{inside:>5}/{n:<4}"
                  f"{noise:>10}{cpu:>8.1f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
