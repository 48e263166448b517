"""Keyframes solved against the old submaps they revisit (``holoslam.submaps.revisits``, ``holoslam.graph.nodes``):
a warped submap's revisiting keyframes are pulled onto the old submap's map of the place; on a cut of the real
intel log (its robot circles the lab and comes back through the same corridors) the relations between passes
through one place get better, the short ones no worse."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from repo_paths import SHARED

from holoslam import geometry as g
from holoslam.graph.nodes import solve_nodes
from holoslam.submaps.revisits import NodeMatches, Nodes, graph_nodes

REALDATA = SHARED / "realdata"


def test_a_keyframe_belongs_to_the_submap_it_was_matched_into():
    """A node inserted into two submaps (the older it was matched into, the younger it was carried into) is
    listed once, with the older one as host and its pose there."""
    s0 = SimpleNamespace(index=0, scan_stamps_ns=np.array([10, 20, 30]), aTb=np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]]),
                         cov_aTb=np.zeros((3, 3, 3)), scan_points=(np.zeros((1, 2)),) * 3)
    s1 = SimpleNamespace(index=1, scan_stamps_ns=np.array([30, 40]), aTb=np.array([[0, 0, 0], [1, 0, 0]]),
                         cov_aTb=np.zeros((2, 3, 3)), scan_points=(np.zeros((1, 2)),) * 2)
    nodes = graph_nodes([s1, s0])
    assert nodes.stamps_ns.tolist() == [10, 20, 30, 40]
    assert nodes.host.tolist() == [0, 0, 0, 1]
    assert nodes.aTb[2].tolist() == [2, 0, 0] and nodes.aTb[3].tolist() == [1, 0, 0]
    # the shared node remembers its second submap and its pose there (the disputed nodes' second placement)
    assert nodes.second.tolist() == [-1, -1, 1, -1] and nodes.second_aTb[2].tolist() == [0, 0, 0]


def _slipped(second: bool):
    """Five nodes in submap 1 (host) and submap 2 (second), 0.5 m apart along x in both. The solved anchors place
    submap 2 one metre further along than submap 1 (the closures of the nodes after a slip inside submap 1 moved
    submap 2's anchor): by their host the nodes lie 1 m short of where their scans are; each node's match into
    the old submap 0 (the world's frame) says where (the truth, by submap 2)."""
    x = np.arange(5) * 0.5
    aTb = np.column_stack([x, np.zeros(5), np.zeros(5)])
    cov = np.broadcast_to(np.diag([0.02**2, 0.02**2, np.radians(0.5) ** 2]), (5, 3, 3)).copy()
    nodes = Nodes(np.arange(5, dtype=np.int64), np.ones(5, np.int64), aTb, cov, (np.zeros((0, 2)),) * 5,
                  np.full(5, 2 if second else -1, np.int64), aTb.copy())
    wTa = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    truth = aTb + [1.0, 0.0, 0.0]
    matches = NodeMatches(np.zeros(5, np.int64), np.arange(5), truth,
                          np.broadcast_to(np.diag([1e-4, 1e-4, np.radians(0.2) ** 2]), (5, 3, 3)), np.full(5, 0.7))
    return nodes, wTa, truth, matches


def test_nodes_two_solved_anchors_place_apart_are_placed_by_their_matches():
    """A slip of local SLAM inside a submap: the nodes it shares with the next are placed 1 m apart by the two
    solved anchors (more than ``max_shift_m``): disputed, their host ties and steps are robust, and their matches
    into the old submap place them (``revisits.disputed_nodes``). Without the second placement the host's tie
    holds them a metre off."""
    from holoslam.submaps.revisits import RevisitConfig, disputed_nodes

    cov_wTa = np.broadcast_to(np.diag([1e-6, 1e-6, 1e-8]), (3, 3, 3))
    nodes, wTa, truth, matches = _slipped(second=True)
    assert disputed_nodes(nodes, wTa, RevisitConfig().max_shift_m).all()
    assert not disputed_nodes(nodes, wTa, 1.5).any()  # placements 1 m apart agree within 1.5 m
    lone, _, _, _ = _slipped(second=False)
    assert not disputed_nodes(lone, wTa, 0.3).any()
    held = solve_nodes(lone, matches, wTa, cov_wTa)
    freed = solve_nodes(nodes, matches, wTa, cov_wTa)
    held_err = np.hypot(*(held.wTn[:, :2] - truth[:, :2]).T)
    freed_err = np.hypot(*(freed.wTn[:, :2] - truth[:, :2]).T)
    assert held_err.min() > 0.9  # measured 0.97 m: the host's tie (2 cm) outweighs one robust match each
    assert freed_err.max() < 0.03  # measured 1.0 cm: robust both ways, the match (1.4 cm with its floor) places it


def test_bad_settings_are_a_config_error_that_names_them():
    from holoslam.errors import ConfigError
    from holoslam.submaps.revisits import RevisitConfig

    with pytest.raises(ConfigError, match="sample_every"):
        RevisitConfig(sample_every=0)
    with pytest.raises(ConfigError, match="keyframe_distance_m = -1"):
        RevisitConfig(keyframe_distance_m=-1.0)


def _corridor_there_and_back():
    """Submap 0: 21 nodes from x = 0 to 4 m. Submap 1, anchored at (4, 0) facing back: 21 nodes back to x = 0,
    its map warped sideways by 1.25 cm per metre from its anchor (5 cm at the far end), within its covariance."""
    d = np.linspace(0.0, 4.0, 21)
    true0 = np.column_stack([d, np.zeros(21), np.zeros(21)])
    aTb1_true = np.column_stack([d, np.zeros(21), np.zeros(21)])
    wTa = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, np.pi]])
    warped = aTb1_true + np.column_stack([np.zeros(21), 0.0125 * d, np.zeros(21)])
    sig = 0.005 + 0.0125 * np.concatenate([d, d])
    cov = np.zeros((42, 3, 3))
    cov[:, 0, 0] = cov[:, 1, 1] = sig**2
    cov[:, 2, 2] = np.radians(0.2) ** 2
    nodes = Nodes(np.arange(42, dtype=np.int64), np.repeat([0, 1], 21), np.vstack([true0, warped]), cov,
                  (np.zeros((0, 2)),) * 42)
    truth = np.vstack([true0, g.compose(np.broadcast_to(wTa[1], (21, 3)), aTb1_true)])
    return nodes, wTa, truth


def test_revisiting_keyframes_are_pulled_onto_the_old_submap():
    nodes, wTa, truth = _corridor_there_and_back()
    back = np.arange(31, 42)  # submap 1's nodes in the first half of the corridor (x <= 2 m), seen by submap 0
    matches = NodeMatches(np.zeros(len(back), np.int64), back, truth[back],  # submap 0's frame is the world's
                          np.broadcast_to(np.diag([1e-4, 1e-4, np.radians(0.2) ** 2]), (len(back), 3, 3)),
                          np.full(len(back), 0.7))
    cov_wTa = np.broadcast_to(np.diag([1e-6, 1e-6, 1e-8]), (2, 3, 3))
    rigid = solve_nodes(nodes, NodeMatches(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)),
                                           np.zeros((0, 3, 3)), np.zeros(0)), wTa, cov_wTa)
    solved = solve_nodes(nodes, matches, wTa, cov_wTa)
    before = np.hypot(*(rigid.wTn[:, :2] - truth[:, :2]).T)
    after = np.hypot(*(solved.wTn[:, :2] - truth[:, :2]).T)
    assert before[back].max() == pytest.approx(0.05, abs=0.002)  # no node match: the rigid submap, 3.8-5 cm off
    assert after[back].max() < 0.012  # measured 0.8 cm: the old submap's map holds them
    assert after[:21].max() < 0.002  # submap 0's own nodes stay where they were
    steps = np.delete(np.hypot(*np.diff(solved.wTn[:, :2], axis=0).T), 20)  # (node 21 is where node 20 turned)
    assert np.abs(steps - 0.2).max() < 0.02  # and the corridor walk stays smooth
    assert solved.error < 0.5 * solved.initial_error  # measured 4.3 from 23.7


@pytest.fixture(scope="module")
def intel_cut(tmp_path_factory):
    from holoslam.evaluate import relation_errors
    from holoslam.io.mcap import read_log
    from holoslam.io.mcap_cut import cut_log
    from holoslam.io.relations import cut_relations, read_relations
    from holoslam.optimise import reestimate_anchors, run_build_options
    from holoslam.solve import SolveOptions, solve
    from holoslam.submaps.frontend import build_problem
    from holoslam.submaps.revisits import RevisitConfig, match_nodes
    from holoslam.trajectory import keyframe_poses, node_keyframe_poses, optimised_trajectory

    path = tmp_path_factory.mktemp("intel") / "cut.mcap"
    cut_log(REALDATA / "intel.mcap", path, 0.0, 900.0)
    log, _ = read_log(path, require=["odometry", "scan"])
    fe = build_problem(log, optimize=reestimate_anchors)
    sol = solve(fe.problem, SolveOptions(build=run_build_options()))
    nodes = graph_nodes(fe.submaps)
    matches = match_nodes(fe.submaps, nodes, sol.wTa, RevisitConfig(threads=2))
    one = match_nodes(fe.submaps, nodes, sol.wTa, RevisitConfig(threads=1))
    ns = solve_nodes(nodes, matches, sol.wTa, sol.cov_wTa)
    stamps = np.array([s.stamp_ns for s in log.scans], dtype=np.int64)
    ost, opose = log.odometry_arrays()
    rel = cut_relations(read_relations(REALDATA / "intel.relations"), int(stamps[0]), int(stamps[-1]))
    rigid = optimised_trajectory(stamps, ost, opose, *keyframe_poses(fe.submaps, sol.wTa))
    solved = optimised_trajectory(stamps, ost, opose, *node_keyframe_poses(fe.submaps, nodes.stamps_ns, ns.wTn))
    far = (np.asarray(rel.t2_ns) - np.asarray(rel.t1_ns)) >= 30_000_000_000
    return relation_errors(stamps, rigid, rel), relation_errors(stamps, solved, rel), far, matches, one


@pytest.mark.slow
@pytest.mark.skipif(not (REALDATA / "intel.mcap").exists(), reason="../shared/realdata is not here")
def test_relations_between_passes_through_one_place_improve_on_a_real_log(intel_cut):
    """The first 900 s of intel: 898 relations, 311 of them between poses >= 30 s apart (passes through one
    place). Measured 2026-12-02: those 0.048 m with rigid submaps -> 0.034 m with the keyframes solved (1,462 of
    1,959 node matches kept); the others 0.0233 -> 0.0226 m; all 0.0318 -> 0.0266 m (Cartographer, whole log:
    0.0229). Bounds about 1.3x the measurement, so a 2x regression fails. 2026-12-04, with the matcher's
    seed_margin the rigid submaps are better: far relations 0.0320 -> 0.0272 m (0.85x)."""
    rigid, solved, far, matches, _ = intel_cut
    assert solved.n_matched == solved.n_relations >= 850
    t_r, t_s = rigid.translation_m, solved.translation_m
    assert far.sum() >= 300
    assert np.nanmean(t_s[far]) < 0.045
    assert np.nanmean(t_s[far]) < 0.9 * np.nanmean(t_r[far])
    assert np.nanmean(t_s[~far]) < 1.05 * np.nanmean(t_r[~far])
    assert solved.translation_mean_m < 0.032 and solved.translation_max_m < 0.6
    assert len(matches) > 0.5 * matches.tried


@pytest.mark.slow
@pytest.mark.skipif(not (REALDATA / "intel.mcap").exists(), reason="../shared/realdata is not here")
def test_node_matches_are_the_same_in_threads_as_in_one(intel_cut):
    """The node matches run in a thread pool (``RevisitConfig.threads``): two threads find exactly what one
    finds, in the same order (each match is independent; the kernels release the GIL)."""
    matches, one = intel_cut[3], intel_cut[4]
    assert len(one) > 1000 and matches.tried == one.tried
    for k in ("submap", "node", "aTb", "cov_aTb", "score"):
        assert np.array_equal(getattr(matches, k), getattr(one, k)), k
