"""Real laser data: a cut of the Freiburg benchmark's ACES log (../shared/realdata, not in the repository) is
mapped by the front end and solver to a stated relation error against the benchmark's ground truth."""

from __future__ import annotations

import numpy as np
import pytest
from repo_paths import SHARED

REALDATA = SHARED / "realdata"
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not (REALDATA / "aces.mcap").exists(), reason="../shared/realdata is not here"),
]


@pytest.fixture(scope="module")
def aces_cut(tmp_path_factory):
    from holoslam.evaluate import relation_errors
    from holoslam.io.mcap import read_log
    from holoslam.io.mcap_cut import cut_log
    from holoslam.io.relations import cut_relations, read_relations
    from holoslam.optimise import reestimate_anchors, run_build_options
    from holoslam.solve import SolveOptions, solve
    from holoslam.submaps.frontend import build_problem
    from holoslam.trajectory import keyframe_poses, optimised_trajectory

    path = tmp_path_factory.mktemp("aces") / "cut.mcap"
    cut_log(REALDATA / "aces.mcap", path, 0.0, 150.0)
    log, _ = read_log(path, require=["odometry", "scan"])
    fe = build_problem(log, optimize=reestimate_anchors)
    sol = solve(fe.problem, SolveOptions(build=run_build_options()))
    stamps = np.array([s.stamp_ns for s in log.scans], dtype=np.int64)
    ost, opose = log.odometry_arrays()
    ks, wTk = keyframe_poses(fe.submaps, sol.wTa)
    wTb = optimised_trajectory(stamps, ost, opose, ks, wTk)
    rel = cut_relations(read_relations(REALDATA / "aces.relations"), int(stamps[0]), int(stamps[-1]))
    return fe, relation_errors(stamps, wTb, rel), relation_errors(stamps, optimised_trajectory(
        stamps, ost, opose, ost[:1], opose[:1]), rel)


def test_a_real_log_maps_to_a_few_centimetres(aces_cut):
    """Measured 2026-12-02 (session 4): 127 relations, 0.036 m / 0.30 deg mean, 0.16 m max (Cartographer on the
    whole log: 0.0375 m / 0.373 deg); bounds about 1.5x the measurement (max: 1.9x), so a 2x regression fails."""
    _fe, e, _odo = aces_cut
    assert e.n_relations >= 120 and e.n_matched == e.n_relations
    assert e.translation_mean_m < 0.055
    assert e.rotation_mean_deg < 0.45
    assert e.translation_max_m < 0.3


def test_scan_matching_is_no_worse_than_good_wheel_odometry_over_short_spans(aces_cut):
    """ACES's odometry is good over the first minutes (0.036 m mean on these relations; it drifts to 0.55 m over
    the whole log): the matched trajectory must not add noise to it (measured 0.035 m, 0.31 deg)."""
    _fe, e, odo = aces_cut
    assert e.translation_mean_m < 1.1 * odo.translation_mean_m
    assert e.rotation_mean_deg < odo.rotation_mean_deg


def test_every_scan_has_a_matched_pose(aces_cut):
    """Nodes (motion filter) plus the scans localised between them cover the log's scans."""
    fe, _e, _odo = aces_cut
    n = sum(len(sm.scan_stamps_ns) + len(sm.track_stamps_ns) for sm in fe.submaps)
    stamps = np.unique(np.concatenate([np.concatenate([sm.scan_stamps_ns, sm.track_stamps_ns])
                                       for sm in fe.submaps]))
    # 941 scans in the cut; measured 875 matched: the robot stands still for its first ~10 s, and until the first
    # submap holds min_scans_to_match nodes (5 s apart when standing) scans are placed by odometry
    assert n >= len(stamps) and len(stamps) > 850
