"""Lifelong household maps (issue 27): relocalisation, joining, object change detection and growth of a map store.

    .venv/bin/python benchmarks/bench_lifelong.py [--parts sim real growth] [--days 10] [--duration S]
        [--logs intel aces fr079] [--growth-days 30] [--growth-duration S] [--out DIR]

``sim``: ``--days`` simulated days of the household (``holoslam.sim.days``: 5-10 changes a day, a new start
each day), each day's log run into one store (``holoslam.lifelong.session.run_session``, what
``holoslam run LOG --map STORE`` calls). Printed per day: joined / by what, relocalisation s, run s; then the
change detection's precision and recall per kind against days.json (moved / gone = removed / new = added; an
object the store did not know before and sees for the first time counts as a false "new" unless it was
added), the unchanged objects' position RMSE in the world (world -> map by day 1's start pose, the store's frame)
against the same day's single-session result (the session's own solve, moved to the map by the true start
pose), and the joint solve of the last day re-solved by batch LM and by iSAM2 over the whole graph (median of 3,
interleaved, and the largest anchor difference).

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


def sim_part(out: Path, days: int, duration: float | None, seed: int) -> None:
    from holoslam.lifelong.joint import solve_joint
    from holoslam.lifelong.session import run_session
    from holoslam.sim.days import simulate_days

    if not (out / "days.json").exists():
        simulate_days(out, days, seed=seed, duration_s=duration)
    truth = json.loads((out / "days.json").read_text())
    store = out / "home.holomap"
    store.unlink(missing_ok=True)
    w2m = truth["days"][0]["start_pose"]
    counts = {k: [0, 0, 0] for k in KINDS.values()}  # true positives, detected, true
    errs_life, errs_single, relocs, last = [], [], [], None
    print("day  joined by       reloc s  run s   changes (truth | detected)")
    for d in truth["days"]:
        t0 = time.perf_counter()
        r = run_session(out / d["log"], store)
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
        changed = set(tru)
        for o in r.update.objects:
            if o.status == "seen" and o.object_id not in changed and o.object_id in d["objects"]:
                errs_life.append(np.hypot(*(_map_xy(w2m, o.w_xy)[0] - d["objects"][o.object_id][:2])))
        for o in r.stages.objects:
            if o.object_id in d["objects"] and o.object_id not in changed:
                errs_single.append(np.hypot(*(_map_xy(d["start_pose"], o.w_position[:2])[0]
                                              - d["objects"][o.object_id][:2])))
        last = r
    print("\nchange detection  precision  recall  (detected / true)")
    for k, (tp, nd, nt) in counts.items():
        print(f"  {k:<6}          {tp / nd if nd else float('nan'):9.3f} {tp / nt if nt else float('nan'):7.3f}  "
              f"({nd} / {nt})")
    rm = lambda e: float(np.sqrt(np.mean(np.square(e)))) if e else float("nan")  # noqa: E731
    print(f"unchanged objects seen, position RMSE: store world {rm(errs_life) * 1000:.1f} mm (n {len(errs_life)}), "
          f"single-day sessions {rm(errs_single) * 1000:.1f} mm (n {len(errs_single)})")
    print(f"relocalisation s: median {np.median(relocs):.1f}, max {np.max(relocs):.1f} over {len(relocs)} sessions")
    if last is not None and last.joint_graph is not None:
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


def real_part(out: Path, logs: list[str]) -> None:
    from holoslam.evaluate import relation_errors
    from holoslam.io.mcap import read_log
    from holoslam.io.relations import read_relations
    from holoslam.lifelong.session import run_session_data
    from holoslam.pipeline import run_data
    from holoslam.relocalise import relocalise
    from holoslam.store.db import MapStore

    sessions: dict[str, list] = {}
    print("log     session joined by       reloc s  run s")
    rows = []
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
            t0 = time.perf_counter()
            r = run_session_data(w, rep, store, f"{name}-{k + 1}", f"{name}-{k + 1}")
            s = r.summary
            print(f"{name:<7} {k + 1:>7} {str(s.joined):<6} {s.joined_by:<8} {s.relocalisation_s:7.1f} "
                  f"{time.perf_counter() - t0:6.1f}   {s.why[:90]}")
            sys.stdout.flush()
            st.append((r.run.stamps_ns, r.run.wTb, s.joined))
            sessions.setdefault(name, []).append((r.stages.fe.submaps, np.asarray(r.stages.sol.wTa)))
            if k:
                reloc.append(s.relocalisation_s)
        joined = [x for x in st if x[2]]
        stamps = np.concatenate([x[0] for x in joined])
        wTb = np.vstack([x[1] for x in joined])
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
    print("day  working anchors  run s   store MB  joined")
    for d in truth["days"]:
        t0 = time.perf_counter()
        r = run_session(out / d["log"], store)
        with MapStore.open(store) as s:
            n = s.counts()["working_submaps"]
        print(f"{d['day']:>3}  {n:>15} {time.perf_counter() - t0:6.1f} {store.stat().st_size / 1e6:9.2f}  "
              f"{r.summary.joined} ({r.summary.joined_by})")
        sys.stdout.flush()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--parts", nargs="+", default=["sim", "real", "growth"],
                    choices=["sim", "real", "wrong", "growth"])
    ap.add_argument("--days", type=int, default=10)
    ap.add_argument("--duration", type=float, default=None, help="s of each simulated day (default: a whole tour)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--logs", nargs="+", default=["intel", "aces", "fr079"])
    ap.add_argument("--growth-days", type=int, default=30)
    ap.add_argument("--growth-duration", type=float, default=150.0)
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args()
    out = a.out or Path(tempfile.mkdtemp(prefix="bench_lifelong_"))
    for part in a.parts:
        d = out / part
        d.mkdir(parents=True, exist_ok=True)
        print(f"\n== {part} ({d})")
        if part == "sim":
            sim_part(d, a.days, a.duration, a.seed)
        elif part == "real":
            real_part(d, a.logs)
        elif part == "wrong":
            wrong_part(d)
        else:
            growth_part(d, a.growth_days, a.growth_duration, a.seed + 100)
        sys.stdout.flush()



if __name__ == "__main__":
    main()
