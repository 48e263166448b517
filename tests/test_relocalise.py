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


# Verification by prediction: a room with an identical copy 40 m along x; the session starts in the room and drives
# out along the corridor that leaves the first copy. Around the copy the corridor is another (wider, other bays),
# or, for the tie, the same corridor copied too.
ROOM_COPY = np.array([40.0, 0.0, 0.0])
NEAR_ROOM = L_ROOM + [(6, 1, 24, 1), (6, 3, 24, 3), (24, 1, 24, 3)] + [
    (x, 3, x, 3.4 + 0.3 * k) for k, x in enumerate((8.0, 11.5, 13.0, 17.0, 20.5))]
OTHER_CORRIDOR = [(6, 0.4, 24, 0.4), (6, 4.2, 24, 4.2)] + [(x, 0.4, x, 1.2) for x in (9.0, 14.5, 21.0)]


def _shifted(walls, T):
    return [(*g.transform_points(T, np.array([[a, b]]))[0], *g.transform_points(T, np.array([[c, d]]))[0])
            for a, b, c, d in walls]


def _local_submap(walls, wTa, sid, reach=6.0, res=0.05):
    """A submap of the walls within ``reach`` of its anchor at ``wTa``: a stored record (``sid`` > 0) or a session
    submap (sid 0: its grid and its anchor scan)."""
    pts = _wall_points(walls, res / 2)
    a = g.transform_points(g.inverse(wTa), pts[np.hypot(*(pts - wTa[:2]).T) <= reach])
    origin = a.min(axis=0) - 0.5
    shape = (np.ceil((a.max(axis=0) - origin + 0.5) / res)).astype(int)
    prob = np.full((shape[1], shape[0]), 0.1, np.float32)
    c = ((a - origin) / res).astype(int)
    prob[c[:, 1], c[:, 0]] = 0.9
    st = StoredSubmap(sid, 1, sid, 0, np.asarray(wTa, float), None, np.asarray(wTa, float),
                      (float(origin[0]), float(origin[1])), res, None, prob, None, np.ones_like(prob, bool))
    if sid:
        return st
    return SimpleNamespace(prob=st.prob, origin=st.origin, resolution=st.resolution, known=st.known, points=a)


def _two_rooms(copy_walls):
    """The stored map: the room and its corridor, the room's copy with ``copy_walls`` (in the room's frame)."""
    anchors = [(3.0, 2.0), (10.0, 2.0), (15.0, 2.0), (20.0, 2.0)]
    walls = NEAR_ROOM + _shifted(L_ROOM + copy_walls, ROOM_COPY)
    return [_local_submap(walls, np.array([x + dx, y, 0.0]), 1 + k + 4 * c)
            for c, dx in enumerate((0.0, ROOM_COPY[0])) for k, (x, y) in enumerate(anchors)]


def _corridor_session(wTs):
    """The session: its first submap in the room, four more along the corridor; (submaps, sTa)."""
    wTn = np.array([[3.5, 2.2, 0.1], [8.5, 2.0, 0.0], [12.0, 2.0, 0.05], [16.0, 2.0, 0.0], [19.5, 2.0, -0.03]])
    sTa = g.between(np.broadcast_to(wTs, wTn.shape), wTn)
    return [_local_submap(NEAR_ROOM, T, 0, reach=5.0) for T in wTn], sTa


def _room_matches(wTs, n_true, n_alias):
    """Global matches of the session's first submap (the room) only: ``n_true`` at the room, ``n_alias`` at its
    copy (2 cm / 0.2 deg apart within each)."""
    from holoslam.relocalise import LaserMatch

    def m(old, T, k):
        T = g.compose(T, np.array([0.02 * (k % 2), -0.01 * k, math.radians(0.1 * k)]))
        return LaserMatch(0, old, np.zeros(3), np.eye(3) * 1e-4, 0.7, T)

    alias = g.compose(ROOM_COPY, wTs)
    return [m(1, wTs, k) for k in range(n_true)] + [m(5, alias, k) for k in range(n_alias)]


def test_a_hypothesis_confirmed_by_its_predictions_is_verified_and_the_alias_is_not():
    from holoslam.relocalise import predicted_hypothesis

    wTs = np.array([2.0, -1.0, 0.7])
    subs, sTa = _corridor_session(wTs)
    stored = _two_rooms(OTHER_CORRIDOR)
    ms = _room_matches(wTs, 3, 3)  # the room and its copy: two groups as large, the global test refuses both
    cfg = RelocaliseConfig()
    assert not laser_hypothesis(ms, cfg).verified
    h, preds = predicted_hypothesis(ms, subs, sTa, stored, cfg)
    assert len(preds) == 2
    by_place = {round(float(p.wTs[0])): p for p in preds}
    assert by_place[2].submaps == 4 and by_place[42].submaps == 0 and by_place[42].tested == (1, 2, 3, 4)
    assert h is not None and h.verified and h.support == 3 + len(by_place[2].confirmed)
    assert np.hypot(*(h.wTs[:2] - wTs[:2])) < 0.03 and abs(g.wrap(h.wTs[2] - wTs[2])) < math.radians(0.3)
    assert "confirmed by local matches of 4 further session submaps" in h.why
    assert "the best other group's predictions 0" in h.why
    # the session of another building whose room is the copy's: the predictions fail, not joined
    h2, (p2,) = predicted_hypothesis(_room_matches(wTs, 0, 3), subs, sTa, stored, cfg)
    assert p2.submaps == 0 and p2.tested == (1, 2, 3, 4) and p2.refused and h2 is None
    assert "0 of 4 further session submaps confirmed" in p2.text() and "(refused)" in p2.text()
    h3, _ = predicted_hypothesis(_room_matches(wTs, 0, 3), subs, sTa, stored,
                                 RelocaliseConfig(verify_joins=False))  # without the map check: still not verified
    assert h3 is not None and not h3.verified and "confirmed by local matches of 0 further" in h3.why


def test_two_hypotheses_both_confirmed_stay_unjoined():
    from holoslam.relocalise import predicted_hypothesis

    wTs = np.array([2.0, -1.0, 0.7])
    subs, sTa = _corridor_session(wTs)
    stored = _two_rooms(NEAR_ROOM[len(L_ROOM):])  # the copy has the same corridor: a shifted copy of the place
    h, preds = predicted_hypothesis(_room_matches(wTs, 3, 3), subs, sTa, stored, RelocaliseConfig())
    assert sorted(p.submaps for p in preds) == [4, 4]
    assert h is not None and not h.verified and "the best other group's predictions 4" in h.why
    # too few further submaps: the first two of the corridor only
    h3, _ = predicted_hypothesis(_room_matches(wTs, 3, 0), subs[:3], sTa[:3], _two_rooms(OTHER_CORRIDOR),
                                 RelocaliseConfig())
    assert h3 is not None and not h3.verified and "needs 3 further submaps" in h3.why


def test_relocalise_joins_by_prediction_and_says_so(monkeypatch):
    from holoslam import relocalise as R

    wTs = np.array([2.0, -1.0, 0.7])
    subs, sTa = _corridor_session(wTs)
    stored = _two_rooms(OTHER_CORRIDOR)
    ms = _room_matches(wTs, 3, 3)
    monkeypatch.setattr(R, "laser_matches", lambda *a, **k: (list(ms), 40))
    r = R.relocalise(subs, sTa, {}, stored, {}, RelocaliseConfig())
    assert r.placed and r.joined_by == "laser" and r.why.startswith("laser: verified by prediction: ")
    assert "the global matches alone: 3 consistent laser matches from 1 session submaps" in r.why
    assert np.hypot(*(r.hypothesis.wTs[:2] - wTs[:2])) < 0.03
    assert {m.old for m in r.matches} == {1}  # the cross-session factors: the global matches that agree
    off = R.relocalise(subs, sTa, {}, stored, {}, RelocaliseConfig(predict_min_submaps=0))
    assert not off.placed and "predictions" not in off.why


def test_the_predictions_use_every_third_keyframe():
    from holoslam.relocalise import predicted_hypothesis

    wTs = np.array([2.0, -1.0, 0.7])
    subs, sTa = _corridor_session(wTs)
    # the corridor's submaps: an anchor scan of 10 returns (too few to search), their fourth keyframe 0.4 m on
    # seeing the corridor (its points in the base frame)
    bTk = np.array([0.4, 0.1, 0.05])
    pts = _wall_points(NEAR_ROOM)
    for k in range(1, 5):
        wTk = g.compose(g.compose(wTs, sTa[k]), bTk)
        near = pts[np.hypot(*(pts - wTk[:2]).T) <= 5.0]
        subs[k] = SimpleNamespace(**vars(subs[k]), aTb=np.array([np.zeros(3), [0.1, 0, 0], [0.2, 0, 0], bTk]),
                                  scan_points=(subs[k].points[:10], near[:5], near[:5],
                                               g.transform_points(g.inverse(wTk), near)))
    stored = _two_rooms(OTHER_CORRIDOR)
    h, preds = predicted_hypothesis(_room_matches(wTs, 3, 3), subs, sTa, stored, RelocaliseConfig())
    assert h is not None and h.verified and max(p.submaps for p in preds) == 4
    assert np.hypot(*(h.wTs[:2] - wTs[:2])) < 0.03
    anchor_only, _ = predicted_hypothesis(_room_matches(wTs, 3, 3), subs, sTa, stored,
                                          RelocaliseConfig(predict_keyframe_step=0))
    assert anchor_only is not None and not anchor_only.verified and "of 0 placed near" in anchor_only.why
    # the first keyframe a scan of somewhere else (a 60-point ring): one of the two keyframes near a stored submap
    # matches, half of them: confirmed at the share 0.5, not at 0.75
    ring = 1.5 * np.column_stack([np.cos(np.linspace(0, 6, 60)), np.sin(np.linspace(0, 6, 60))])
    for k in range(1, 5):
        subs[k] = SimpleNamespace(**{**vars(subs[k]), "scan_points": (ring, *subs[k].scan_points[1:])})
    half, _ = predicted_hypothesis(_room_matches(wTs, 3, 3), subs, sTa, stored, RelocaliseConfig())
    assert half is not None and half.verified
    assert "local matches of 4 further session submaps" in half.why
    strict, _ = predicted_hypothesis(_room_matches(wTs, 3, 3), subs, sTa, stored,
                                     RelocaliseConfig(predict_keyframe_share=0.75))
    assert strict is not None and not strict.verified and "local matches of 0 further" in strict.why
