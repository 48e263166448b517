"""A sparse real laser: the first 600 s of the Freiburg benchmark's fr079 log (../shared/realdata, not in the
repository) decimated to 1.4 Hz with every second beam dropped (180 beams over 180 deg, the held-out hospital log's
laser). Local SLAM must not shorten straight motion: its grid's odds updates are scaled to the laser's rate
(``GridConfig.for_rate``), and without that scaling the same cut shortens it several times more."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from repo_paths import SHARED

from holoslam import geometry as g

REALDATA = SHARED / "realdata"
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not (REALDATA / "fr079.mcap").exists(), reason="../shared/realdata is not here"),
]


def _along_bias(log, fe, rel) -> tuple[float, int]:
    """Summed along-track error of the straight short relations (< 5 s, > 0.15 m, < 10 deg) whose stamps are
    scans of the sparse log, over their summed length; and their count."""
    from holoslam.optimise import run_build_options
    from holoslam.solve import SolveOptions, solve
    from holoslam.trajectory import keyframe_poses, optimised_trajectory

    sol = solve(fe.problem, SolveOptions(build=run_build_options()))
    stamps = np.array([s.stamp_ns for s in log.scans], np.int64)
    ost, opose = log.odometry_arrays()
    ks, wTk = keyframe_poses(fe.submaps, sol.wTa)
    keep = np.isin(rel.t1_ns, stamps) & np.isin(rel.t2_ns, stamps)
    dist = np.hypot(rel.T[:, 0], rel.T[:, 1])
    keep &= (rel.t2_ns - rel.t1_ns < 5e9) & (dist > 0.15) & (np.abs(rel.T[:, 2]) < np.radians(10.0))
    a = optimised_trajectory(rel.t1_ns[keep], ost, opose, ks, wTk)
    b = optimised_trajectory(rel.t2_ns[keep], ost, opose, ks, wTk)
    d = g.between(a, b)
    u = rel.T[keep, :2] / dist[keep, None]
    along = np.sum(d[:, :2] * u, axis=1)
    return float(np.sum(along - dist[keep]) / np.sum(dist[keep])), int(keep.sum())


@pytest.fixture(scope="module")
def fr079_sparse(tmp_path_factory):
    from holoslam import derive
    from holoslam.io.mcap import read_log
    from holoslam.io.mcap_cut import cut_log
    from holoslam.io.relations import cut_relations, read_relations
    from holoslam.optimise import reestimate_anchors
    from holoslam.submaps.frontend import FrontEndConfig, build_problem, scan_rate_hz

    path = tmp_path_factory.mktemp("fr079") / "cut.mcap"
    cut_log(REALDATA / "fr079.mcap", path, 0.0, 600.0)
    full, _ = read_log(path, require=["odometry", "scan"])
    log = derive.drop_beams(derive.decimate_scans(full, 1.4), 2)
    stamps = np.array([s.stamp_ns for s in log.scans], np.int64)
    rel = cut_relations(read_relations(REALDATA / "fr079.relations"), int(stamps[0]), int(stamps[-1]))
    cfg = FrontEndConfig()
    plain = dataclasses.replace(cfg, local=dataclasses.replace(
        cfg.local, grid=dataclasses.replace(cfg.local.grid, reference_rate_hz=0.0)))
    scaled = _along_bias(log, build_problem(log, config=cfg, optimize=reestimate_anchors), rel)
    unscaled = _along_bias(log, build_problem(log, config=plain, optimize=reestimate_anchors), rel)
    return scan_rate_hz(stamps), scaled, unscaled


def test_a_sparse_real_laser_does_not_shorten_straight_motion(fr079_sparse):
    """Measured 2026-12-04 (the summed along-track error of the cut's 41 straight relations over their summed
    length): -0.53 % with the rate's scaling, -19.4 % without it (its submaps' walls ramp up over metres behind the
    frontier, and the matches climb them backwards; -0.66 / -19.7 % before the matcher's seed_margin); the wheel
    odometry of these logs errs about -1 %."""
    rate, (scaled, n), (unscaled, _) = fr079_sparse
    assert 1.0 < rate < 1.4  # decimated to 1.4 Hz: the kept scans are 0.71 s apart at least
    assert n >= 40
    assert scaled > -0.012
    assert unscaled < -0.05
