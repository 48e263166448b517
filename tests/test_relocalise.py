"""Global relocalisation: the SE(2) fit, object hypotheses (known identities, a moved object as an outlier, too
few objects not verified) and the laser's global branch and bound over synthetic rooms (an L-shaped room found
from another frame at any heading; a room of another building not joined)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from holoslam import geometry as g
from holoslam.relocalise import (
    RelocaliseConfig,
    fit_se2,
    global_match,
    laser_hypothesis,
    laser_matches,
    object_hypothesis,
    relocalise,
)
from holoslam.store.records import StoredSubmap

L_ROOM = [(0, 0, 6, 0), (6, 0, 6, 3), (6, 3, 3, 3), (3, 3, 3, 5), (3, 5, 0, 5), (0, 5, 0, 0), (1.0, 1.0, 1.6, 1.0),
          (1.6, 1.0, 1.6, 1.8)]
OTHER_ROOM = [(0, 0, 4, 0), (4, 0, 4, 4), (4, 4, 0, 4), (0, 4, 0, 0), (2.0, 2.0, 2.5, 2.5)]


def _wall_points(walls, step=0.05):
    pts = []
    for x0, y0, x1, y1 in walls:
        n = max(2, int(math.hypot(x1 - x0, y1 - y0) / step))
        t = np.linspace(0, 1, n)
        pts.append(np.column_stack([x0 + t * (x1 - x0), y0 + t * (y1 - y0)]))
    return np.vstack(pts)


def _stored(walls, wTa, sid, res=0.05):
    """A stored submap of ``walls`` (world) in the frame of an anchor at ``wTa``: walls 0.9, the rest 0.1."""
    a = g.transform_points(g.inverse(wTa), _wall_points(walls, res / 2))
    origin = a.min(axis=0) - 0.5
    shape = (np.ceil((a.max(axis=0) - origin + 0.5) / res)).astype(int)
    prob = np.full((shape[1], shape[0]), 0.1, np.float32)
    c = ((a - origin) / res).astype(int)
    prob[c[:, 1], c[:, 0]] = 0.9
    return StoredSubmap(sid, 1, sid, 0, np.asarray(wTa, float), None, np.asarray(wTa, float),
                        (float(origin[0]), float(origin[1])), res, None, prob, None, np.ones_like(prob, bool))


def test_fit_se2_recovers_a_transform():
    rng = np.random.default_rng(1)
    for _ in range(20):
        T = np.array([*rng.uniform(-5, 5, 2), rng.uniform(-math.pi, math.pi)])
        s = rng.uniform(-3, 3, (6, 2))
        np.testing.assert_allclose(fit_se2(s, g.transform_points(T, s)), T, atol=1e-9)


def test_objects_give_a_verified_hypothesis_with_a_moved_one_left_out():
    rng = np.random.default_rng(2)
    wTs = np.array([3.0, -2.0, 2.5])
    world = {f"O{k:02d}": rng.uniform(0, 8, 2) for k in range(1, 7)}
    session = {k: g.transform_points(g.inverse(wTs), v[None])[0] + rng.normal(0, 0.01, 2) for k, v in world.items()}
    session["O03"] = session["O03"] + np.array([1.0, 0.0])  # moved since
    h = object_hypothesis(session, world)
    assert h is not None and h.verified and h.support == 5 and "O03" not in h.members
    assert np.hypot(*(h.wTs[:2] - wTs[:2])) < 0.03 and abs(g.wrap(h.wTs[2] - wTs[2])) < math.radians(1)
    two = {k: session[k] for k in ("O01", "O02")}
    h2 = object_hypothesis(two, world)
    assert h2 is not None and not h2.verified and "needs 3" in h2.why
    assert object_hypothesis({"X": np.zeros(2)}, world) is None


@pytest.mark.parametrize("theta", [0.4, -2.9])
def test_the_global_search_finds_a_room_at_any_heading(theta):
    wTa = np.array([1.0, 0.5, 0.3])
    stored = _stored(L_ROOM, wTa, 1)
    wTn = np.array([2.0, 1.5, theta])  # the session's submap anchor in the world
    pts = g.transform_points(g.inverse(wTn), _wall_points(L_ROOM))
    m = global_match(stored, pts, RelocaliseConfig())
    assert m is not None
    oTn, _cov, score = m
    truth = g.between(wTa, wTn)
    assert score > 0.8
    assert np.hypot(*(oTn[:2] - truth[:2])) < 0.05 and abs(g.wrap(oTn[2] - truth[2])) < math.radians(1)


def test_laser_matches_verify_a_session_and_refuse_another_building():
    stored = [_stored(L_ROOM, np.array([1.0, 0.5, 0.3]), 1), _stored(L_ROOM, np.array([4.0, 1.0, -1.0]), 2),
              _stored(L_ROOM, np.array([0.5, 3.0, 2.0]), 3)]
    wTs = np.array([2.0, 1.5, 1.1])  # the session's anchors stand in the room
    sTa = np.array([[0.0, 0.0, 0.0], [0.5, 0.2, 0.3]])
    subs = [SimpleNamespace(points=g.transform_points(g.inverse(g.compose(wTs, T)), _wall_points(L_ROOM)))
            for T in sTa]
    cfg = RelocaliseConfig(enough_consistent=0)
    ms, n = laser_matches(subs, sTa, stored, cfg)
    assert n == 6 and len(ms) == 6
    h = laser_hypothesis(ms, cfg)
    assert h is not None and h.verified and h.support == 6
    assert np.hypot(*(h.wTs[:2] - wTs[:2])) < 0.05 and abs(g.wrap(h.wTs[2] - wTs[2])) < math.radians(1)
    other = [SimpleNamespace(points=g.transform_points(g.inverse(T), _wall_points(OTHER_ROOM))) for T in sTa]
    r = relocalise(other, sTa, {}, stored, {}, cfg)
    assert not r.placed and r.joined_by == "none" and "no verified hypothesis" in r.why


def test_a_placed_session_is_matched_locally_into_the_nearest_stored_submaps():
    from holoslam.relocalise import local_matches

    stored = [_stored(L_ROOM, np.array([1.0, 0.5, 0.3]), 1), _stored(L_ROOM, np.array([4.0, 1.0, -1.0]), 2),
              _stored(L_ROOM, np.array([30.0, 30.0, 0.0]), 3)]  # the third far away: not searched
    wTs = np.array([2.0, 1.5, 1.1])
    sTa = np.array([[0.0, 0.0, 0.0], [0.5, 0.2, 0.3]])
    subs = [SimpleNamespace(points=g.transform_points(g.inverse(g.compose(wTs, T)), _wall_points(L_ROOM)))
            for T in sTa]
    off = g.compose(wTs, np.array([0.12, -0.08, math.radians(1.5)]))  # the hypothesis 14 cm / 1.5 deg off
    ms = local_matches(subs, sTa, stored, off, RelocaliseConfig())
    assert sorted((m.new, m.old) for m in ms) == [(0, 1), (0, 2), (1, 1), (1, 2)]
    for m in ms:  # each match implies the true transform, not the hypothesis it started from
        assert np.hypot(*(m.wTs[:2] - wTs[:2])) < 0.03 and abs(g.wrap(m.wTs[2] - wTs[2])) < math.radians(0.5)
    assert local_matches(subs, sTa, stored, off, RelocaliseConfig(close_per_submap=0)) == []


def _session_submap(walls, wTn, res=0.05):
    """A session submap of ``walls`` (world) anchored at ``wTn``: its grid (``_stored``'s) and its anchor scan."""
    st = _stored(walls, wTn, 0, res)
    return SimpleNamespace(prob=st.prob, origin=st.origin, resolution=st.resolution, known=st.known,
                           points=g.transform_points(g.inverse(wTn), _wall_points(walls)))


# a corridor with bays: a door recess every 2 m on one side, one wider bay at the end (what tells them apart)
CORRIDOR = [(0, 0, 14, 0), (0, 2, 14, 2), (14, 0, 14, 2), (0, 0, 0, 2)] + [
    (x, 2, x, 2.6) for x in (2.0, 2.8, 4.0, 4.8, 6.0, 6.8, 8.0, 8.8, 10.0, 11.6)]


def test_the_map_check_refuses_a_join_one_bay_along():
    from holoslam.relocalise import join_agreement

    stored = [_stored(CORRIDOR, np.array([x, 1.0, 0.0]), k + 1) for k, x in enumerate((1.0, 5.0, 9.0, 13.0))]
    wTs = np.array([3.0, 1.0, 0.0])
    sTa = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [8.0, 0.0, 0.0]])
    subs = [_session_submap(CORRIDOR, g.compose(wTs, T)) for T in sTa]
    cfg = RelocaliseConfig()
    right = join_agreement(subs, sTa, stored, wTs, [0], cfg)
    assert right is not None and right.fraction > 0.97 and right.verdict(cfg.verify) is True
    wrong = join_agreement(subs, sTa, stored, g.compose(wTs, np.array([2.0, 0.0, 0.0])), [0], cfg)
    assert wrong is not None and wrong.fraction < 0.9 and wrong.verdict(cfg.verify) is False
    bare = [SimpleNamespace(points=s.points) for s in subs]  # no grids: no verdict
    assert join_agreement(bare, sTa, stored, wTs, [0], cfg) is None


def test_a_refused_group_gives_way_to_the_next_verified_one():
    from holoslam.relocalise import LaserMatch, checked_hypothesis

    stored = [_stored(CORRIDOR, np.array([x, 1.0, 0.0]), k + 1) for k, x in enumerate((1.0, 5.0, 9.0, 13.0))]
    wTs = np.array([3.0, 1.0, 0.0])
    sTa = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [8.0, 0.0, 0.0]])
    subs = [_session_submap(CORRIDOR, g.compose(wTs, T)) for T in sTa]
    alias = g.compose(wTs, np.array([2.0, 0.0, 0.0]))

    def match(k, T):
        return LaserMatch(k, 1, np.zeros(3), np.eye(3) * 1e-4, 0.7, np.asarray(T, float))

    ms = [match(k % 3, alias) for k in range(5)] + [match(k % 3, wTs) for k in range(3)]
    cfg = RelocaliseConfig(runner_up_ratio=0.7)
    h, notes = checked_hypothesis(ms, subs, sTa, stored, cfg)
    assert len(notes) == 1 and "refused by the map check" in notes[0] and "5 matches" in notes[0]
    assert h is not None and h.verified and h.support == 3 and np.allclose(h.wTs, wTs)
    assert "map check" in h.why
    h_off, notes_off = checked_hypothesis(ms, subs, sTa, stored, RelocaliseConfig(runner_up_ratio=0.7,
                                                                                  verify_joins=False))
    assert notes_off == [] and h_off is not None and np.allclose(h_off.wTs, alias)
