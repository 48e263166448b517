"""Why each false or missed change of a ``bench_lifelong.py --parts sim`` run happened, from its output folder
(``--out DIR``: ``sim/days.json``, ``sim/sim_detail.json``, ``sim/home.holomap`` and the day logs).

    .venv/bin/python benchmarks/lifelong_misses.py DIR

First every error against the observable truth (``lifelong_truth.py``, what the issue's goal is judged on).
Then per day and object, what the robot could have known (the simulator's raw truth against the store):

- a **moved** object called gone or not reported: the seconds of the day in which the simulated camera could have
  photographed it at its new place (``bench_lifelong._photographable_s`` on that day's home: within 3.5 m, facing
  within 60 deg, nothing in between, within the zoom); 0 means nothing of the day could have found it;
- a **gone** that was wrong (the object still at its place) and a removal missed: the store's camera time in view
  and the images that held the place readable (what ``changes.classify`` decided on), and for a present object
  the angle between the direction the store saw its label from (``ObjectState.view``, the mean over its
  sightings) and the label's true normal, the stored normal's error (``ObjectState.normal``, from the readings'
  PnP poses) and its sigma, and the largest angle from the true normal of the robot poses the view test counted
  (the simulated camera reads to 60 deg); whether the session's laser saw the thing it was on gone
  (``support``);
- **new**: for every object first located after day 1 (added or not), the images of each earlier session that
  held its place readable (``frustum.covering_images``), and the seconds the robot had it in view
  (``changes.in_view_seconds``, unshared): whether an earlier session could tell "there all along" from "added".
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def _world_angle(w2m: list, vec: np.ndarray | None) -> float:
    """A store-world direction's angle in the simulator's map frame (deg)."""
    return float("nan") if vec is None else math.degrees(math.atan2(vec[1], vec[0]) + w2m[2])


def _diff(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


def _observable_errors(out: Path, truth: dict, detail: list, worlds: list) -> None:
    """Every false and missed change against the observable truth (``lifelong_truth``: labels read in the day's
    images, places photographable), the goal's truth; computed when the run's ``sim_detail.json`` predates it."""
    from lifelong_truth import camera_positions, observable_truth

    if all(x.get("truth_rule") == "read" for x in detail):
        obs = [x["truth_observable"] for x in detail]
    else:  # a run scored before the read rule: its stored truth_observable is the photographable rule's
        days = truth["days"][: len(detail)]
        obs = observable_truth({**truth, "days": days}, worlds[: len(days)],
                               [camera_positions(out / d["log"]) for d in days]).days
    print("errors against the observable truth (day object: truth -> detected)")
    for x, t in zip(detail, obs, strict=True):
        det = x["detected"]
        for oid in sorted(set(t) | {o for o, v in det.items() if v in ("moved", "gone", "new")}):
            if t.get(oid) != det.get(oid) and (oid in t or det.get(oid) != "seen"):
                print(f"  day {x['day']:>2} {oid}: {t.get(oid)} -> {det.get(oid)} (raw truth {x['truth'].get(oid)})")


def _moved_misses(out: Path, truth: dict, detail: list, worlds: list) -> None:
    from bench_lifelong import _photographable_s

    print("moved objects called gone or not reported: seconds the new place could be photographed that day")
    for x, d in zip(detail, truth["days"], strict=True):
        for oid, kind in sorted(x["truth"].items()):
            if kind == "moved" and x["detected"].get(oid) != "moved":
                s = _photographable_s(worlds[d["day"] - 1], oid, out / d["log"])
                print(f"  day {d['day']:>2} {oid}: detected {x['detected'].get(oid)}, photographable {s:.1f} s")


def _gone_misses(truth: dict, detail: list, worlds: list, hist: dict, trajs: dict, merged) -> None:
    from holoslam.lifelong.changes import ChangeConfig, _thin, in_view_mask

    w2m = truth["days"][0]["start_pose"]
    print("wrong or missed gone: camera s in view, images holding the place; a present object's label normal "
          "against the direction the store saw it from and the poses in view")
    for x, d in zip(detail, truth["days"], strict=True):
        for oid, s in sorted(x["unseen_in_view_s"].items()):
            gone, absent = x["detected"].get(oid) == "gone", oid not in d["objects"]
            if gone == absent:
                continue
            row = f"  day {d['day']:>2} {oid}: {'gone, present' if gone else 'absent, not gone'}, in view {s} s, " \
                  f"images {x['unseen_in_images'].get(oid)}, support left {oid in x.get('unseen_support_left', ())}"
            prev = [h for h in hist.get(oid, ()) if h.session_id < d["day"] and h.w_xy is not None]
            if gone and prev and (prev[-1].view is not None or prev[-1].normal is not None) \
                    and oid not in x["truth"]:  # at its place
                p = prev[-1]
                normal = math.degrees(worlds[d["day"] - 1].object(oid).label_yaw)
                t, wTb, _ = trajs[d["day"]]
                tt, xy = _thin(t, wTb[:, :2], ChangeConfig().view_step_s)
                m = in_view_mask(p.w_xy, p.view, xy, merged, ChangeConfig(), p.normal, p.normal_sigma_rad)
                rel = xy[m] - p.w_xy
                worst = max((_diff(_world_angle(w2m, r), normal) for r in rel), default=float("nan"))
                if p.view is not None:
                    row += f"; seen from {_diff(_world_angle(w2m, p.view), normal):.0f} deg off its normal"
                if p.normal is not None:
                    row += (f"; stored normal {_diff(_world_angle(w2m, p.normal), normal):.1f} deg off the true one "
                            f"(sigma {math.degrees(p.normal_sigma_rad):.1f})")
                row += f", in view up to {worst:.0f} deg from the true normal"
            print(row)


def _new_evidence(out: Path, truth: dict, hist: dict, trajs: dict, merged) -> None:
    from holoslam.io.mcap import read_log
    from holoslam.lifelong.changes import ChangeConfig, in_view_seconds
    from holoslam.lifelong.frustum import camera_views, covering_images, world_cameras

    cams = {}
    for d in truth["days"][:-1]:
        views = camera_views(read_log(out / d["log"])[0])
        t, wTb, _ = trajs[d["day"]]
        cams[d["day"]] = (views, world_cameras(views, t, wTb), t, wTb[:, :2])
    print("objects first located after day 1: earlier sessions' images holding the place / s in view")
    for oid, rows in sorted(hist.items()):
        first = rows[0]
        if first.session_id == 1 or first.w_xy is None:
            continue
        added = any(c["id"] == oid and c["change"] == "added" for d in truth["days"] for c in d["changes"])
        p = np.array([first.w_xy[0], first.w_xy[1], first.z])
        ev = [f"{covering_images(p, first.view, first.payload, v, wTc, merged)}/"
              f"{in_view_seconds(first.w_xy, first.view, t, xy, merged, ChangeConfig()):.0f}"
              for v, wTc, t, xy in (cams[k] for k in range(1, first.session_id))]
        print(f"  day {first.session_id:>2} {oid} {'added' if added else 'there from day 1'}: {' '.join(ev)}")


def main() -> None:
    from holoslam.lifelong.export import merged_map, session_trajectories
    from holoslam.sim.days import household_days
    from holoslam.store.db import MapStore

    out = Path(sys.argv[1]) / "sim"
    truth = json.loads((out / "days.json").read_text())
    detail = json.loads((out / "sim_detail.json").read_text())
    worlds = [d.world for d in household_days(len(truth["days"]), truth["seed"], tuple(truth.get("changes", (5, 10))),
                                              tuple(truth.get("furniture_moves", (0, 0))))]
    with MapStore.open(out / "home.holomap", create=False) as s:
        trajs = session_trajectories(s)
        merged = merged_map(s.submaps(working=True, grids=True))
        hist: dict = {}
        for h in s.object_history():
            hist.setdefault(h.object_id, []).append(h)
    _observable_errors(out, truth, detail, worlds)
    _moved_misses(out, truth, detail, worlds)
    _gone_misses(truth, detail, worlds, hist, trajs, merged)
    _new_evidence(out, truth, hist, trajs, merged)


if __name__ == "__main__":
    main()
