"""The front end on a small synthetic two-room world with ground truth: motion filter, probability-grid submaps,
measurements, loops, Eq. 16, solver."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from holoslam import geometry as g
from holoslam.sim.world import raycast
from holoslam.submaps.deadreckon import DeadReckoningConfig, integrate
from holoslam.submaps.frontend import FrontEndConfig, build_problem, landmark_in_anchor
from holoslam.submaps.local_slam import LocalSlam, LocalSlamConfig
from holoslam.submaps.loops import LoopConfig
from holoslam.submaps.probgrid import ProbGrid
from holoslam.types import Heading, LogData, ObjectObservation, Odometry, Pose2, Scan, Transform

# two rooms 4 x 4 m side by side joined by a 1 m doorway at x = 4, y in [1.5, 2.5]; a box in each room
WALLS = np.array([
    [0, 0, 8, 0], [8, 0, 8, 4], [8, 4, 0, 4], [0, 4, 0, 0], [4, 0, 4, 1.5], [4, 2.5, 4, 4],
    [1.0, 3.0, 1.6, 3.0], [1.6, 3.0, 1.6, 3.4], [1.6, 3.4, 1.0, 3.4], [1.0, 3.4, 1.0, 3.0],
    [6.0, 0.6, 6.8, 0.6], [6.8, 0.6, 6.8, 1.0], [6.8, 1.0, 6.0, 1.0], [6.0, 1.0, 6.0, 0.6],
], float)
# the rooms are small and the route short (~240 scans, ~130 nodes): 20 nodes per submap instead of 90, so there
# are enough submaps for the route's return to the first room to be a revisit
LOCAL = LocalSlamConfig(scans_per_submap=20)
OBJECTS = {"O01": np.array([0.3, 0.5, 0.8]), "O02": np.array([7.6, 3.5, 1.0]), "O03": np.array([2.0, 3.8, 0.5])}
bTs = np.array([0.1, 0.0, 0.0])


def true_route(dt=0.05):
    """Out through the door to the far room, a loop there, back to the start room: (stamps_ns, wTb)."""
    way = np.array([[1.0, 1.0], [3.0, 2.0], [5.0, 2.0], [7.0, 2.0], [7.0, 3.0], [5.5, 3.0], [5.0, 2.0],
                    [3.0, 2.0], [1.5, 2.0], [1.0, 1.2]])
    pts = [way[0]]
    for a, b in zip(way[:-1], way[1:], strict=True):
        n = int(np.ceil(np.hypot(*(b - a)) / (0.3 * dt)))
        pts.append(a + (b - a) * np.linspace(0, 1, n + 1)[1:, None])
    xy = np.vstack(pts)
    head = np.arctan2(np.gradient(xy[:, 1]), np.gradient(xy[:, 0]))
    head = np.convolve(np.unwrap(head), np.ones(9) / 9, mode="same")
    head[:5], head[-5:] = head[5], head[-6]
    t = (np.arange(xy.shape[0]) * dt * 1e9).astype(np.int64) + 10**9
    return t, np.column_stack([xy, g.wrap(head)])


def make_log(seed=0, odo_scale=0.02, slip=0.002, compass_sigma=0.02, laser_sigma=0.01):
    rng = np.random.default_rng(seed)
    t, wTb = true_route()
    # odometry: per-step distance with a scale error and slip, wheel heading changes with noise
    d = np.hypot(*np.diff(wTb[:, :2], axis=0).T)
    dth = g.wrap(np.diff(wTb[:, 2]))
    s = d * (1 + odo_scale) + rng.normal(0, slip, d.size)
    dd = dth * 1.01 + rng.normal(0, 0.002, d.size)
    odo = integrate(np.zeros(3), s, dd)
    odometry = tuple(Odometry(int(k), Pose2(*p)) for k, p in zip(t, odo, strict=True))
    hs = t[::2] + 7_000_000
    yaw_true = np.interp(hs, t, np.unwrap(wTb[:, 2]))
    headings = tuple(Heading(int(k), float(g.wrap(y + 0.3 + rng.normal(0, compass_sigma))), compass_sigma)
                     for k, y in zip(hs, yaw_true, strict=True))
    st = t[::4]
    ang = np.radians(np.arange(-90, 91, 1.0))
    wTs = g.compose(wTb[::4], np.broadcast_to(bTs, wTb[::4].shape))
    R = raycast(WALLS, wTs[:, :2], wTs[:, 2:3] + ang[None], 8.0)
    R = R + rng.normal(0, laser_sigma, R.shape)
    scans = tuple(Scan(int(k), "laser", -math.pi / 2, math.radians(1.0), 0.05, 8.0, r.astype(np.float32),
                       np.isfinite(r)) for k, r in zip(st, R, strict=True))
    tf = (Transform(0, "base_link", "laser", (0.1, 0.0, 0.3), (0.0, 0.0, 0.0, 1.0), static=True),)
    # object observations: every 2 s when the object is within 3 m, in the base frame with 2 cm noise
    obs = []
    for k in range(0, t.size, 40):
        for oid, pw in OBJECTS.items():
            pb = g.transform_points(g.inverse(wTb[k]), pw[None, :2])[0]
            if np.hypot(*pb) < 3.0:
                cov = np.diag([0.02**2, 0.02**2, 0.02**2])
                obs.append(ObjectObservation(int(t[k]), oid, f"HL1;{oid};box", np.r_[pb + rng.normal(0, 0.02, 2),
                                             pw[2]], cov))
    log = LogData("synthetic", odometry=odometry, headings=headings, scans=scans, transforms=tf)
    return log, obs, t, wTb


def test_eq16_by_hand():
    # robot at (1, 2, 90 deg) in the anchor frame; an object 2 m ahead, 0.5 m up
    xy, cov, z = landmark_in_anchor(np.array([1.0, 2.0, math.pi / 2]), np.diag([0.0, 0.0, 0.01]),
                                    np.array([2.0, 0.0, 0.5]), np.diag([1e-4, 4e-4, 1e-4]))
    np.testing.assert_allclose(xy, [1.0, 4.0], atol=1e-12)
    assert z == 0.5
    # heading sigma 0.1 rad at 2 m range -> 0.2 m sideways (x in the anchor frame); range noise along y
    np.testing.assert_allclose(cov, [[4e-4 + 0.04, 0.0], [0.0, 1e-4]], atol=1e-12)


PROGRESS_CALLS: list[tuple[int, int]] = []  # what the fixture's front end reported
# the dead-reckoning noise model of the synthetic log above: 2 mm slip and 0.002 rad wheel-heading noise per
# 1.5 cm step (random walks of 0.016 m and 0.016 rad per sqrt(m)), its 2 % scale error within sigma_scale
SYNTHETIC_DR = DeadReckoningConfig(sigma_s_per_sqrt_m=0.016, odo_sigma_heading_per_sqrt_m=0.016)


@pytest.fixture(scope="module")
def frontend_run():
    log, obs, t, wTb = make_log()
    dr = SYNTHETIC_DR
    from holoslam.optimise import reestimate_anchors

    PROGRESS_CALLS.clear()
    fe = build_problem(
        log, obs, FrontEndConfig(dead_reckoning=dr, local=LOCAL), progress=lambda d, n: PROGRESS_CALLS.append((d, n)),
        optimize=reestimate_anchors,
    )
    return fe, log, obs, t, wTb


def test_progress_reports_the_scans_walked(frontend_run):
    _, log, *_ = frontend_run
    done = np.array([d for d, _ in PROGRESS_CALLS])
    totals = {n for _, n in PROGRESS_CALLS}
    assert len(totals) == 1 and 0 < totals.pop() <= len(log.scans)
    assert done[0] == 0 and np.all(np.diff(done) > 0) and 20 <= len(done) <= 50


def test_submaps_and_measurements(frontend_run):
    fe, log, obs, t, wTb = frontend_run
    P = fe.problem
    assert P.num_poses == len(fe.submaps) >= 4
    # submaps are started by node count (two active submaps, a new one when the younger holds half), not by
    # segmentation: each finished one holds scans_per_submap nodes, each anchor is a node of the previous submap
    assert {s.reason for s in fe.submaps} == {"scans"}
    counts = [len(s.scan_stamps_ns) for s in fe.submaps]
    assert all(c == LOCAL.scans_per_submap for c in counts[:-2]) and all(0 < c <= LOCAL.scans_per_submap
                                                                        for c in counts[-2:])
    for prev, sm in zip(fe.submaps[:-1], fe.submaps[1:], strict=True):
        assert sm.index == prev.index + 1 and sm.anchor_stamp_ns in set(prev.scan_stamps_ns.tolist())
    kinds = set(P.relative.kind.tolist())
    assert {"dead_reckoning", "scan_match"} <= kinds
    assert "loop" in kinds  # the route returns to the first room
    np.testing.assert_allclose(fe.bTs, bTs, atol=1e-12)
    # every relative measurement agrees with the truth within 5 sigma (per axis), but for loops the final solve
    # rejects: with the rotation prior measured on the real logs (60) one loop here is an alias 1.6 m off (none
    # with 100); the chi-square rounds must catch it
    truth_wTa = np.array([np.interp(fe.anchor_stamps_ns, t, wTb[:, c]) for c in range(2)] +
                         [np.interp(fe.anchor_stamps_ns, t, np.unwrap(wTb[:, 2]))]).T
    from holoslam.graph.problem import MeasurementFamily
    from holoslam.optimise import run_build_options
    from holoslam.solve import SolveOptions, solve

    rejected = {r.index for r in solve(P, SolveOptions(build=run_build_options())).rejected
                if r.family is MeasurementFamily.RELATIVE}
    wrong = []
    for r, (i, j, m, c, kind) in enumerate(zip(P.relative.i, P.relative.j, P.relative.iTj, P.relative.cov_iTj,
                                               P.relative.kind, strict=True)):
        true = g.between(truth_wTa[i], truth_wTa[j])
        e = g.between(true, m)
        z = np.abs(e) / np.sqrt(np.diag(c))
        # yaw of a scan match: 6 sigma. The matcher's heading floor (its angular step^2 / 12, ~0.2 deg) is
        # overconfident in this world: one anchor's heading errs 1.1 deg = 5.4 sigma with the rotation prior 60
        # (3.8 sigma at 100), and seed 3 of this world has 11 sigma with either: a known weakness
        if not np.all(z < (5.0, 5.0, 6.0 if kind == "scan_match" else 5.0)):
            wrong.append((r, kind, i, j, e, np.sqrt(np.diag(c))))
    assert all(kind == "loop" and r in rejected for r, kind, *_ in wrong), wrong
    assert len(wrong) <= 1, wrong
    # submap contents: anchor first at the identity; a probability grid whose likely-occupied cells (> 0.5) lie on
    # the walls and whose seen-free cells (below 0.5, above the unknown p_min) lie inside the rooms
    for sm, wTa in zip(fe.submaps, truth_wTa, strict=True):
        np.testing.assert_allclose(sm.aTb[0], 0.0, atol=1e-12)
        gr = sm.grid
        assert isinstance(gr, ProbGrid) and gr.prob.min() >= gr.p_min - 1e-6 and gr.prob.max() <= 0.9 + 1e-6
        occ = _cells_in_world(gr, gr.prob > 0.5, wTa)
        free = _cells_in_world(gr, (gr.prob < 0.5) & (gr.prob > gr.p_min + 1e-6), wTa)
        assert len(occ) > 50 and len(free) > 10 * len(occ)
        assert np.mean(_wall_distance(occ) < 0.1) > 0.95, np.mean(_wall_distance(occ) < 0.1)
        inside = (free[:, 0] > -0.1) & (free[:, 0] < 8.1) & (free[:, 1] > -0.1) & (free[:, 1] < 4.1)
        assert inside.mean() > 0.99
        assert sm.features.segments.shape[0] > 0
    # headings: one per anchor, with the compass's bias (0.3 rad) still in them
    hs = np.array([h.stamp_ns for h in log.headings])
    inside = (fe.anchor_stamps_ns >= hs[0]) & (fe.anchor_stamps_ns <= hs[-1])
    assert not inside[0] and inside[1:].all()  # the compass starts 7 ms after the first scan
    np.testing.assert_array_equal(P.headings.i, np.nonzero(inside)[0])
    bias = g.wrap(P.headings.yaw - truth_wTa[inside, 2])
    assert abs(np.median(bias) - 0.3) < 0.05
    assert len(P.landmarks) > 5 and set(P.landmarks.landmark) == set(OBJECTS)


def _cells_in_world(gr: ProbGrid, mask: np.ndarray, wTa: np.ndarray) -> np.ndarray:
    """World positions (true anchor pose) of the centres of the grid cells in ``mask``."""
    r, c = np.nonzero(mask)
    a_xy = np.column_stack([gr.origin[0] + (c + 0.5) * gr.resolution, gr.origin[1] + (r + 0.5) * gr.resolution])
    return g.transform_points(wTa, a_xy)


def _wall_distance(xy: np.ndarray) -> np.ndarray:
    """Distance of each point to the nearest wall segment of the world."""
    a, b = WALLS[:, :2], WALLS[:, 2:]
    ab = b - a
    t = np.clip(np.einsum("nmk,mk->nm", xy[:, None, :] - a[None], ab) / np.einsum("mk,mk->m", ab, ab), 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.min(np.hypot(*(xy[:, None, :] - closest).transpose(2, 0, 1)), axis=1)


def test_landmarks_in_anchor_frames_match_truth(frontend_run):
    fe, log, obs, t, wTb = frontend_run
    P = fe.problem
    truth_wTa = np.column_stack([np.interp(fe.anchor_stamps_ns, t, wTb[:, 0]),
                                 np.interp(fe.anchor_stamps_ns, t, wTb[:, 1]),
                                 np.interp(fe.anchor_stamps_ns, t, np.unwrap(wTb[:, 2]))])
    for i, name, xy, c in zip(P.landmarks.i, P.landmarks.landmark, P.landmarks.a_position,
                              P.landmarks.cov_a_position, strict=True):
        true_xy = g.transform_points(g.inverse(truth_wTa[i]), OBJECTS[name][None, :2])[0]
        e = xy - true_xy
        assert e @ np.linalg.solve(c, e) < 20.0, (name, i, e, np.sqrt(np.diag(c)))


def test_solver_recovers_truth(frontend_run):
    solve = pytest.importorskip("holoslam.solve")
    fe, log, obs, t, wTb = frontend_run
    if not hasattr(solve, "solve"):
        pytest.skip("holoslam.solve has no solve() yet")
    sol = solve.solve(fe.problem)
    truth = np.column_stack([np.interp(fe.anchor_stamps_ns, t, wTb[:, c]) for c in range(2)])
    est = sol.wTa[:, :2]
    # align the first anchor (the gauge) and compare
    T = g.compose(np.array([*truth[0], np.interp(fe.anchor_stamps_ns[0], t, np.unwrap(wTb[:, 2]))]),
                  g.inverse(sol.wTa[0]))
    err = np.hypot(*(g.transform_points(T, est) - truth).T)
    dr = np.column_stack([np.interp(fe.anchor_stamps_ns, fe.dr_stamps_ns, fe.dr_wTb[:, 0]),
                          np.interp(fe.anchor_stamps_ns, fe.dr_stamps_ns, fe.dr_wTb[:, 1]),
                          np.interp(fe.anchor_stamps_ns, fe.dr_stamps_ns, np.unwrap(fe.dr_wTb[:, 2]))])
    T_dr = g.compose(np.array([*truth[0], np.interp(fe.anchor_stamps_ns[0], t, np.unwrap(wTb[:, 2]))]),
                     g.inverse(dr[0]))
    err_dr = np.hypot(*(g.transform_points(T_dr, dr[:, :2]) - truth).T)
    rmse, rmse_dr = np.sqrt(np.mean(err**2)), np.sqrt(np.mean(err_dr**2))
    assert rmse < 0.05 and rmse < 0.5 * rmse_dr, (rmse, rmse_dr)


def test_loops_per_submap_pair_are_bounded_and_never_chain_neighbours(frontend_run):
    # several nodes of a new submap may close against one old submap, up to LoopConfig.max_per_pair
    fe = frontend_run[0]
    P = fe.problem.relative
    loop = P.kind == "loop"
    pairs = list(zip(P.i[loop].tolist(), P.j[loop].tolist(), strict=True))
    assert pairs
    per_pair = {p: pairs.count(p) for p in set(pairs)}
    assert max(per_pair.values()) <= LoopConfig().max_per_pair
    # never the submaps just before (their relation is the chain of scan matches)
    assert all(i < j - LoopConfig().skip_recent for i, j in pairs)
    # the chain: one dead-reckoning and one scan-match relation per consecutive pair of anchors
    for kind in ("dead_reckoning", "scan_match"):
        k = P.kind == kind
        assert P.i[k].tolist() == list(range(len(fe.submaps) - 1)) and np.array_equal(P.j[k], P.i[k] + 1)


def test_without_compass_and_camera_scan_only_loops_recover_truth():
    # a robot with odometry + laser + tf only: no headings, no observations
    from holoslam.evaluate import trajectory_errors, truth_at

    log, _, t, wTb = make_log(seed=1)
    bare = dataclasses.replace(log, headings=(), images=(), camera_infos=(), tags=())
    from holoslam.optimise import reestimate_anchors, run_build_options

    fe = build_problem(bare, (), FrontEndConfig(local=LOCAL), optimize=reestimate_anchors)
    P = fe.problem
    assert len(P.headings) == 0 and len(P.landmarks) == 0
    assert "loop" in set(P.relative.kind.tolist())
    solve = pytest.importorskip("holoslam.solve")
    sol = solve.solve(P, solve.SolveOptions(build=run_build_options()))  # as the pipeline solves (Huber loops)
    truth = truth_at(fe.anchor_stamps_ns, t, wTb)
    err = trajectory_errors(sol.wTa, truth)
    dr = trajectory_errors(truth_at(fe.anchor_stamps_ns, fe.dr_stamps_ns, fe.dr_wTb), truth)
    # measured 0.030 m against dead reckoning's 0.048 m (0.023 m with the rotation prior 100 of an earlier
    # default: in this world the odometry's heading is better than fr079's, and a strong prior suits it)
    assert err.rmse_m < 0.04 and err.rmse_m < 0.7 * dr.rmse_m, (err.rmse_m, dr.rmse_m)


def test_object_whose_two_sightings_disagree_is_ambiguous(frontend_run):
    fe, log, obs, t, wTb = frontend_run
    assert fe.ambiguous_objects == ()  # clean sightings always agree
    counts = {}
    for o in obs:
        counts[o.object_id] = counts.get(o.object_id, 0) + 1
    name = max(counts, key=counts.get)
    assert counts[name] >= 2
    mine = [o for o in obs if o.object_id == name][:2]
    bad = ObjectObservation(mine[1].stamp_ns, name, mine[1].payload, mine[1].b_position + np.array([1.5, 0.0, 0.0]),
                            mine[1].cov_b_position)
    others = [o for o in obs if o.object_id != name]
    dr = SYNTHETIC_DR
    fe2 = build_problem(log, others + [mine[0], bad], FrontEndConfig(dead_reckoning=dr, build_grids=False))
    assert fe2.ambiguous_objects == (name,)
    assert name not in set(fe2.problem.landmarks.landmark)
    # three sightings with a majority are left to the solver's outlier rejection
    fe3 = build_problem(log, others + mine + [bad], FrontEndConfig(dead_reckoning=dr, build_grids=False))
    assert fe3.ambiguous_objects == () and name in set(fe3.problem.landmarks.landmark)


def test_initial_landmark_is_the_agreeing_majority_not_the_first_sighting(frontend_run):
    fe, log, obs, t, wTb = frontend_run
    name = sorted(OBJECTS)[0]
    mine = sorted((o for o in obs if o.object_id == name), key=lambda o: o.stamp_ns)
    assert len(mine) >= 2
    first = mine[0]
    bad = ObjectObservation(first.stamp_ns - 1, name, first.payload, first.b_position + np.array([0.0, 1.5, 0.0]),
                            first.cov_b_position)  # a wrong sighting before all the good ones
    dr = SYNTHETIC_DR
    fe2 = build_problem(log, [bad, *obs], FrontEndConfig(dead_reckoning=dr, build_grids=False))
    init = fe2.problem.initial_landmarks[name]
    # the initial estimate (world frame of the first anchor = the truth's first pose, up to drift) is near the
    # clean estimate, not 1.5 m off
    clean = fe.problem.initial_landmarks[name]
    assert np.hypot(*(init - clean)) < 0.1


def test_motion_filter_is_exactly_distance_turn_or_time():
    # a scan becomes a node when the robot moved motion_distance, turned motion_turn_deg or waited motion_time_s
    # since the last node, measured on the odometry; nothing else
    rng = np.random.default_rng(5)
    cfg = LocalSlamConfig()
    slam = LocalSlam(cfg, bTs)
    assert slam.wants(0, np.zeros(3))  # the first scan always
    last = np.array([1.0, -2.0, 3.1])
    slam._last_odo, slam._last_stamp = last, 10**9
    step = np.column_stack([rng.uniform(-0.3, 0.3, (4000, 2)), rng.uniform(-0.03, 0.03, 4000)])
    step[:50, :2] = step[:50, :2] / np.hypot(*step[:50, :2].T)[:, None] * cfg.motion_distance  # on the edge
    step[:50, 2] = 0.0
    dt = rng.uniform(0.0, 2.0 * cfg.motion_time_s, 4000)
    odo = g.compose(np.broadcast_to(last, step.shape), step)
    got = np.array([slam.wants(10**9 + int(d * 1e9), o) for d, o in zip(dt, odo, strict=True)])
    dist, turn = np.hypot(step[:, 0], step[:, 1]), np.abs(step[:, 2])
    exact = (dist >= cfg.motion_distance - 1e-12) | (turn >= math.radians(cfg.motion_turn_deg)) | (
        dt >= cfg.motion_time_s)
    clear = np.abs(dist - cfg.motion_distance) > 1e-9
    assert np.array_equal(got[clear], exact[clear]) and got[:50].mean() > 0.4  # the edge: rounding either way
    assert 500 < got.sum() < 3900


def test_nodes_are_the_scans_past_the_motion_filter_and_the_others_are_tracked(frontend_run):
    fe, log, obs, t, wTb = frontend_run
    ost, opose = log.odometry_arrays()
    from holoslam.geometry import interpolate_poses

    nodes = np.unique(np.concatenate([sm.scan_stamps_ns for sm in fe.submaps]))
    tracked = np.concatenate([sm.track_stamps_ns for sm in fe.submaps])
    scans = np.array([s.stamp_ns for s in log.scans], dtype=np.int64)
    assert nodes[0] == scans[0] and len(nodes) < len(scans)
    # walk the scans: each is a node exactly when the motion filter passes from the last node
    cfg = LOCAL
    odo = interpolate_poses(ost, opose, scans)
    last = 0
    for k in range(1, len(scans)):
        d = g.between(odo[last], odo[k])
        moved = (math.hypot(d[0], d[1]) >= cfg.motion_distance or abs(d[2]) >= math.radians(cfg.motion_turn_deg)
                 or scans[k] - scans[last] >= cfg.motion_time_s * 1e9)
        assert moved == (scans[k] in set(nodes.tolist())), k
        if moved:
            last = k
    # the scans between nodes are localised in their submap too (match_every_scan), near the truth
    others = np.setdiff1d(scans, nodes)
    assert len(np.intersect1d(tracked, nodes)) == 0 and np.mean(np.isin(others, tracked)) > 0.9
    truth_wTa = np.column_stack([np.interp(fe.anchor_stamps_ns, t, wTb[:, 0]), np.interp(fe.anchor_stamps_ns, t, wTb[:, 1]),
                                 np.interp(fe.anchor_stamps_ns, t, np.unwrap(wTb[:, 2]))])
    for sm in fe.submaps:
        if len(sm.track_stamps_ns) == 0:
            continue
        true_b = np.column_stack([np.interp(sm.track_stamps_ns, t, wTb[:, 0]), np.interp(sm.track_stamps_ns, t, wTb[:, 1])])
        est_b = g.transform_points(truth_wTa[sm.index], sm.track_aTb[:, :2])
        assert np.max(np.hypot(*(est_b - true_b).T)) < 0.075  # measured 12-50 mm per submap (prior 30)


def test_observation_before_the_first_scan_goes_to_anchor_0_by_dead_reckoning_back():
    # the laser starts 2 s after odometry and camera (the first 10 scans dropped): sightings in those 2 s are
    # placed in anchor 0 through the odometry between them and the first scan, not dropped
    log, obs, t, wTb = make_log(seed=3)
    late = dataclasses.replace(log, scans=log.scans[10:])
    first = late.scans[0].stamp_ns
    early = [o for o in obs if o.stamp_ns < first]
    assert early, "the synthetic log must have sightings before the first kept scan"
    fe = build_problem(late, obs, FrontEndConfig(build_grids=False))
    assert fe.skipped_observations == 0
    P = fe.problem
    a0 = np.array([np.interp(first, t, wTb[:, 0]), np.interp(first, t, wTb[:, 1]),
                   np.interp(first, t, np.unwrap(wTb[:, 2]))])
    rows = np.flatnonzero(P.landmarks.i == 0)[: len(early)]
    assert len(rows) == len(early)
    for r in rows:
        name, xy, c = P.landmarks.landmark[r], P.landmarks.a_position[r], P.landmarks.cov_a_position[r]
        e = xy - g.transform_points(g.inverse(a0), OBJECTS[name][None, :2])[0]
        assert e @ np.linalg.solve(c, e) < 20.0 and np.hypot(*e) < 0.1, (name, e)


def test_the_anchors_are_re_solved_only_for_a_closure_the_estimate_contradicts():
    from types import SimpleNamespace

    from holoslam.submaps.anchor_graph import AnchorGraph

    G = AnchorGraph(np.zeros(3))
    G.est.append(np.array([10.0, 0.0, 0.0]))  # anchor 1 estimated 10 m ahead of anchor 0
    cov = np.diag([0.05**2, 0.05**2, np.radians(1.0) ** 2])
    agrees = SimpleNamespace(old=0, new=1, mTn=np.array([10.08, 0.0, 0.0]), cov_mTn=cov)  # 1.6 sigma
    contradicts = SimpleNamespace(old=0, new=1, mTn=np.array([10.3, 0.0, 0.0]), cov_mTn=cov)  # 6 sigma
    min_d2 = LoopConfig().resolve_min_d2
    assert not G.disagree([agrees], min_d2)
    assert G.disagree([agrees, contradicts], min_d2)
    assert G.disagree([agrees], 0.0)  # 0: always re-solved


def test_the_estimate_is_compared_with_dead_reckoning_alone_within_one_part_of_the_run():
    from holoslam.submaps.anchor_graph import AnchorGraph

    G = AnchorGraph(np.zeros(3))
    step = np.array([10.0, 0.0, 0.0])
    for k in range(4):  # scan matches 10 m ahead each; dead reckoning 10.1 m and 0.01 rad to the left each
        G.add_anchor(k, step, np.array([10.1, 0.0, 0.01]), 10.0 * (k + 1), lost=False)
    G.add_anchor(4, step, np.array([30.0, 5.0, 1.0]), 50.0, lost=True)  # a break: the robot carried
    G.add_anchor(5, step, step, 60.0, lost=False)
    xy, th = G.dead_reckoning_disagreement(4)
    dr_0T4 = g.compose(g.compose(g.compose(np.array([10.1, 0.0, 0.01]), np.array([10.1, 0.0, 0.01])),
                                 np.array([10.1, 0.0, 0.01])), np.array([10.1, 0.0, 0.01]))
    e = g.between(dr_0T4, np.array([40.0, 0.0, 0.0]))
    assert xy[0] == pytest.approx(math.hypot(e[0], e[1])) and th[0] == pytest.approx(0.04)
    assert xy[4] == pytest.approx(0.0, abs=1e-12) and xy[3] == pytest.approx(math.hypot(*g.between(np.array([10.1, 0.0, 0.01]), step)[:2]))
    assert np.isinf(xy[5]) and np.isinf(th[6])  # the other side of the break: no bound
    xy6, _ = G.dead_reckoning_disagreement(6)
    assert np.all(np.isinf(xy6[:5])) and xy6[5:] == pytest.approx([0.0, 0.0], abs=1e-12)


def test_the_scan_rate_ignores_bursts_of_stamps_and_stops():
    """``scan_rate_hz``: 5 Hz scans, some stamped in bursts 1 ms apart (as intel's log) and a 60 s stop: 5 Hz."""
    from holoslam.submaps.frontend import scan_rate_hz

    t = np.arange(600) * 0.2
    t[100:110] = t[100] + np.arange(10) * 0.001  # a burst, then the next scans at their times
    t[300:] += 60.0  # a stop
    assert scan_rate_hz((t * 1e9).astype(np.int64)) == pytest.approx(5.0, rel=0.02)
    assert scan_rate_hz(np.arange(5, dtype=np.int64)) == 0.0


def test_the_loop_search_runs_every_kth_node_once_the_robot_moved_or_turned():
    """``_search_due``: every ``every_nodes``-th node, and with ``every_m`` / ``every_deg`` only once the robot
    moved or turned that much since the node that searched last (the first due node always searches)."""
    from holoslam.submaps.frontend import _search_due

    cfg = LoopConfig(every_nodes=3, every_m=0.3, every_deg=30.0)
    assert not _search_due(cfg, (4, 5.0, 0.0), None)  # not a 3rd node
    assert _search_due(cfg, (3, 0.0, 0.0), None)  # the first search
    last = (3, 0.0, 0.0)
    assert not _search_due(cfg, (6, 0.29, math.radians(29.0)), last)  # neither moved nor turned enough
    assert _search_due(cfg, (6, 0.30, 0.0), last)  # moved
    assert _search_due(cfg, (6, 0.0, math.radians(-31.0)), last)  # turned the other way
    assert _search_due(cfg, (6, 0.0, math.radians(179.0)), (3, 0.0, math.radians(-179.0))) is False  # 2 deg
    assert _search_due(LoopConfig(every_nodes=3, every_m=0.0, every_deg=0.0), (6, 0.0, 0.0), last)  # off: by count


def test_the_disagreement_window_turns_on_once_local_slams_matches_were_blind_often_enough():
    """``_blind_enough``: judged from the 500th matched node on, at the share ``disagreement_window_blind_share``."""
    from holoslam.submaps.frontend import _BLIND_SHARE_NODES, _blind_enough
    from holoslam.submaps.loop_config import LoopConfig
    from holoslam.submaps.odometer import OdometerCorrectionConfig, OdometerWatch

    watch = OdometerWatch(OdometerCorrectionConfig(), np.zeros(1, np.int64), np.zeros((1, 3)))
    cfg = LoopConfig()  # 5 %
    for k in range(_BLIND_SHARE_NODES - 1):
        watch.add(k, 0, np.zeros(3), blind=k % 10 == 0)  # 10 % blind
    assert not _blind_enough(cfg, watch)  # too soon to judge
    watch.add(_BLIND_SHARE_NODES, 0, np.zeros(3), blind=False)
    assert watch.blind_share == pytest.approx(0.1) and _blind_enough(cfg, watch)
    assert not _blind_enough(LoopConfig(disagreement_window_blind_share=0.11), watch)
    assert not _blind_enough(LoopConfig(disagreement_window=0.0), watch)  # the window off: never
    with pytest.raises(ValueError, match="disagreement_window_blind_share"):
        from holoslam.submaps.loops import LoopSearch
        from holoslam.submaps.scanmatch import MatchConfig

        LoopSearch(LoopConfig(disagreement_window_blind_share=float("nan")), MatchConfig())
