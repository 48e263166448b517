"""Multi-day households: changes between days are real (moved objects land elsewhere, removed ones are gone,
added ones are new ids on free spots), each day starts elsewhere, and days.json holds the truth."""

from __future__ import annotations

import json
import math

import numpy as np

from holoslam.sim.days import MIN_MOVE_M, MIN_SPACING_M, household_days, simulate_days


def test_days_change_the_household_and_start_elsewhere():
    days = household_days(6, seed=4)
    assert [d.day for d in days] == [1, 2, 3, 4, 5, 6] and not days[0].changes
    assert len({d.start for d in days}) == 6
    for before, day in zip(days, days[1:], strict=False):
        own = [c for c in day.changes if c.furniture is None]  # the labels carried with furniture come on top
        assert 4 <= len(own) <= 10  # a change without a free spot is skipped (rarely)
        ids_before = {o.object_id for o in before.world.objects}
        ids_now = {o.object_id: o for o in day.world.objects}
        for c in day.changes:
            if c.kind == "removed":
                assert c.object_id in ids_before and c.object_id not in ids_now
            elif c.kind == "added":
                assert c.object_id not in ids_before and ids_now[c.object_id].position == c.after
            else:
                assert math.dist(c.before[:2], c.after[:2]) >= MIN_MOVE_M
                assert ids_now[c.object_id].position == c.after
        xy = np.array([o.position[:2] for o in day.world.objects])
        d = np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1)) + np.eye(len(xy)) * 9
        moved = {c.object_id for c in day.changes if c.kind in ("moved", "added")}
        for k, o in enumerate(day.world.objects):
            if o.object_id in moved:
                assert d[k].min() >= MIN_SPACING_M - 1e-9
    assert household_days(3, seed=4)[2].changes == days[2].changes  # deterministic


def test_simulated_days_write_logs_and_the_truth(tmp_path):
    out = simulate_days(tmp_path, 2, seed=1, duration_s=4.0)
    truth = json.loads((tmp_path / "days.json").read_text())
    assert truth == json.loads(json.dumps(out))
    assert [d["log"] for d in truth["days"]] == ["day_01.mcap", "day_02.mcap"]
    assert all((tmp_path / d["log"]).stat().st_size > 10_000 for d in truth["days"])
    assert truth["days"][1]["changes"] and truth["days"][1]["start_pose"] != truth["days"][0]["start_pose"]
    assert truth["days"][0]["checked"] == {}  # day 1 has no map to check: the single-day household's camera
    # the robot's map: nothing on day 1; on day 2 the objects day 1's images read (sim.days.robot_map), not the
    # day before's truth (an object never photographed is not known)
    assert truth["days"][0]["remembered"] == []
    first = truth["days"][0]
    assert truth["days"][1]["remembered"] == sorted(set(first["photographed"]) & set(first["objects"]))
