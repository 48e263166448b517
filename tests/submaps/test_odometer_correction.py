"""The odometer correction (holoslam.submaps.odometer, holoslam.optimise.odometer_pass): a real robot's odometry
with a known bias put on it is found off by a first pass and the run maps again on it corrected, exactly as a run
on that corrected log would; where the scans see motion every way (a real building's rooms and clutter) the gate
leaves the odometry alone; the report says which."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from repo_paths import SHARED

from holoslam.submaps.odometer import (
    MIN_STRETCHES,
    OdometerBias,
    OdometerCorrectionConfig,
    OdometerWatch,
    is_blind,
    odometer_correction,
    odometer_text,
)

REALDATA = SHARED / "realdata"
# fr079's own odometer over its first 90 s (tests/submaps/test_realdata_frames.py): -0.7 % and -0.92 deg/m; the
# bias put on top of it: derive.bias_odometry's 5 % and 0.5 deg per metre
SCALE, DEG_PER_M = 1.05, 0.5


@pytest.fixture(scope="module")
def biased_cut(tmp_path_factory):
    if not (REALDATA / "fr079.mcap").exists():
        pytest.skip("../shared/realdata is not here")
    from holoslam.derive import bias_odometry
    from holoslam.io.mcap import read_log
    from holoslam.io.mcap_cut import cut_log

    path = tmp_path_factory.mktemp("fr079") / "cut.mcap"
    cut_log(REALDATA / "fr079.mcap", path, 0.0, 90.0)
    log, report = read_log(path, require=["odometry", "scan"])
    return bias_odometry(log, SCALE, DEG_PER_M), report


def _config(**odometer):
    from holoslam.config import RunConfig

    cfg = RunConfig()
    return replace(cfg, frontend=replace(cfg.frontend, odometer=replace(cfg.frontend.odometer, **odometer)))


@pytest.mark.slow
def test_a_biased_real_odometer_is_found_and_the_run_maps_again_on_it_corrected(biased_cut):
    from holoslam.pipeline import FRONT_END, run_data

    log, report = biased_cut
    # the gate open: fr079's scans are blind along the track at < 1 % of its nodes (the default gate, 5 %, keeps
    # its odometry), and a 90 s cut's straight stretches are enough
    said = []
    result = run_data(log, report, _config(blind_share=0.0, min_stretches=MIN_STRETCHES),
                      progress=lambda stage, *_a: said.append(stage))
    fix = result.frontend.odometer_correction
    assert fix is not None and fix.bias.off and fix.bias.stretches >= MIN_STRETCHES
    # the bias put on (5 % long, 0.5 deg/m) on fr079's own (0.7 % short, -0.92 deg/m): 1.0427 and about -0.42
    assert abs(fix.bias.scale - SCALE * 0.993) < 0.01
    assert abs(fix.bias.yaw_deg_per_m - (DEG_PER_M - 0.92)) < 0.3
    # a second pass, not a patch: the same anchors as a run on the corrected log from its start
    again = run_data(fix.apply(log), report, _config(enabled=False))
    assert again.frontend.odometer_correction is None and len(again.wTa) == len(result.wTa)
    assert np.abs(again.wTa - result.wTa).max() < 1e-6
    # the report: the raw odometry's check and the correction the run mapped with
    m = result.report.submaps.odometer
    assert m["corrected"]["scale"] == pytest.approx(fix.bias.scale, abs=1e-4)
    assert abs(m["scale"] - fix.bias.scale) < 0.01  # the raw odometry against the corrected run's keyframes
    assert "the run mapped again with the odometry corrected" in result.report.text()
    # and the user saw why the SLAM stages ran twice
    notice = [s for s in said if s.startswith(f"the odometer measures {100 * (fix.bias.scale - 1):+.1f} %")]
    assert len(notice) == 1 and "mapping again on the corrected odometry" in notice[0]
    assert said.index(notice[0]) < len(said) - 1 - said[::-1].index(FRONT_END)


@pytest.mark.slow
def test_local_slams_own_check_finds_it_while_mapping_and_starts_again(biased_cut):
    # checked every 25 matched nodes (the default 500 is more than this 90 s cut's ~190; its 8 straight stretches
    # are in by node 125): the front end finds the odometer off while it maps and starts again on the corrected
    # odometry, without finishing a first pass
    from holoslam.submaps.frontend import FrontEndConfig, build_problem

    cfg = FrontEndConfig()
    fe = build_problem(biased_cut[0], config=replace(cfg, odometer=replace(
        cfg.odometer, blind_share=0.0, min_stretches=MIN_STRETCHES, check_every_nodes=25)))
    fix = fe.odometer_correction
    assert fix is not None and abs(fix.bias.scale - SCALE * 0.993) < 0.01
    assert fix.nodes % 25 == 0 and 100 <= fix.nodes <= 175  # its 8th straight stretch came at node 125
    again = build_problem(fix.apply(biased_cut[0]), config=replace(cfg, odometer=replace(cfg.odometer,
                                                                                         enabled=False)))
    assert again.odometer_correction is None and len(again.submaps) == len(fe.submaps)
    assert np.abs(again.problem.initial_wTa - fe.problem.initial_wTa).max() < 1e-6


@pytest.mark.slow
def test_where_the_scans_see_motion_every_way_the_odometry_is_left_alone(biased_cut):
    from holoslam.optimise import map_log

    fe, _sol = map_log(biased_cut[0], covariances=False)
    assert fe.blind_share < 0.02 and fe.odometer_correction is None  # the default gate: 5 % of nodes blind
    # the blind nodes' stamps, kept for the checks after the front end (their stretches are left out): few here
    nodes = len(np.unique(np.concatenate([sm.scan_stamps_ns for sm in fe.submaps])))
    assert len(fe.blind_stamps_ns) <= 0.02 * nodes and fe.blind_at(fe.blind_stamps_ns).all()
    marked = replace(fe, blind_stamps_ns=fe.anchor_stamps_ns[1:3])
    assert list(np.flatnonzero(marked.blind_at(fe.anchor_stamps_ns))) == [1, 2]


def _bias(scale=1.05, yaw=0.5, stretches=30, std=0.003):
    return OdometerBias(scale, std, yaw, 0.1, stretches, 2.0 * stretches)


@pytest.mark.parametrize(("bias", "blind", "found"), [
    (_bias(), 0.09, True),  # 5 % long where 9 % of the matches are blind: corrected
    (_bias(), 0.04, False),  # the scans see motion almost everywhere: the odometer is only their prior
    (_bias(stretches=12), 0.09, False),  # too few straight stretches to tell
    (_bias(scale=1.01, yaw=0.2), 0.5, False),  # within a wheel's calibration
    (_bias(scale=1.05, std=0.02), 0.5, False),  # off, but not by three standard errors
    (_bias(scale=1.0, yaw=-1.0), 0.09, False),  # a heading drift alone: the corridor's walls see the heading
    (_bias(scale=0.96, yaw=-1.0), 0.09, True),  # 4 % short
    (_bias(scale=1.025), 0.09, False),  # 2.5 % long: a second pass maps no better (the building, +2.1 %)
    (None, 0.5, False),  # no measurement
])
def test_a_correction_needs_an_odometer_off_where_the_scans_are_blind(bias, blind, found):
    fix = odometer_correction(bias, blind, OdometerCorrectionConfig())
    assert (fix is not None) is found
    assert odometer_correction(bias, blind, OdometerCorrectionConfig(enabled=False)) is None


def test_a_ridge_is_a_match_blind_along_one_direction():
    along = np.diag([0.2 ** 2, 0.03 ** 2, 1e-4])  # 0.2 m along x, 0.03 m across: ratio 6.7
    turned = np.array([[0.0101, 0.0099, 0], [0.0099, 0.0101, 0], [0, 0, 1e-4]])  # 0.14 m along the diagonal
    assert is_blind(along, 5.0) and not is_blind(along, 7.0)
    assert is_blind(turned, 5.0) and not is_blind(np.diag([4e-4, 1e-4, 1e-4]), 5.0)  # 2:1 is a room


def test_the_report_says_the_run_mapped_with_the_odometry_corrected():
    m = {"scale": 1.052, "scale_std": 0.002, "yaw_deg_per_m": 0.9, "yaw_std": 0.05, "stretches": 120,
         "distance_m": 240.0, "off": True,
         "corrected": {"scale": 1.049, "scale_std": 0.004, "yaw_deg_per_m": 0.95, "yaw_std": 0.1, "stretches": 110,
                       "distance_m": 220.0, "off": True, "blind_share": 0.093}}
    text = "\n".join(odometer_text(m))
    assert "raw odometry measures 5.2 % long" in text and "wheel radii" in text
    assert "a first pass found it 4.9 % long" in text and "110 straight stretches" in text
    assert "9 % of its scan matches" in text
    online = {**m, "corrected": {**m["corrected"], "nodes": 2500}}
    assert "local SLAM's check at matched node 2500 found it 4.9 % long" in "\n".join(odometer_text(online))


def test_the_correction_settings_refuse_what_cannot_work():
    with pytest.raises(ValueError, match="min_stretches"):
        OdometerCorrectionConfig(min_stretches=3)
    with pytest.raises(ValueError, match="blind_ratio"):
        OdometerCorrectionConfig(blind_ratio=1.0)


def test_the_watch_checks_local_slams_nodes_as_the_anchors_place_them_now():
    # a robot driving 60 m straight at 0.2 m a node, the matches of nodes 100-129 blind, with an odometer 4 % long;
    # its nodes in two submaps whose anchors the estimate places 30 m apart (submap 1 starts at node 150)
    n = 300
    x = np.arange(n) * 0.2
    odo = np.column_stack([1.04 * x, np.zeros(n), np.zeros(n)])
    stamps = np.arange(n, dtype=np.int64) * 200_000_000
    watch = OdometerWatch(OdometerCorrectionConfig(check_every_nodes=50), stamps, odo)
    est = np.array([[0.0, 0.0, 0.0], [30.0, 0.0, 0.0]])
    found = []
    for k in range(n):
        sub = int(k >= 150)
        if watch.add(int(stamps[k]), sub, np.array([x[k] - 30.0 * sub, 0.0, 0.0]), 100 <= k < 130):
            found.append((k + 1, watch.check(est)))
    assert [k for k, _ in found] == [50, 100, 150, 200, 250, 300]
    hits = [(k, f) for k, f in found if f is not None]
    # 20 straight 2 m stretches take 40 m: from the check at node 250 on (200 nodes span 39.8 m)
    assert hits and hits[0][0] == 250 and hits[0][1].bias.scale == pytest.approx(1.04, abs=1e-6)
    assert watch.blind_share == pytest.approx(0.1)
    assert list(watch.blind_stamps_ns) == list(stamps[100:130])  # the front end's record for the later checks
    # a submap whose anchor is not in the estimate yet: its nodes wait (no stretch through them)
    assert watch.check(est[:1]) is None
