"""Furniture moved between simulated days: a free-standing piece lands on a free place of its room (no wall, no
other piece, no doorway under it), the route still drives, the labels on it move with it and are the day's
"moved" changes, and days.json holds the footprints."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from holoslam.sim import furniture_moves as fm
from holoslam.sim.days import MIN_MOVE_M, MIN_SPACING_M, MOVED_M, household_days, simulate_days
from holoslam.sim.route import household_trajectory
from holoslam.sim.world import free_space, reference_household


def _to_edges(pts, A) -> float:
    """The smallest distance from the points (N, 2) to the edges of the closed polygon A."""
    a, b = A, np.roll(A, -1, axis=0)
    t = np.clip((((pts[:, None] - a) * (b - a)).sum(-1)) / ((b - a) ** 2).sum(-1), 0, 1)
    return float(np.hypot(*(pts[:, None] - (a + t[..., None] * (b - a))).transpose(2, 0, 1)).min())


def _gap(P, Q) -> float:
    """Distance between two convex polygons (0 when they overlap): a separating axis, then vertex-edge distances."""
    P, Q = np.asarray(P, float), np.asarray(Q, float)
    for A in (P, Q):
        e = np.roll(A, -1, axis=0) - A
        for n in np.column_stack([e[:, 1], -e[:, 0]]):
            if (P @ n).max() < (Q @ n).min() or (Q @ n).max() < (P @ n).min():
                return min(_to_edges(P, Q), _to_edges(Q, P))
    return 0.0


@pytest.fixture(scope="module")
def days():
    return household_days(10, seed=2)  # seed 2: 11 pieces moved over the ten days (chairs, the lamp)


def test_moved_furniture_lands_free_in_its_room(days):
    moves = [m for d in days for m in d.furniture]
    assert len(moves) >= 6 and {m.name for m in moves} <= set(fm.MOVABLE)
    for before, day in zip(days, days[1:], strict=False):
        for m in day.furniture:
            P, Q = np.asarray(m.before), np.asarray(m.after)
            # the same piece, turned and shifted: edge lengths kept (to the mm the corners are rounded to)
            np.testing.assert_allclose(np.hypot(*np.diff(P, axis=0, append=P[:1]).T),
                                       np.hypot(*np.diff(Q, axis=0, append=Q[:1]).T), atol=3e-3)
            assert m.shift_m >= MIN_MOVE_M and math.dist(P.mean(0), Q.mean(0)) == pytest.approx(m.shift_m, abs=2e-3)
            room = next(r for r in day.world.rooms if r.name == m.room)
            assert Q[:, 0].min() >= room.xmin + fm.WALL_GAP_M - 1e-3 and Q[:, 0].max() <= room.xmax - fm.WALL_GAP_M + 1e-3
            assert Q[:, 1].min() >= room.ymin + fm.WALL_GAP_M - 1e-3 and Q[:, 1].max() <= room.ymax - fm.WALL_GAP_M + 1e-3
            for f in day.world.furniture:
                if f.name != m.name:  # checked on a 2 cm raster: a corner may come up to ~5 mm closer
                    assert _gap(Q, f.polygon) >= fm.FURNITURE_GAP_M - 0.006, (day.day, m.name, f.name)
            for dw in day.world.doorways:
                assert _to_edges(np.array([dw.centre]), Q) >= fm.DOOR_CLEAR_M - 0.01
            assert next(f for f in before.world.furniture if f.name == m.name).polygon == m.before
            assert next(f for f in day.world.furniture if f.name == m.name).polygon == m.after


def test_labels_move_with_their_furniture(days):
    for before, day in zip(days, days[1:], strict=False):
        carried = {c.object_id: c for c in day.changes if c.furniture is not None}
        assert len(carried) == sum(len(m.objects) for m in day.furniture)
        for m in day.furniture:
            P, Q = np.asarray(m.before), np.asarray(m.after)
            R = np.array([[math.cos(m.turn_rad), -math.sin(m.turn_rad)], [math.sin(m.turn_rad), math.cos(m.turn_rad)]])
            for oid in m.objects:
                o0, o1 = before.world.object(oid), day.world.object(oid)
                expect = (np.array(o0.position[:2]) - P.mean(0)) @ R.T + Q.mean(0)
                np.testing.assert_allclose(o1.position[:2], expect, atol=3e-3)  # rigidly with the piece
                assert o1.position[2] == o0.position[2] and o1.furniture == m.name
                assert math.cos(o1.label_yaw - o0.label_yaw - m.turn_rad) > 1 - 1e-9
                c = carried[oid]
                assert c.kind == "moved" and c.before == o0.position and c.after == o1.position
                assert math.dist(c.before[:2], c.after[:2]) >= MIN_MOVE_M > MOVED_M
        # no label changed twice in a day, and the carried labels keep their distance from the others
        ids = [c.object_id for c in day.changes]
        assert len(ids) == len(set(ids))
        xy = np.array([o.position[:2] for o in day.world.objects])
        for oid in carried:
            k = [o.object_id for o in day.world.objects].index(oid)
            assert np.delete(np.hypot(*(xy - xy[k]).T), k).min() >= MIN_SPACING_M - 1e-9


def test_the_robot_still_drives_and_starts_free(days):
    for day in days[1:]:
        if not day.furniture:
            continue
        fs = free_space(day.world, resolution=0.05)
        r, c = fs.cell_of(np.array([day.start[:2]]))
        assert fs.standable[r[0], c[0]]
        traj = household_trajectory(day.world, None, start=day.start, rate_hz=2.0)  # one whole tour plans
        r, c = fs.cell_of(traj.wTb[:, :2])
        assert fs.clearance[r, c].min() >= 0.2  # never inside furniture (the planned clearance, smoothed)


def test_the_furniture_has_its_own_random_stream():
    still = household_days(5, seed=1, furniture=(0, 0))
    assert not any(d.furniture for d in still)
    assert all(d.world.furniture == reference_household().furniture for d in still)
    moved = household_days(5, seed=1)
    first = next(d.day for d in moved if d.furniture)
    assert first == 4  # seed 1 moves its first piece before day 4: days 2 and 3 are those of a home left as it was
    for a, b in zip(still[: first - 1], moved[: first - 1], strict=True):
        assert a.changes == b.changes and a.start == b.start and a.world == b.world


def test_days_json_holds_the_moved_furniture(tmp_path):
    out = simulate_days(tmp_path, 2, seed=2, duration_s=3.0, furniture=(1, 1))
    truth = json.loads((tmp_path / "days.json").read_text())
    assert truth["furniture_moves"] == [1, 1] and truth["days"][0]["furniture"] == []
    (m,) = truth["days"][1]["furniture"]
    assert m == out["days"][1]["furniture"][0] and len(m["before"]) == len(m["after"]) == 4
    assert m["shift_m"] >= MIN_MOVE_M and m["objects"]
    moved = {c["id"]: c for c in truth["days"][1]["changes"] if c.get("with") == m["name"]}
    assert set(moved) == set(m["objects"])
    assert all(truth["days"][1]["objects"][k] == c["after"] for k, c in moved.items())


def test_the_command_line_moves_furniture(tmp_path, capsys):
    from holoslam.cli import main

    assert main(["simulate", "--days", "2", "--duration", "3", "--seed", "2", "--furniture", "1", "1",
                 "-o", str(tmp_path / "d")]) == 0
    out = capsys.readouterr().out
    assert "day 2:" in out and " moved " in out and " deg" in out
    assert json.loads((tmp_path / "d" / "days.json").read_text())["furniture_moves"] == [1, 1]
    assert main(["simulate", "--days", "2", "--furniture", "2", "1", "-o", str(tmp_path / "e")]) != 0
