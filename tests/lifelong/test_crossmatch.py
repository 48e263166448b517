"""Cross-session closures of a placed session (``crossmatch.session_closures``: the run's loop search from its
keyframes into the stored submaps near them) and the relative poses kept through retired submaps
(``joint.composed_factors``)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from holoslam import geometry as g
from holoslam.lifelong.crossmatch import path_from, session_closures
from holoslam.lifelong.joint import composed_factors, working_factors
from holoslam.store.records import StoredFactors
from tests.test_relocalise import L_ROOM, _stored, _wall_points


def _session(walls, wTs, sTa, aTb):
    """Session submaps of ``walls`` at wTs ∘ sTa: keyframes at ``aTb`` seeing every wall, and the grid."""
    subs = []
    for T in sTa:
        wTn = g.compose(wTs, T)
        wTb = g.compose(np.broadcast_to(wTn, aTb.shape), aTb)
        scans = tuple(g.transform_points(g.inverse(b), _wall_points(walls)) for b in wTb)
        st = _stored(walls, wTn, 0)
        subs.append(SimpleNamespace(scan_points=scans, aTb=aTb, cov_aTb=np.array([np.eye(3) * 1e-6] * len(aTb)),
                                    prob=st.prob, origin=st.origin, resolution=st.resolution, known=st.known))
    return subs


def test_keyframes_close_on_the_stored_submaps_near_them():
    stored = [_stored(L_ROOM, np.array([1.0, 0.5, 0.3]), 1), _stored(L_ROOM, np.array([4.0, 1.0, -1.0]), 2),
              _stored(L_ROOM, np.array([40.0, 40.0, 0.0]), 3)]  # the third far away: never searched
    wTs = np.array([2.0, 1.5, 1.1])
    sTa = np.array([[0.0, 0.0, 0.0], [0.5, 0.2, 0.3]])
    aTb = np.array([[0.0, 0.0, 0.0], [0.4, 0.3, 0.2], [0.8, 0.1, -0.3], [1.0, 1.0, 0.5]])
    subs = _session(L_ROOM, wTs, sTa, aTb)
    off = g.compose(wTs, np.array([0.12, -0.08, math.radians(1.5)]))  # the hypothesis 14 cm / 1.5 deg off
    ms = session_closures(subs, sTa, stored, off, every_nodes=2)
    pairs = sorted({(m.new, m.old) for m in ms})
    assert pairs == [(0, 1), (0, 2), (1, 1), (1, 2)]
    assert len(ms) == 8  # keyframes 0 and 2 of each submap, each into both stored submaps
    for m in ms:  # each closure implies the true transform, not the hypothesis it started from
        assert np.hypot(*(m.wTs[:2] - wTs[:2])) < 0.03 and abs(g.wrap(m.wTs[2] - wTs[2])) < math.radians(0.5)
        truth = g.between(stored[[1, 2].index(m.old)].wTa, g.compose(wTs, sTa[m.new]))
        assert np.hypot(*(m.oTn[:2] - truth[:2])) < 0.03
    # the join's own matches count against the loop search's closures per pair (max_per_pair: 4)
    joined = [ms[0]] * 4
    again = session_closures(subs, sTa, stored, off, every_nodes=2, already=joined)
    assert (ms[0].new, ms[0].old) not in {(m.new, m.old) for m in again} and len(again) == 6


def test_a_join_one_bay_along_settles_where_the_closures_and_the_map_agree():
    from holoslam.lifelong.crossmatch import settle_join
    from holoslam.relocalise import Hypothesis

    stored = [_stored(L_ROOM, np.array([1.0, 0.5, 0.3]), 1), _stored(L_ROOM, np.array([4.0, 1.0, -1.0]), 2)]
    wTs = np.array([2.0, 1.5, 1.1])
    sTa = np.array([[0.0, 0.0, 0.0], [0.5, 0.2, 0.3], [1.5, -0.5, -0.4]])
    aTb = np.array([[0.0, 0.0, 0.0], [0.4, 0.3, 0.2], [0.8, 0.1, -0.3], [1.0, 1.0, 0.5]])
    subs = _session(L_ROOM, wTs, sTa, aTb)
    off = g.compose(wTs, np.array([0.6, 0.0, 0.0]))  # the global matches agreed 0.6 m along
    h0 = Hypothesis(off, np.eye(3) * 1e-3, 3, True, "3 matches")
    h, closures, note = settle_join(subs, sTa, stored, h0, every_nodes=1)
    assert h is not h0 and "moved 0.6" in note and h.why.startswith("3 matches; moved")
    assert np.hypot(*(h.wTs[:2] - wTs[:2])) < 0.03 and abs(g.wrap(h.wTs[2] - wTs[2])) < math.radians(0.5)
    assert len(closures) >= 6 and all(np.hypot(*(m.wTs[:2] - wTs[:2])) < 0.05 for m in closures)
    # at the right place it stays, and a margin no group can beat keeps any hypothesis where it is
    h_right = Hypothesis(wTs, np.eye(3) * 1e-3, 3, True, "3 matches")
    assert settle_join(subs, sTa, stored, h_right, every_nodes=1)[0] is h_right
    assert settle_join(subs, sTa, stored, h0, every_nodes=1, margin=1.0)[0] is h0


def _factors(rows):
    return StoredFactors(np.arange(len(rows)), np.ones(len(rows), np.int64), np.array([r[0] for r in rows]),
                         np.array([r[1] for r in rows]), np.array([r[2] for r in rows], float),
                         np.array([np.diag(r[3]) for r in rows], float), np.array(["scan_match"] * len(rows), object))


def test_relative_poses_through_retired_submaps_are_kept_composed():
    A, B, C = np.array([1.0, 0.0, 0.1]), np.array([0.9, 0.2, -0.3]), np.array([1.2, -0.1, 0.2])
    s = [1e-4, 1e-4, 1e-6]
    rows = [(1, 2, A, s), (2, 3, B, s), (3, 4, C, s), (4, 5, A, s),
            (2, 3, B + 0.3, [1e-2, 1e-2, 1e-4]),  # a less certain factor of the same pair: not on the path
            (9, 8, A, s)]  # retired 8 and 9 touch no working submap: nothing composed
    f = _factors(rows)
    c = composed_factors(f, np.array([1, 4, 5]))
    assert c.i.tolist() == [1] and c.j.tolist() == [4] and c.kind.tolist() == ["composed"]
    np.testing.assert_allclose(c.iTj[0], g.compose(g.compose(A, B), C), atol=1e-12)
    assert 3e-4 < np.trace(c.cov_iTj[0][:2, :2]) < 3e-3  # three steps' variance and the headings' lever arms
    # a factor stored j -> i is inverted on the way
    rev = _factors([(2, 1, g.inverse(A), s), (2, 3, B, s)])
    np.testing.assert_allclose(composed_factors(rev, np.array([1, 3])).iTj[0], g.compose(A, B), atol=1e-12)
    w = working_factors(f, np.array([1, 4, 5]))
    assert sorted(zip(w.i.tolist(), w.j.tolist(), strict=True)) == [(1, 4), (4, 5)]
    assert len(working_factors(f, np.array([1, 4, 5]), compose=False)) == 1
    assert len(composed_factors(f, np.array([1, 4, 5]), kinds=("loop", "cross"))) == 0  # only a session's chain


def test_far_along_the_session_from_where_it_was_placed_windows_and_agreement_grow():
    """A session is rigid only to its own drift: its submap 1.3 m from where the join's transform puts it (the far
    end of aces' second third from the submaps that placed it) is found in a window grown by the path from them
    (``path_from``, at ``LoopConfig.window_rate``), not in the 1 m window right after a closure."""
    stored = [_stored(L_ROOM, np.array([1.0, 0.5, 0.3]), 1), _stored(L_ROOM, np.array([4.0, 1.0, -1.0]), 2)]
    wTs = np.array([2.0, 1.5, 1.1])
    sTa = np.array([[0.0, 0.0, 0.0], [0.5, 0.2, 0.3]])
    aTb = np.array([[0.0, 0.0, 0.0], [0.4, 0.3, 0.2], [0.8, 0.1, -0.3], [1.0, 1.0, 0.5]])
    subs = _session(L_ROOM, wTs, sTa, aTb)
    off = g.compose(wTs, np.array([1.0, -0.85, math.radians(2.0)]))  # 1.3 m / 2 deg off
    assert session_closures(subs, sTa, stored, off, every_nodes=2, path_m=np.zeros(2)) == []
    far = session_closures(subs, sTa, stored, off, every_nodes=2, path_m=np.full(2, 40.0))
    assert len(far) >= 4
    for m in far:  # each implies the true transform
        assert np.hypot(*(m.wTs[:2] - wTs[:2])) < 0.03 and abs(g.wrap(m.wTs[2] - wTs[2])) < math.radians(0.5)


def test_the_path_from_the_placing_submaps_runs_along_the_chain_and_through_loops():
    sTa = np.column_stack([np.arange(5.0), np.zeros(5), np.zeros(5)])  # 1 m apart
    assert np.allclose(path_from(sTa, [4]), [4, 3, 2, 1, 0])
    loop = SimpleNamespace(i=np.array([0]), j=np.array([4]), kind=np.array(["loop"], object))
    assert np.allclose(path_from(sTa, [4], loop), [0, 1, 2, 1, 0], atol=1e-6)
    assert np.allclose(path_from(sTa, []), 0.0)
