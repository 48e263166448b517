"""Loop closures on the real laser logs: relation error of the front end + final solve, and the time spent in
``LoopSearch.search``, with the default ``LoopConfig`` or with settings overridden (to compare an acceptance rule
with and without a change, on the same code).

    .venv/bin/python benchmarks/bench_loops_realdata.py [--logs aces fr079 intel] [--set NAME=VALUE ...]
        [--out FILE.json] [--timing]

What runs is what ``holoslam.pipeline.run`` does for the trajectory, without the maps, vision and covariances:
``frontend.build_problem(log, optimize=optimise.reestimate_anchors)``, ``solve`` with the run's robust kernels
(``optimise.run_build_options``) and the default solver settings (LM, chi-square rounds at 0.9999), keyframe poses
and the wheel odometry between them at every odometry and scan stamp, scored by ``evaluate.relation_errors``
against ``../shared/realdata/<log>.relations`` (nearest pose within 0.05 s).

Each log runs in this process one after the other (a few minutes each). Columns: transl / rot = mean relation
error, max = largest translational one; loops = loop edges in the problem / searches tried; rejected = loops
the final solve's chi-square rounds removed; ambiguous = matches ``LoopSearch`` turned down or widened because
of a second peak (``LoopSearch.ambiguous``, when the code has it); fe s = front-end wall time, loop s = the part
of it spent in ``LoopSearch.search`` (anchor re-estimates after closures excluded); loop cpu = the same in CPU
time of this process (steadier than wall time on a shared machine; the JSON rows hold both).

``--timing`` measures the loop search's CPU time before and after, paired: the calls of a run with
``ambiguity="off"`` and of a run with the settings given are recorded and replayed alternately
(``replay_timing``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "realdata"
LOGS = ("aces", "fr079", "intel")


def _parse_value(text: str):
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


def bench_log(name: str, data: Path, overrides: dict) -> dict:
    from holoslam import geometry as g
    from holoslam.evaluate import relation_errors
    from holoslam.io.mcap import read_log
    from holoslam.io.relations import read_relations
    from holoslam.optimise import reestimate_anchors, run_build_options
    from holoslam.solve import SolveOptions, solve
    from holoslam.submaps import loops as loops_mod
    from holoslam.submaps.frontend import FrontEndConfig, build_problem
    from holoslam.trajectory import keyframe_poses, optimised_trajectory

    log, _ = read_log(data / f"{name}.mcap", require=["odometry", "scan"])
    rel = read_relations(data / f"{name}.relations")
    cfg = FrontEndConfig(loops=dataclasses.replace(loops_mod.LoopConfig(), **overrides))

    spent = [0.0, 0.0]
    searches: list = []
    original = loops_mod.LoopSearch.search

    def timed(self, *a, **k):
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            return original(self, *a, **k)
        finally:
            spent[0] += time.perf_counter() - t0
            spent[1] += time.process_time() - c0
            searches.append(self)

    loops_mod.LoopSearch.search = timed
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        fe = build_problem(log, (), cfg, optimize=reestimate_anchors)
        fe_s, fe_cpu = time.perf_counter() - t0, time.process_time() - c0
    finally:
        loops_mod.LoopSearch.search = original
    ls = searches[-1] if searches else None
    t0 = time.perf_counter()
    sol = solve(fe.problem, SolveOptions(build=run_build_options()))
    solve_s = time.perf_counter() - t0
    odom_stamps, odomTb = log.odometry_arrays()
    scan_stamps = np.array([s.stamp_ns for s in log.scans], dtype=np.int64)
    stamps = np.union1d(odom_stamps, scan_stamps)
    key_stamps, wTk = keyframe_poses(fe.submaps, sol.wTa)
    wTb = optimised_trajectory(stamps, odom_stamps, odomTb, key_stamps, wTk)
    e = relation_errors(stamps, wTb, rel)

    # each loop against the final solution: how far (and how many sigmas) it is from what the map settled on
    P = fe.problem
    loop = np.flatnonzero(np.asarray(P.relative.kind) == "loop")
    d2, dist = [], []
    for k in loop:
        i, j = int(P.relative.i[k]), int(P.relative.j[k])
        r = g.between(g.between(sol.wTa[i], sol.wTa[j]), P.relative.iTj[k])
        r[2] = g.wrap(r[2])
        d2.append(float(r @ np.linalg.solve(P.relative.cov_iTj[k], r)))
        dist.append(float(np.hypot(r[0], r[1])))
    d2, dist = np.array(d2), np.array(dist)
    kind = np.asarray(P.relative.kind)
    rejected = sum(1 for m in sol.rejected if m.family.name.lower().startswith("rel") and kind[m.index] == "loop")
    return {
        "log": name, "overrides": overrides,
        "transl_mean_m": e.translation_mean_m, "transl_std_m": e.translation_std_m,
        "transl_max_m": e.translation_max_m, "rot_mean_deg": e.rotation_mean_deg,
        "rot_std_deg": e.rotation_std_deg, "matched": f"{e.n_matched}/{e.n_relations}",
        "loops": int(loop.size), "tried": int(fe.loops_tried), "rejected_loops": rejected,
        "rejected_total": len(sol.rejected),
        "ambiguous": int(getattr(ls, "ambiguous", -1)) if ls is not None else -1,
        "loops_off_0.3m": int((dist > 0.3).sum()), "loops_d2_gt_21": int((d2 > 21.1).sum()),
        "loop_d2_median": float(np.median(d2)) if d2.size else float("nan"),
        "frontend_s": fe_s, "loop_search_s": spent[0], "frontend_cpu_s": fe_cpu, "loop_search_cpu_s": spent[1],
        "solve_s": solve_s,
    }


def _record(log, loops_mod, cfg) -> list:
    """The calls of ``LoopSearch`` (submaps added, searches with their arguments) in one front-end run."""
    from holoslam.optimise import reestimate_anchors
    from holoslam.submaps.frontend import FrontEndConfig, build_problem

    events: list = []
    o_search, o_add = loops_mod.LoopSearch.search, loops_mod.LoopSearch.add_submap

    def search(self, *a, **k):
        events.append(("search", a, k))
        return o_search(self, *a, **k)

    def add(self, index, grid):
        events.append(("add", (index, grid), {}))
        return o_add(self, index, grid)

    loops_mod.LoopSearch.search, loops_mod.LoopSearch.add_submap = search, add
    try:
        build_problem(log, (), FrontEndConfig(loops=cfg), optimize=reestimate_anchors)
    finally:
        loops_mod.LoopSearch.search, loops_mod.LoopSearch.add_submap = o_search, o_add
    return events


def _replay(loops_mod, cfg, events) -> tuple[float, tuple[int, int, int]]:
    """CPU seconds in ``LoopSearch.search`` replaying ``events`` through a fresh ``LoopSearch(cfg)``, and its
    (closures found, windows tried, ambiguous matches)."""
    from holoslam.submaps.scanmatch import MatchConfig

    ls = loops_mod.LoopSearch(cfg, MatchConfig())
    n_found, spent = 0, 0.0
    for kind, a, k in events:
        if kind == "add":
            ls.add_submap(*a)
            continue
        c0 = time.process_time()
        n_found += len(ls.search(*a, **k))
        spent += time.process_time() - c0
    return spent, (n_found, ls.tried, ls.ambiguous)


def replay_timing(name: str, data: Path, overrides: dict, repeats: int = 7) -> dict:
    """CPU time of ``LoopSearch.search`` with the ambiguity test off and on, paired: the calls of one front-end
    run with ``ambiguity="off"`` and of one with the settings given are recorded, then replayed alternately
    (``repeats`` times; the minimum of each and the median of the paired ratios kept) as: the off run's calls with the test off (``cpu_off_s``: the loop
    search before), the same calls with it on (``cpu_rule_s``: the test's own cost), and the on run's calls
    with it on (``cpu_on_s``: the loop search after, including what it does differently: fewer closures accepted
    leave wider windows and unsaturated pairs). Whole-run timings mostly measure other load on a shared machine."""
    from holoslam.io.mcap import read_log
    from holoslam.submaps import loops as loops_mod

    log, _ = read_log(data / f"{name}.mcap", require=["odometry", "scan"])
    cfg_off = dataclasses.replace(loops_mod.LoopConfig(), ambiguity="off")
    cfg_on = dataclasses.replace(loops_mod.LoopConfig(), **overrides)
    ev_off, ev_on = _record(log, loops_mod, cfg_off), _record(log, loops_mod, cfg_on)
    cases = {"off": (cfg_off, ev_off), "rule": (cfg_on, ev_off), "on": (cfg_on, ev_on)}
    times: dict[str, list[float]] = {k: [] for k in cases}
    found = {}
    for _ in range(repeats):
        for key, (cfg, events) in cases.items():
            spent, found[key] = _replay(loops_mod, cfg, events)
            times[key].append(spent)
    t = {k: np.array(v) for k, v in times.items()}
    return {"log": name, "overrides": overrides, "searches_off": sum(e[0] == "search" for e in ev_off),
            "searches_on": sum(e[0] == "search" for e in ev_on), "cpu_off_s": float(t["off"].min()),
            "cpu_rule_s": float(t["rule"].min()), "cpu_on_s": float(t["on"].min()),
            "rule_ratio_median": float(np.median(t["rule"] / t["off"])),
            "on_ratio_median": float(np.median(t["on"] / t["off"])), "times": {k: v.tolist() for k, v in times.items()},
            "found_off": found["off"], "found_rule": found["rule"], "found_on": found["on"]}


def print_table(rows: list[dict]) -> None:
    print(f"{'log':<8}{'transl m':>10}{'max m':>8}{'rot deg':>9}{'loops/tried':>13}{'rej':>5}{'amb':>5}"
          f"{'>0.3m':>6}{'d2>21':>6}{'fe s':>8}{'loop s':>8}{'loop cpu':>9}  overrides")
    for r in rows:
        print(f"{r['log']:<8}{r['transl_mean_m']:>10.4f}{r['transl_max_m']:>8.3f}{r['rot_mean_deg']:>9.3f}"
              f"{str(r['loops']) + '/' + str(r['tried']):>13}{r['rejected_loops']:>5}{r['ambiguous']:>5}"
              f"{r['loops_off_0.3m']:>6}{r['loops_d2_gt_21']:>6}{r['frontend_s']:>8.1f}{r['loop_search_s']:>8.1f}"
              f"{r['loop_search_cpu_s']:>9.1f}"
              f"  {r['overrides'] or ''}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", nargs="+", choices=LOGS, default=list(LOGS))
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="LoopConfig overrides")
    ap.add_argument("--out", type=Path, help="append the rows to this JSON-lines file")
    ap.add_argument("--timing", action="store_true",
                    help="instead: CPU time of the loop search off vs on over the same recorded calls")
    a = ap.parse_args()
    overrides = {k: _parse_value(v) for k, v in (s.split("=", 1) for s in a.set)}
    if a.timing:
        for name in a.logs:
            r = replay_timing(name, a.data, overrides)
            print(f"{name:<8} loop search CPU (min of {len(r['times']['off'])}): {r['cpu_off_s']:.2f} s before "
                  f"(ambiguity off, {r['searches_off']} calls); {r['cpu_rule_s']:.2f} s with the test on the same "
                  f"calls (x{r['cpu_rule_s'] / r['cpu_off_s']:.3f}, median paired x{r['rule_ratio_median']:.3f}); "
                  f"{r['cpu_on_s']:.2f} s after (its own run's {r['searches_on']} calls, "
                  f"x{r['cpu_on_s'] / r['cpu_off_s']:.3f}, median paired x{r['on_ratio_median']:.3f}); "
                  f"(closures, windows, ambiguous) {r['found_off']} / {r['found_rule']} / {r['found_on']}",
                  flush=True)
            if a.out:
                with a.out.open("a") as f:
                    f.write(json.dumps(r) + "\n")
        return 0
    rows = []
    for name in a.logs:
        row = bench_log(name, a.data, overrides)
        rows.append(row)
        print(json.dumps(row), flush=True)
        if a.out:
            with a.out.open("a") as f:
                f.write(json.dumps(row) + "\n")
    print()
    print_table(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
