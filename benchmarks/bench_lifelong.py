"""Lifelong household maps (issue 27): relocalisation, joining, object change detection and growth of a map store.

    .venv/bin/python benchmarks/bench_lifelong.py [--parts sim real growth] [--days 10] [--duration S]
        [--furniture LO HI] [--logs intel aces fr079] [--growth-days 30] [--growth-duration S] [--out DIR]

``sim``: ``--days`` simulated days of the household (``holoslam.sim.days``: 5-10 changes a day, a new start
each day), each day's log run into one store (``holoslam.lifelong.session.run_session``, what
``holoslam run LOG --map STORE`` calls). Printed per day: joined / by what, relocalisation s, run s; then the
change detection's precision and recall per kind against three truths, all printed and labelled:

- the **observable truth** (what the issue's goal is judged on; ``lifelong_truth.py`` has the rule and its
  named thresholds): the simulator's changes as the day's camera could observe them, decided from the
  simulator's truth and the day's true trajectory alone. A label is observable on a day when one of the images
  the day's camera took read it (``days.json`` ``photographed``: a label's identity is known only from an image
  that read it); its place is in view when the label standing there was photographable from a true pose of the
  day (every 0.25 s; within the camera's reading limits: facing it within 60 deg in 3-D, tilt within 45 deg,
  modules of 3 px at the full 10x zoom, no wall or furniture as tall as the label between; absence is also seen by
  the laser). An object that moved where no image of the day read it is "gone" that day when its old place was in
  view (not seen although its place was in view), and "moved" against its last known place on the first later
  day an image reads it; a gone (taken away, or moved out of sight) counts on the first day its last known place
  is in view; an added object is "new" on the first day an image reads it;
- the **photographable truth** (the rule before, printed beside it): a label also observable when photographable
  from one true pose of the day, whether or not an image was taken. It called seed 4's ``O35`` (whole tours)
  "moved" on a day it was photographable for 3.5 s and read in none of the day's 115 images;
- the **raw simulator truth**: days.json's changes on their days (moved / gone = removed / new = added).

In each an object the store did not know before and sees for the first time counts as a false "new" unless it
was added. Then the unchanged objects' position RMSE in the world (world -> map by day 1's start pose, the store's frame)
against the same day's single-session result (the session's own solve, moved to the map by the true start
pose), and the joint solve of the last day re-solved by batch LM and by iSAM2 over the whole graph (median of 3,
interleaved, and the largest anchor difference). For every piece of furniture moved before a day
(``holoslam.sim.furniture_moves``), the store's merged map (``holoslam.lifelong.export.merged_map``) before and after
that day's session: the share of the old footprint's edge cells it no longer holds occupied and of the new
footprint's it holds occupied (``holoslam.evaluate_footprints``; the truth put in the store's world by the map's
frame fitted to the unchanged objects so far, as below). The label normals the store holds for the day's located
objects (``ObjectState.normal``) against the simulator's true normals: median, 95th percentile and largest angle.

``real``: each shared real log (../shared/realdata) cut into 3 equal windows in memory; the 2nd and 3rd have
their odometry moved by a hidden transform (metres, any heading) and no pose prior; each window run into a
fresh store. Printed: joined and relocalisation s per session, the relation error of every relation (.relations)
on the sessions' world trajectories (within and across sessions) against the whole log run in one piece
(``pipeline.run_data``), and the wrong joins: every session of one log relocalised against the stores of the
others (must never be placed); ``wrong`` does the same from the stores ``real`` left (when it was cut short).

``growth``: ``--growth-days`` shorter days into one store: the working graph's anchors, the session's run
time and the store's size per day.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "realdata"
KINDS = {"moved": "moved", "removed": "gone", "added": "new"}
HIDDEN = ((0.0, 0.0, 0.0), (5.3, -3.1, 2.1), (-4.2, 6.4, -2.6))  # x m, y m, yaw rad: each window's odometry


def _map_xy(start, xy):
    from holoslam import geometry as g

    return g.transform_points(np.asarray(start, float), np.asarray(xy, float).reshape(-1, 2))


def _photographable_s(world, oid: str, log_path: Path, step_s: float = 0.5) -> float:
    """Seconds of the day (its true trajectory, every ``step_s``) in which the simulated camera could have
    photographed object ``oid`` of ``world`` (the day before's, where it still stood): the conditions of
    ``holoslam.sim.sensors``' snapshot target (within 3.5 m, facing the camera within 60 deg, not behind a wall
    or furniture, within the zoom range). The ground truth of "its place was in view" for a removed object."""
    from holoslam.io.mcap import read_log
    from holoslam.sim import sensors as S
    from holoslam.sim.camera import camera_pose_world, qr_modules
    from holoslam.sim.world import segments_block

    log, _ = read_log(log_path, require=["odometry"])
    gt = log.ground_truth
    o = world.object(oid)
    n = qr_modules(o.payload).shape[0]
    walls = world.wall_segments()
    cosmax = np.cos(np.radians(S.MAX_FACING_DEG))
    t_last, total = None, 0.0
    for p in gt:
        if t_last is not None and p.stamp_ns - t_last < step_s * 1e9:
            continue
        t_last = p.stamp_ns
        _, cam = camera_pose_world(np.array([p.wTb.x, p.wTb.y, p.wTb.theta]), 0.0, 0.0)
        d = float(np.linalg.norm(np.asarray(o.position) - cam))
        if d > S.MAX_SNAPSHOT_RANGE or S._facing_cos(o, cam) < cosmax + 0.05:
            continue
        if segments_block(walls, cam[None, :2], np.asarray(o.position)[None, :2])[0] or S._occluded(world, cam[:2], o):
            continue
        if S.TARGET_MODULE_PX * n * d / (S.F0 * o.label_size) > S.ZOOM_MAX * 1.25:
            continue
        total += step_s
    return total


def _positions(r, d: dict, w2m) -> tuple[dict, dict]:
    """The day's unchanged objects: object -> (x, y in the map, true x, y), in the store (seen where expected;
    world -> map by day 1's true start) and in the day's own run (its frame -> map by the day's true start)."""
    changed = {c["id"] for c in d["changes"]}
    p_life, p_single = {}, {}
    for o in r.update.objects:
        if o.status == "seen" and o.object_id not in changed and o.object_id in d["objects"]:
            p_life[o.object_id] = (*_map_xy(w2m, o.w_xy)[0], *d["objects"][o.object_id][:2])
    for o in r.stages.objects:
        if o.object_id in d["objects"] and o.object_id not in changed:
            p_single[o.object_id] = (*_map_xy(d["start_pose"], o.w_position[:2])[0], *d["objects"][o.object_id][:2])
    return p_life, p_single


def _normal_errors(r, world, w2m) -> dict[str, float]:
    """The day's located objects with a label normal in the store (``ObjectState.normal``): object -> the angle
    (deg) between it (world -> map by day 1's true start heading) and the label's true normal in the day's home."""
    out = {}
    for o in r.update.objects:
        if o.status in ("seen", "moved", "new") and o.normal is not None:
            yaw = float(np.arctan2(o.normal[1], o.normal[0])) + w2m[2]
            d = (yaw - world.object(o.object_id).label_yaw + np.pi) % (2 * np.pi) - np.pi
            out[o.object_id] = round(float(np.degrees(abs(d))), 3)
    return out


def _print_normals(detail: list) -> None:
    e = np.array([v for x in detail for v in x["normal_err_deg"].values()])
    n_located = sum(x["located"] for x in detail)
    if not len(e):
        print(f"label normals: none known (of {n_located} located object-days)")
        return
    print(f"label normals against the truth: {len(e)} of {n_located} located object-days have one; error median "
          f"{np.median(e):.2f} deg, p95 {np.percentile(e, 95):.2f}, max {e.max():.2f}; over 5 deg: "
          f"{int((e > 5).sum())}")


def _score_gone(det: dict, tru: dict, d: dict, world_before, log: Path, acc: list) -> None:
    """Adds to ``acc`` (detected and absent, detected, removed and in view, of those detected, late): "gone" by
    what the robot could know (``sim_part``)."""
    absent = [o for o, v in det.items() if v == "gone" and o not in d["objects"]]
    acc[0] += len(absent)
    acc[1] += sum(1 for v in det.values() if v == "gone")
    acc[4] += sum(1 for o in absent if tru.get(o) != "gone")
    for o, v in tru.items():
        if v == "gone" and _photographable_s(world_before, o, log) >= 8.0:
            acc[2] += 1
            acc[3] += det.get(o) == "gone"


def _observable(out: Path, truth: dict, worlds: list, detail: list) -> None:
    """The change detection against the observable truth (``lifelong_truth``: a label observable when the day's
    images read it) and against the photographable truth (the rule before it: also when the day's poses could have
    photographed it), both kept per day in ``detail``."""
    from lifelong_truth import camera_positions, format_scores, observable_truth, score

    days = truth["days"][: len(detail)]
    cams = [camera_positions(out / d["log"]) for d in days]
    obs = observable_truth({**truth, "days": days}, worlds[: len(days)], cams)
    photo = observable_truth({**truth, "days": days}, worlds[: len(days)], cams, "photographable")
    for x, t, p in zip(detail, obs.days, photo.days, strict=True):
        x["truth_observable"], x["truth_photographable"], x["truth_rule"] = t, p, "read"
    (out / "sim_detail.json").write_text(json.dumps(detail, indent=1))
    det = [x["detected"] for x in detail]
    print("\n" + format_scores("change detection against the OBSERVABLE truth (the issue's goal: labels read in the images "
                               "the day's camera took, benchmarks/lifelong_truth.py)", score(obs.days, det)))
    print("\n" + format_scores("change detection against the PHOTOGRAPHABLE truth (the rule before: labels the day's "
                               "true poses could have photographed for 0.25 s)", score(photo.days, det)))


def _print_changes(counts: dict, gone_fair: list, unseen_new: int) -> None:
    print("\nchange detection against the RAW simulator truth (days.json, every change on its day)")
    print("  kind    precision  recall  (detected / true)")
    for k, (tp, nd, nt) in counts.items():
        print(f"  {k:<6} {tp / nd if nd else float('nan'):10.3f} {tp / nt if nt else float('nan'):7.3f}  "
              f"({nd} / {nt})")
    print(f"  gone, by what could be known: precision {gone_fair[0] / max(gone_fair[1], 1):.3f} (absent that day; "
          f"{gone_fair[4]} of them removed a day or more before), recall {gone_fair[3] / max(gone_fair[2], 1):.3f} "
          f"of the {gone_fair[2]} removals whose place the camera could have photographed for 8 s")
    tp, nd, _nt = counts["new"]
    if unseen_new:
        print(f"  new, not counting the {unseen_new} objects there from day 1 that no earlier session had located: "
              f"precision {tp / max(nd - unseen_new, 1):.3f}")


def _store_map(store: Path):
    """The store's merged map now (what ``holoslam export`` pictures)."""
    from holoslam.lifelong.export import merged_map
    from holoslam.store.db import MapStore

    with MapStore.open(store, create=False) as s:
        return merged_map(s.submaps(working=True, grids=True))


def _truth_to_world(detail: list, w2m) -> np.ndarray:
    """The map frame's pose in the store's world: day 1's true start, corrected by the SE(2) fitted to the unchanged
    objects located so far (``_aligned``: the store's frame is the first session's, centimetres off the truth)."""
    from holoslam import geometry as g
    from holoslam.relocalise import fit_se2

    a = np.array([v for x in detail for v in x["xy_store"].values()], float).reshape(-1, 4)
    T = fit_se2(a[:, :2], a[:, 2:]) if len(a) >= 3 else np.zeros(3)  # store's map xy -> true map xy
    return g.compose(g.inverse(np.asarray(w2m, float)), g.inverse(T))


def _furniture(day, before, store: Path, wTm, rows: list) -> None:
    """Per piece moved before ``day`` (a ``holoslam.sim.days.Day``): the footprint shares on the store's merged map
    ``before`` the day's session and after it (and the day's own map), added to ``rows`` and printed."""
    from holoslam.evaluate_footprints import footprint_shares
    from holoslam.lifelong.export import merged_map
    from holoslam.store.db import MapStore

    with MapStore.open(store, create=False) as s:
        subs = s.submaps(working=True, grids=True)
    last = max(x.session_id for x in subs)
    after, own = merged_map(subs), merged_map([x for x in subs if x.session_id == last])
    for m in day.furniture:
        a = footprint_shares(before, after, m, day.world, wTm, own)
        rows.append({"day": day.day, "name": m.name, "shift_m": m.shift_m, "turn_deg": float(np.degrees(m.turn_rad)),
                     **dataclasses.asdict(a)})
        print(f"     {m.name} moved {m.shift_m:.2f} m, turned {np.degrees(m.turn_rad):.0f} deg: old edge "
              f"{a.old_cells} cells, {a.old_held} held occupied before, freed {a.old_freed:.2f} ({a.old_seen} seen "
              f"by the day: freed {a.old_freed_seen:.2f}); new edge {a.new_cells} cells, occupied "
              f"{a.new_occupied:.2f}, free {a.new_free:.2f} ({a.new_seen} seen by the day: occupied "
              f"{a.new_occupied_seen:.2f})")


def _print_furniture(rows: list) -> None:
    if not rows:
        print("furniture: no piece moved on these days")
        return

    def pooled(n: str, f: str) -> str:  # the shares over every piece's cells
        k = np.array([r[n] for r in rows], float)
        v = np.array([r[f] for r in rows], float)
        ok = k > 0
        return f"{np.sum(k[ok] * v[ok]) / max(np.sum(k[ok]), 1):.3f} of {int(k.sum())}"

    print(f"furniture moved: {len(rows)} pieces; old edge cells held occupied before the day and freed after: "
          f"{pooled('old_held', 'old_freed')} ({pooled('old_seen', 'old_freed_seen')} of those the day saw); new "
          f"edge cells occupied after {pooled('new_cells', 'new_occupied')}, free {pooled('new_cells', 'new_free')} "
          f"(occupied {pooled('new_seen', 'new_occupied_seen')} of those the day saw)")


def sim_part(out: Path, days: int, duration: float | None, seed: int, lifelong: dict | None = None,
             furniture: tuple[int, int] | None = None) -> None:
    from holoslam.lifelong.session import LifelongConfig, run_session
    from holoslam.sim.days import household_days, simulate_days

    if not (out / "days.json").exists():
        simulate_days(out, days, seed=seed, duration_s=duration, **({"furniture": furniture} if furniture else {}))
    truth = json.loads((out / "days.json").read_text())
    store = out / "home.holomap"
    store.unlink(missing_ok=True)
    w2m = truth["days"][0]["start_pose"]
    sim_days = household_days(len(truth["days"]), truth["seed"], tuple(truth.get("changes", (5, 10))),
                              tuple(truth.get("furniture_moves", (0, 0))))
    worlds = [d.world for d in sim_days]
    furniture_rows: list = []
    counts = {k: [0, 0, 0] for k in KINDS.values()}  # true positives, detected, true
    # "gone" scored by what the robot could know: a detected gone is right when the object is not in the home
    # that day (removed that day or before, and not yet detected); a removal counts for recall when the simulated
    # camera could have photographed its place for two snapshot periods (8 s) of the day (else nothing tells it)
    gone_fair = [0, 0, 0, 0, 0]  # detected and absent, detected, removed and in view, of those detected, late
    errs_life, errs_single, relocs, last = [], [], [], None
    detail = []  # per day: truth, detected, the unseen objects' camera s in view, the unchanged objects' errors
    ever_located: set[str] = set()
    unseen_new = 0  # "new" objects there from the start that no earlier session had located (not a change)
    print("day  joined by       reloc s  run s   changes (truth | detected)")
    for d in truth["days"]:
        before = _store_map(store) if sim_days[d["day"] - 1].furniture else None
        t0 = time.perf_counter()
        r = run_session(out / d["log"], store, lifelong=LifelongConfig(**(lifelong or {})))
        run_s = time.perf_counter() - t0
        s = r.summary
        if d["day"] > 1:
            relocs.append(s.relocalisation_s)
        det = {c.id: c.status for c in s.changes} if d["day"] > 1 else {}
        tru = {c["id"]: KINDS[c["change"]] for c in d["changes"]}
        for k in counts:
            counts[k][0] += sum(1 for o, v in det.items() if v == k and tru.get(o) == k)
            counts[k][1] += sum(1 for v in det.values() if v == k)
            counts[k][2] += sum(1 for v in tru.values() if v == k)
        print(f"{d['day']:>3}  {str(s.joined):<6} {s.joined_by:<8} {s.relocalisation_s:7.1f} {run_s:6.1f}   "
              f"{sorted(tru.items())} | {sorted(det.items())}")
        if d["day"] > 1:
            _score_gone(det, tru, d, worlds[d["day"] - 2], out / d["log"], gone_fair)
        unseen_new += sum(1 for o, v in det.items() if v == "new" and o not in tru and o not in ever_located
                          and o in truth["days"][0]["objects"])
        ever_located |= {o.object_id for o in r.stages.objects}
        p_life, p_single = _positions(r, d, w2m)
        e_life = {k: float(np.hypot(v[0] - v[2], v[1] - v[3])) for k, v in p_life.items()}
        e_single = {k: float(np.hypot(v[0] - v[2], v[1] - v[3])) for k, v in p_single.items()}
        errs_life += list(e_life.values())
        errs_single += list(e_single.values())
        normal_err = _normal_errors(r, worlds[d["day"] - 1], w2m)
        n_located = sum(o.status in ("seen", "moved", "new") for o in r.update.objects)
        detail.append({"day": d["day"], "truth": tru, "detected": det, "unseen_in_view_s": s.unseen_in_view_s,
                       "normal_err_deg": normal_err, "located": n_located,
                       "unseen_in_images": s.unseen_in_images, "checked": d.get("checked", {}),
                       "unseen_support_left": s.unseen_support_left,
                       "err_store_m": e_life, "err_single_m": e_single, "xy_store": p_life, "xy_single": p_single,
                       "reloc_s": s.relocalisation_s, "run_s": run_s, "joined_by": s.joined_by})
        if before is not None:
            _furniture(sim_days[d["day"] - 1], before, store, _truth_to_world(detail, w2m), furniture_rows)
        (out / "sim_detail.json").write_text(json.dumps(detail, indent=1))
        (out / "sim_furniture.json").write_text(json.dumps(furniture_rows, indent=1))
        last = r
    _observable(out, truth, worlds, detail)
    _print_changes(counts, gone_fair, unseen_new)
    _print_normals(detail)
    _print_furniture(furniture_rows)
    rm = lambda e: float(np.sqrt(np.mean(np.square(e)))) if e else float("nan")  # noqa: E731
    per_day = [(x["day"], rm(list(x["err_store_m"].values())), rm(list(x["err_single_m"].values()))) for x in detail]
    print("unchanged objects per day, RMSE mm (store | that day alone): " +
          ", ".join(f"d{k} {a * 1000:.1f}|{b * 1000:.1f}" for k, a, b in per_day))
    print(f"unchanged objects seen, position RMSE: store world {rm(errs_life) * 1000:.1f} mm (n {len(errs_life)}), "
          f"single-day sessions {rm(errs_single) * 1000:.1f} mm (n {len(errs_single)})")
    _aligned(detail)
    print(f"relocalisation s: median {np.median(relocs):.1f}, max {np.max(relocs):.1f} over {len(relocs)} sessions")
    _joint_methods(last)


def _aligned(detail: list) -> None:
    """The unchanged objects' RMSE with the map's frame taken out (the world is the first session's frame, a gauge:
    its first anchor is not the true start to the millimetre): the store's positions of every day under one
    best-fit SE(2) to the truth, and each single-day run under its own (as trajectory errors are aligned)."""
    from holoslam.relocalise import fit_se2

    def fit(rows):
        a = np.array(rows, float).reshape(-1, 4)
        if len(a) < 3:
            return np.array([]), np.zeros(3)
        T = fit_se2(a[:, :2], a[:, 2:])
        return np.hypot(*(_map_xy(T, a[:, :2]) - a[:, 2:]).T), T

    rm = lambda e: float(np.sqrt(np.mean(np.square(e)))) if len(e) else float("nan")  # noqa: E731
    every = [v for x in detail for v in x["xy_store"].values()]
    e_all, T = fit(every)
    per_day = []
    for x in detail:
        a = np.array(list(x["xy_store"].values()), float).reshape(-1, 4)
        es = np.hypot(*(_map_xy(T, a[:, :2]) - a[:, 2:]).T) if len(a) else np.array([])
        per_day.append((x["day"], rm(es), rm(fit(list(x["xy_single"].values()))[0])))
    print(f"unchanged objects, RMSE with the map's frame fitted (one SE(2) for the store: {T[0] * 1000:.0f} mm, "
          f"{T[1] * 1000:.0f} mm, {np.degrees(T[2]):.2f} deg): store {rm(e_all) * 1000:.1f} mm (max "
          f"{e_all.max(initial=0) * 1000:.0f}); per day (store | that day alone, its own fit): " +
          ", ".join(f"d{k} {a * 1000:.1f}|{b * 1000:.1f}" for k, a, b in per_day))


def _joint_methods(last) -> None:
    """The last day's joint graph re-solved by batch LM and by iSAM2 (median of 3, interleaved)."""
    from holoslam.lifelong.joint import solve_joint

    if last is None or last.joint_graph is None:
        return
    times = {"batch": [], "isam2": []}
    sols = {}
    for _ in range(3):
        for m in times:
            t0 = time.perf_counter()
            sols[m] = solve_joint(last.joint_graph, m, covariances=False)
            times[m].append(time.perf_counter() - t0)
    d = np.hypot(*(sols["batch"].new_wTa[:, :2] - sols["isam2"].new_wTa[:, :2]).T).max()
    n = last.joint_graph.problem.num_poses
    print(f"joint solve of the last day ({n} anchors): batch {np.median(times['batch']):.3f} s, isam2 "
          f"{np.median(times['isam2']):.3f} s (x{np.median(times['isam2']) / np.median(times['batch']):.2f}); "
          f"new anchors differ by at most {d * 1000:.1f} mm")


def _window(log, t0: int, t1: int, hidden):
    """The records of ``log`` in [t0, t1), its odometry moved by ``hidden`` (x, y, yaw) and no ground truth."""
    from holoslam import geometry as g
    from holoslam.types import Pose2

    H = np.asarray(hidden, float)

    def inside(r):
        return t0 <= r.stamp_ns < t1

    odo = []
    for o in log.odometry:
        if inside(o):
            p = g.compose(H, np.array([o.odomTb.x, o.odomTb.y, o.odomTb.theta]))
            odo.append(dataclasses.replace(o, odomTb=Pose2(float(p[0]), float(p[1]), float(p[2]))))
    return dataclasses.replace(log, odometry=tuple(odo), scans=tuple(s for s in log.scans if inside(s)),
                               headings=tuple(h for h in log.headings if inside(h)), ground_truth=())


def _joined_poses(store: Path) -> tuple[np.ndarray, np.ndarray]:
    """The joined sessions' poses as the store holds them at the end (what ``holoslam export`` writes: each
    session's poses hung from its submaps' current anchors), not as each session's run left them before the later
    sessions' joint solves."""
    from holoslam.lifelong.export import session_trajectories
    from holoslam.store.db import MapStore

    with MapStore.open(store, create=False) as s:
        final = session_trajectories(s)
    joined = [final[k] for k in sorted(final) if final[k][2]]
    return np.concatenate([x[0] for x in joined]), np.vstack([x[1] for x in joined])


def real_part(out: Path, logs: list[str], compare: bool = False, lifelong: dict | None = None) -> None:
    from holoslam.evaluate import relation_errors
    from holoslam.io.mcap import read_log
    from holoslam.io.relations import read_relations
    from holoslam.lifelong.session import LifelongConfig, run_session_data
    from holoslam.pipeline import run_data
    from holoslam.relocalise import relocalise
    from holoslam.store.db import MapStore

    sessions: dict[str, list] = {}
    print("log     session joined by       reloc s  run s")
    rows, search_rows = [], []
    for name in logs:
        log, rep = read_log(DATA / f"{name}.mcap", require=["odometry", "scan"])
        rel = read_relations(DATA / f"{name}.relations")
        t = np.array([s.stamp_ns for s in log.scans], np.int64)
        cuts = np.linspace(t[0], t[-1] + 1, 4).astype(np.int64)
        whole = run_data(log, rep)
        ref = relation_errors(whole.stamps_ns, whole.wTb, rel)
        store = out / f"{name}.holomap"
        store.unlink(missing_ok=True)
        st, reloc = [], []
        for k in range(3):
            w = _window(log, int(cuts[k]), int(cuts[k + 1]), HIDDEN[k])
            before = None
            if k:
                with MapStore.open(store) as s0:
                    before = s0.submaps(working=True, grids=True)
            t0 = time.perf_counter()
            r = run_session_data(w, rep, store, f"{name}-{k + 1}", f"{name}-{k + 1}",
                                 lifelong=LifelongConfig(**(lifelong or {})))
            s = r.summary
            if before is not None and compare:
                search_rows.append((name, k + 1, _compare_searches(r, before)))
            print(f"{name:<7} {k + 1:>7} {str(s.joined):<6} {s.joined_by:<8} {s.relocalisation_s:7.1f} "
                  f"{time.perf_counter() - t0:6.1f}   {s.why[:400]}")
            sys.stdout.flush()
            st.append((r.run.stamps_ns, r.run.wTb, s.joined))
            sessions.setdefault(name, []).append((r.stages.fe.submaps, np.asarray(r.stages.sol.wTa)))
            if k:
                reloc.append(s.relocalisation_s)
        stamps, wTb = _joined_poses(store)
        e = relation_errors(stamps, wTb, rel)
        which = np.searchsorted(cuts, rel.t1_ns, side="right") != np.searchsorted(cuts, rel.t2_ns, side="right")
        ec = relation_errors(stamps, wTb, dataclasses.replace(rel, t1_ns=rel.t1_ns[which], t2_ns=rel.t2_ns[which],
                                                              T=rel.T[which])) if which.any() else None
        rows.append((name, ref, e, ec, reloc, sum(x[2] for x in st)))
    print("\nlog     joined  whole-log m    sessions m (ratio)   across sessions m (n)   reloc s median")
    for name, ref, e, ec, reloc, nj in rows:
        cross = f"{ec.translation_mean_m:.4f} ({ec.n_matched})" if ec is not None else "-"
        print(f"{name:<7} {nj}/3    {ref.translation_mean_m:.4f}       {e.translation_mean_m:.4f} "
              f"(x{e.translation_mean_m / ref.translation_mean_m:.2f})   {cross:<22} {np.median(reloc):.1f}")
    if search_rows:
        print("\nrelocalisation search (the session against the store before it; median of 3, interleaved): coarse to "
              "fine (0.2 m, the loop search's) | full-resolution branch and bound")
        print("log     session  placed       matches   searches  cpu s            ratio")
        for name, k, res in search_rows:
            c, f = res["coarse"], res["full"]
            print(f"{name:<7} {k:>7}  {c['placed']!s:<5}|{f['placed']!s:<5} {c['matches']:>3}|{f['matches']:<3}  "
                  f"{c['searches']:>4}|{f['searches']:<4}  {c['cpu']:6.2f}|{f['cpu']:<6.2f}  x{c['cpu'] / f['cpu']:.2f}  "
                  f"wTs differ {res['dxy'] * 1000:.0f} mm")
    false = tried = 0
    for a in logs:
        with MapStore.open(out / f"{a}.holomap") as s:
            stored = s.submaps(working=True, grids=True)
        for b in logs:
            if a == b:
                continue
            for subs, sTa in sessions[b]:
                tried += 1
                r = relocalise(subs, sTa, {}, stored, {})
                false += r.placed
    print(f"wrong joins: {false} of {tried} sessions placed in another building's store")


def _compare_searches(r, stored) -> dict:
    """The session's relocalisation against ``stored`` by the coarse-to-fine search and by the full-resolution
    branch and bound (median CPU s of 3 runs each, interleaved)."""
    from holoslam.relocalise import RelocaliseConfig, relocalise

    subs, sTa = r.stages.fe.submaps, np.asarray(r.stages.sol.wTa)
    out: dict = {}
    cpu: dict[str, list[float]] = {"coarse": [], "full": []}
    for _ in range(3):
        for m, cfg in (("coarse", RelocaliseConfig()), ("full", RelocaliseConfig(coarse_resolution_m=0.0))):
            x = relocalise(subs, sTa, {}, stored, {}, cfg)
            cpu[m].append(x.cpu_seconds)
            out[m] = {"placed": x.placed, "matches": len(x.matches), "searches": x.searches,
                      "wTs": None if x.hypothesis is None else x.hypothesis.wTs}
    for m in cpu:
        out[m]["cpu"] = float(np.median(cpu[m]))
    a, b = out["coarse"]["wTs"], out["full"]["wTs"]
    out["dxy"] = float("nan") if a is None or b is None else float(np.hypot(*(a[:2] - b[:2])))
    return out


def wrong_part(out: Path) -> None:
    """Every session stored in one real log's store relocalised against every other log's store (from the stores
    ``real`` wrote: a session's submaps keep their points and their pose in the session's frame)."""
    from types import SimpleNamespace

    from holoslam.relocalise import relocalise
    from holoslam.store.db import MapStore

    stores = sorted((out.parent / "real").glob("*.holomap"))
    sessions, working = {}, {}
    for p in stores:
        with MapStore.open(p, create=False) as s:
            working[p.stem] = s.submaps(working=True, grids=True)
            sessions[p.stem] = []
            for e in s.sessions():
                subs = sorted(s.submaps(working=False, grids=True, session_id=e.id), key=lambda m: m.idx)
                sessions[p.stem].append(([SimpleNamespace(points=m.points) for m in subs],
                                         np.array([m.sTa for m in subs])))
    print("store   session of   placed  searches  reloc s")
    false = tried = 0
    for a in working:
        for b in sessions:
            if a == b:
                continue
            for k, (subs, sTa) in enumerate(sessions[b]):
                r = relocalise(subs, sTa, {}, working[a], {})
                tried += 1
                false += r.placed
                print(f"{a:<7} {b}-{k + 1:<10} {str(r.placed):<7} {r.searches:>8} {r.seconds:8.1f} "
                      f"(cpu {r.cpu_seconds:.1f})")
                sys.stdout.flush()
    print(f"wrong joins: {false} of {tried} sessions placed in another building's store")


def growth_part(out: Path, days: int, duration: float, seed: int) -> None:
    from holoslam.lifelong.session import run_session
    from holoslam.sim.days import simulate_days
    from holoslam.store.db import MapStore

    if not (out / "days.json").exists():
        simulate_days(out, days, seed=seed, duration_s=duration)
    truth = json.loads((out / "days.json").read_text())
    store = out / "home.holomap"
    store.unlink(missing_ok=True)
    print("day  working anchors  run s  cpu s  reloc s  store MB  joined")
    for d in truth["days"]:
        t0, c0 = time.perf_counter(), time.process_time()
        r = run_session(out / d["log"], store)
        with MapStore.open(store) as s:
            n = s.counts()["working_submaps"]
        print(f"{d['day']:>3}  {n:>15} {time.perf_counter() - t0:6.1f} {time.process_time() - c0:6.1f} "
              f"{r.summary.relocalisation_cpu_s:7.1f} {store.stat().st_size / 1e6:9.2f}  "
              f"{r.summary.joined} ({r.summary.joined_by})")
        sys.stdout.flush()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--parts", nargs="+", default=["sim", "real", "growth"],
                    choices=["sim", "real", "wrong", "growth"])
    ap.add_argument("--days", type=int, default=10)
    ap.add_argument("--duration", type=float, default=None, help="s of each simulated day (default: a whole tour)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--furniture", type=int, nargs=2, default=None, metavar=("LO", "HI"),
                    help="sim: pieces of furniture moved per day (default holoslam.sim.days.FURNITURE_MOVES)")
    ap.add_argument("--logs", nargs="+", default=["intel", "aces", "fr079"])
    ap.add_argument("--compare-search", action="store_true",
                    help="real: each session's relocalisation also by the full-resolution search (3 runs each, slow)")
    ap.add_argument("--growth-days", type=int, default=30)
    ap.add_argument("--growth-duration", type=float, default=150.0)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--lifelong", type=json.loads, default=None,
                    help='sim and real: LifelongConfig settings as JSON, e.g. \'{"dense_closures": true}\'')
    a = ap.parse_args()
    out = a.out or Path(tempfile.mkdtemp(prefix="bench_lifelong_"))
    for part in a.parts:
        d = out / part
        d.mkdir(parents=True, exist_ok=True)
        print(f"\n== {part} ({d})")
        if part == "sim":
            sim_part(d, a.days, a.duration, a.seed, a.lifelong, a.furniture and tuple(a.furniture))
        elif part == "real":
            real_part(d, a.logs, a.compare_search, a.lifelong)
        elif part == "wrong":
            wrong_part(d)
        else:
            growth_part(d, a.growth_days, a.growth_duration, a.seed + 100)
        sys.stdout.flush()



if __name__ == "__main__":
    main()
