"""benchmarks/relation_scans.py, the check of a benchmark relation against its two scans: its ICP recovers a
known motion of a real scan, and its fit rejects a pose 0.3 m across a corridor but hardly one 0.3 m along it."""

from __future__ import annotations

import numpy as np
import pytest
from repo_paths import SHARED, benchmark_module

LOG = SHARED / "realdata" / "aces.mcap"


@pytest.mark.skipif(not LOG.is_file(), reason="the shared real logs are absent")
def test_icp_recovers_a_known_motion_of_a_real_scan_and_the_fit_sees_the_corridor():
    from holoslam.io.mcap import read_log

    rs = benchmark_module("relation_scans")
    log, _ = read_log(LOG)
    a_pts, _stamp = rs.scan_points(log, 1037.06)
    aTb = np.array([0.30, -0.05, np.radians(4.0)])
    c, s = np.cos(aTb[2]), np.sin(aTb[2])
    b_pts = (a_pts - aTb[:2]) @ np.array([[c, -s], [s, c]])  # a's points in b's frame (b = a moved by aTb)
    assert np.allclose(rs.transform(aTb, b_pts), a_pts)
    found = rs.icp(a_pts, b_pts, aTb + np.array([0.15, 0.05, np.radians(2.0)]))
    assert np.hypot(*(found[:2] - aTb[:2])) < 0.01 and abs(found[2] - aTb[2]) < np.radians(0.2)
    med_right, share_right = rs.fit(a_pts, b_pts, aTb)
    assert med_right < 1e-9 and share_right == 1.0
    # the scan is a corridor along x: 0.3 m across it fits nowhere, 0.3 m along it still fits most points (what
    # makes a relation there uncertain, and the reason to look at several starts)
    med_across, share_across = rs.fit(a_pts, b_pts, aTb + np.array([0.0, 0.3, 0.0]))
    med_along, share_along = rs.fit(a_pts, b_pts, aTb + np.array([0.3, 0.0, 0.0]))
    assert med_across > 0.2 and share_across < 0.05
    assert 0.01 < med_along < 0.05 and 0.5 < share_along < 0.9
