"""Accuracy of the front end + solver on household logs against ground truth: dead reckoning vs the graph.

Usage: .venv/bin/python benchmarks/bench_household_accuracy.py [--quick] [--seeds 3] [--duration 300]
       [--noise 1,2] [--log PATH]

Logs:
* ``reference``: the bundled reference household log (``datasets/household_small.mcap`` or --log), read with
  ``holoslam.io.mcap.read_log``, object observations from ``holoslam.vision.observe.observations_from_log``;
* ``sim/s<seed>/x<noise>``: in-memory simulated households (``holoslam.sim``, other seeds, ``--duration`` s,
  every sensor noise times ``--noise``), same pipeline.

Variants of every log: ``clean``; ``corrupt10%`` (10 % of the object observations corrupted, half moved 1-2 m
in the base frame, half given another object's id); ``moved3`` (three objects moved 0.8 m half-way through the
run: their later observations are shifted by the move expressed in the base frame at that stamp, using ground
truth, as if the object had been carried away); ``nocompass+nocamera`` (compass and camera removed: odometry,
laser and tf only; scan-only loop closures).

Printed per row: anchors, anchor position RMSE (m) and heading RMSE (deg) for dead reckoning (DR) and the graph,
the ratio DR/graph, the object RMSE (m) for DR (sightings placed with the DR anchor poses, averaged per object)
and the graph, the fraction of true anchor positions in their 95 % ellipses (``cov95``, after alignment; the
first-anchor gauge variant in ``cov95@0``), for corrupted variants the ratio to clean (``/clean``: the larger of
the anchor ratio and the object ratio, objects compared over those both runs located, ``compare_to_clean``) with
``n/cl`` the objects located by the variant and by the clean run (a lost object is not hidden), and for ``moved3`` how
many of the moved objects the solver reported as moved; ``skip`` the observations the front end skipped (before
the first anchor: an object seen there loses that sighting, which can leave a moved object one sighting before
its move, too few to tell a move from a bad sighting). ``obj≥2`` is the object RMSE over the confirmed objects
(at least two sightings kept by the solver), ``n1`` the number of objects seen once (unconfirmed: a single
misread id naming an object seen nowhere else cannot be detected, it puts that object where the misread label
is), ``/cl≥2`` the corrupted variant's ratio to clean on confirmed objects. Every estimate is aligned to the truth with
``holoslam.evaluate.align_se2`` on the anchors (the SLAM world frame is arbitrary). Last column: front-end
seconds. ``--quick``: the reference log only, clean / corrupt / moved.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

MOVE = 0.8  # m, how far each of the three objects is carried half-way


def corrupt(obs, frac, rng, ids):
    """10 % of the observations: half shifted 1-2 m, half given another object's id."""
    from holoslam.types import ObjectObservation

    obs = list(obs)
    pick = rng.choice(len(obs), max(1, int(round(frac * len(obs)))), replace=False)
    for n, k in enumerate(pick):
        o = obs[k]
        if n % 2 == 0:
            a = rng.uniform(0, 2 * np.pi)
            shift = rng.uniform(1.0, 2.0) * np.array([np.cos(a), np.sin(a), 0.0])
            obs[k] = ObjectObservation(
                o.stamp_ns, o.object_id, o.payload, o.b_position + shift, o.cov_b_position
            )
        else:
            other = [i for i in ids if i != o.object_id][int(rng.integers(len(ids) - 1))]
            obs[k] = ObjectObservation(o.stamp_ns, other, o.payload, o.b_position, o.cov_b_position)
    return obs


def move_objects(obs, gt_t, gt_wTb, rng, n=3):
    """Three objects seen both before and after the middle of their sightings are carried MOVE m at that
    time: later sightings are shifted by the move in the base frame at their stamp. Returns (obs, moved ids,
    truth after the move {id: xy})."""
    from holoslam.evaluate import truth_at
    from holoslam.types import ObjectObservation

    by_id: dict[str, list[int]] = {}
    for k, o in enumerate(obs):
        by_id.setdefault(o.object_id, []).append(k)
    cands = sorted(i for i, ks in by_id.items() if len({obs[k].stamp_ns for k in ks}) >= 4)
    chosen = [cands[j] for j in rng.choice(len(cands), min(n, len(cands)), replace=False)]
    out = list(obs)
    deltas = {}
    for oid in chosen:
        ks = sorted(by_id[oid], key=lambda k: obs[k].stamp_ns)
        half = ks[len(ks) // 2 :]
        a = rng.uniform(0, 2 * np.pi)
        d = MOVE * np.array([np.cos(a), np.sin(a)])
        deltas[oid] = d
        st = np.array([obs[k].stamp_ns for k in half])
        wTb = truth_at(st, gt_t, gt_wTb)
        for k, T in zip(half, wTb, strict=True):
            o = obs[k]
            c, s = np.cos(T[2]), np.sin(T[2])
            db = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], 0.0])
            out[k] = ObjectObservation(
                o.stamp_ns, o.object_id, o.payload, o.b_position + db, o.cov_b_position, o.method
            )
    return out, chosen, deltas


def evaluate_run(log, obs, truth_objects, moved_deltas=None):
    """Front end + solve + errors for one log and observation list -> dict of numbers."""
    from holoslam import geometry as g
    from holoslam.evaluate import object_errors, trajectory_errors, truth_at
    from holoslam.optimise import keyframe_anchors, reestimate_anchors, revisit_nodes, run_build_options
    from holoslam.solve import CovarianceScope, SolveOptions, solve
    from holoslam.submaps.frontend import FrontEndConfig, build_problem

    # as holoslam.pipeline.run does: anchors re-estimated after loop closures, the run's robust kernels, the
    # anchors from the keyframe solve
    t0 = time.perf_counter()
    fe = build_problem(log, obs, optimize=reestimate_anchors)
    t1 = time.perf_counter()
    sol = solve(fe.problem, SolveOptions(covariances=CovarianceScope.ANCHORS, build=run_build_options()))
    sol = keyframe_anchors(sol, fe.anchor_stamps_ns, revisit_nodes(fe, sol, FrontEndConfig()))
    gt_t, gt_wTb = log.ground_truth_arrays()
    true = truth_at(fe.anchor_stamps_ns, gt_t, gt_wTb)
    te = trajectory_errors(sol.wTa, true, sol.cov_wTa)
    T0 = g.compose(true[0], g.inverse(sol.wTa[0]))  # the solver's gauge: anchor 0 fixed
    te0 = trajectory_errors(
        g.compose(np.broadcast_to(T0, sol.wTa.shape), sol.wTa), true, sol.cov_wTa, align=False
    )
    dr = truth_at(fe.anchor_stamps_ns, fe.dr_stamps_ns, fe.dr_wTb)
    de = trajectory_errors(dr, true)
    truth = dict(truth_objects)
    if moved_deltas:  # a moved object's landmark is its final place; "<id>@before" its first
        truth = {
            k: (np.asarray(v)[:2] + moved_deltas[k] if k in moved_deltas else v) for k, v in truth.items()
        }
    oe = object_errors(sol.landmark_ids, sol.w_landmarks, truth, te.T)
    # confirmed objects: at least two sightings kept by the solver (a single misread id cannot be detected)
    from collections import Counter

    from holoslam.graph.keys import object_of
    from holoslam.graph.problem import MeasurementFamily
    from holoslam.maps.holographic import CONFIRMING_SIGHTINGS

    rej = {r.index for r in sol.rejected if r.family is MeasurementFamily.LANDMARK}
    kept = Counter(object_of(n) for k, n in enumerate(fe.problem.landmarks.landmark) if k not in rej)
    conf = [k for k, n in enumerate(sol.landmark_ids) if kept[object_of(n)] >= CONFIRMING_SIGHTINGS]
    oc = object_errors([sol.landmark_ids[k] for k in conf], sol.w_landmarks[conf], truth, te.T)
    P = fe.problem.landmarks
    if len(P.i):
        dw = g.compose(np.broadcast_to(de.T, dr.shape), dr)
        w = np.array(
            [g.transform_points(dw[i], xy[None])[0] for i, xy in zip(P.i, P.a_position, strict=True)]
        )
        names = sorted(set(P.landmark))
        lab = np.array(P.landmark)
        est = np.array([w[lab == k].mean(axis=0) for k in names])
        od = object_errors(names, est, truth, np.zeros(3))
    else:
        od = oe
    moved_found = sorted(m.object_id for m in sol.moved_objects)
    return dict(
        anchors=len(fe.submaps),
        dr_pos=de.rmse_m,
        pos=te.rmse_m,
        dr_head=de.heading_rmse_deg,
        head=te.heading_rmse_deg,
        dr_obj=od.rmse_m,
        obj=oe.rmse_m,
        n_obj=oe.n_matched,
        obj_errors=dict(oe.errors_m),
        obj2=oc.rmse_m,
        n_once=len(sol.landmark_ids) - len(conf),
        cov95=te.coverage95,
        cov95_0=te0.coverage95,
        fe_s=t1 - t0,
        skipped=fe.skipped_observations,
        moved_found=moved_found,
        loops=int(np.sum(fe.problem.relative.kind == "loop")),
    )


def strip_compass_camera(log):
    return dataclasses.replace(log, headings=(), images=(), camera_infos=(), tags=())


def variants(log, obs, name, rng_seed, quick):
    truth = {o["id"]: np.array(o["position"]) for o in json.loads(log.world_json)["objects"]}
    ids = sorted(truth)
    gt_t, gt_wTb = log.ground_truth_arrays()
    rows = []
    clean = evaluate_run(log, obs, truth)
    rows.append((name, "clean", clean, None))
    bad = corrupt(obs, 0.10, np.random.default_rng(rng_seed), ids)
    rows.append((name, "corrupt10%", evaluate_run(log, bad, truth), clean))
    mv, chosen, deltas = move_objects(obs, gt_t, gt_wTb, np.random.default_rng(rng_seed + 1))
    r = evaluate_run(log, mv, truth, deltas)
    r["moved_expected"] = chosen
    rows.append((name, "moved3", r, clean))
    if not quick:
        bare = strip_compass_camera(log)
        rows.append((name, "nocompass+nocamera", evaluate_run(bare, [], truth), None))
    return rows


def compare_to_clean(m: dict, clean: dict) -> dict:
    """A variant's objects against the clean run's: the object RMSE ratio over the objects both runs located
    (an object the variant lost cannot lower its RMSE), how many each matched, and which the variant lost."""
    common = sorted(set(m["obj_errors"]) & set(clean["obj_errors"]))

    def rmse(errors: dict) -> float:
        v = np.array([errors[k] for k in common])
        return float(np.sqrt(np.mean(v**2))) if v.size else float("nan")

    ratio = rmse(m["obj_errors"]) / rmse(clean["obj_errors"]) if common else float("nan")
    return {
        "obj_ratio": ratio,
        "pos_ratio": m["pos"] / clean["pos"],
        "matched": len(m["obj_errors"]),
        "clean_matched": len(clean["obj_errors"]),
        "lost": sorted(set(clean["obj_errors"]) - set(m["obj_errors"])),
    }


def print_table(rows):
    hdr = (
        f"{'log':18s} {'variant':19s} {'anch':>4s} {'DR m':>6s} {'graph m':>7s} {'ratio':>5s} {'DR°':>5s} "
        f"{'graph°':>6s} {'DR obj':>6s} {'obj m':>6s} {'n':>3s} {'obj≥2':>6s} {'n1':>2s} {'cov95':>5s} "
        f"{'cov95@0':>7s} {'/clean':>6s} {'n/cl':>6s} {'/cl≥2':>6s} "
        f"{'moved':>5s} {'skip':>4s} {'loops':>5s} {'fe s':>5s}"
    )
    print(hdr)
    for name, var, m, clean in rows:
        cmp = compare_to_clean(m, clean) if clean else None
        rel = f"{max(cmp['pos_ratio'], cmp['obj_ratio']):6.2f}" if cmp else f"{'':6s}"
        kept = f"{cmp['matched']}/{cmp['clean_matched']}" if cmp else ""
        rel2 = f"{max(m['pos'] / clean['pos'], m['obj2'] / clean['obj2']):6.2f}" if clean else f"{'':6s}"
        mv = (
            f"{len(set(m['moved_found']) & set(m['moved_expected']))}/{len(m['moved_expected'])}"
            if "moved_expected" in m
            else ""
        )
        print(
            f"{name:18s} {var:19s} {m['anchors']:4d} {m['dr_pos']:6.3f} {m['pos']:7.4f} "
            f"{m['dr_pos'] / m['pos']:5.1f} {m['dr_head']:5.2f} {m['head']:6.3f} {m['dr_obj']:6.3f} "
            f"{m['obj']:6.3f} {m['n_obj']:3d} {m['obj2']:6.3f} {m['n_once']:2d} {m['cov95']:5.2f} "
            f"{m['cov95_0']:7.2f} {rel} {kept:>6s} {rel2} {mv:>5s} {m['skipped']:4d} "
            f"{m['loops']:5d} {m['fe_s']:5.1f}",
            flush=True,
        )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="reference log only: clean, corrupt, moved")
    ap.add_argument("--seeds", type=int, default=2, help="simulated seeds besides the reference log")
    ap.add_argument("--duration", type=float, default=300.0, help="simulated run length (s)")
    ap.add_argument("--noise", type=str, default="1,2", help="noise scales of the simulated logs")
    ap.add_argument("--log", type=Path, default=ROOT / "datasets" / "household_small.mcap")
    a = ap.parse_args(argv)
    from holoslam.io.mcap import read_log
    from holoslam.vision.observe import observations_from_log

    rows = []
    log, _ = read_log(a.log)
    obs, _ = observations_from_log(log)
    rows += variants(log, obs, "reference", 100, a.quick)
    print_table(rows)
    if a.quick:
        return 0
    from holoslam.sim import SimConfig, simulate_household
    from holoslam.sim.records import to_log_data

    for k in [float(x) for x in a.noise.split(",")]:
        for seed in range(10, 10 + a.seeds):
            run = simulate_household(SimConfig(seed=seed, duration_s=a.duration).with_noise_scale(k))
            slog = to_log_data(run)
            sobs, _ = observations_from_log(slog)
            srows = variants(slog, sobs, f"sim/s{seed}/x{k:g}", 200 + seed, False)
            print_table(srows)
            rows += srows
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
