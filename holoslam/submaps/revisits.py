"""Revisited places: the keyframes (nodes) of a solved run matched into the older submaps they lie in.

The anchor graph ties submaps together by loop closures between their anchors, each submap rigid. A submap is
built from up to 90 matched scans over metres of travel, and its far end drifts from its anchor by a few
centimetres (``LocalSlamConfig.map_drift_per_m``): where the robot comes back, its pose in the new submap and
the old submap's map of the same place then disagree by that much, though each is accurate locally. Cartographer
(Hess et al. 2016, §V) keeps every node's pose as a variable and constrains nodes to every submap near them; this
module finds those constraints once the anchors are solved, and ``holoslam.graph.nodes`` solves for the nodes.

``match_nodes``: every ``sample_every``-th node is matched into the old submaps (not its own, not its chain
neighbours) that hold a keyframe within ``keyframe_distance_m`` of it (the robot stood there, so the scan sees what that
submap mapped), the ``max_submaps`` nearest first, by the real-time matcher (correlative window + refinement,
``scanmatch.match_scan``) seeded by the solved anchors; a match is kept when it scores like a loop closure and
lies within ``max_shift_m`` of the seed (the anchors are solved: a larger shift is an alias).

Disputed nodes (``disputed_nodes``). A node inserted into two submaps is placed twice by the solved anchors, once
by each; they agree to a few centimetres, unless local SLAM slipped inside one of the submaps (a wide search of
its matcher taking a pose a metre back along a corridor, ``MatchConfig.wide_*``): the loop closures of the nodes
after the slip then move that submap's anchor by the slip, and the two placements of the nodes the submaps share
differ by it. On intel at 1.4 Hz with 12 % of its returns dropped (one draw), the 2,267 shared nodes agree to
0.030 m median but those of two submaps differ by 0.82-0.99 m, and the nodes after the slip are placed by their
host (the older submap) a metre from where their scans are. More than ``max_shift_m`` apart, the two placements
cannot both be the solved anchors' few centimetres from the truth: every node of such a pair is matched from both
placements (either may be the right one), and in the node solve its tie to its host and its steps to its
neighbours are robust (``holoslam.graph.nodes``), so that its matches into the old submaps place it.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from holoslam import geometry as g
from holoslam.submaps.scanmatch import MatchConfig, match_scan

__all__ = ["RevisitConfig", "Nodes", "NodeMatches", "graph_nodes", "match_nodes", "disputed_nodes"]


@dataclass(frozen=True, slots=True)
class RevisitConfig:
    """Settings of the node constraints and of the node solve (``holoslam.graph.nodes``).

    The sampling is denser than Cartographer's constraint builder's (sampling ratio 0.3). Old submaps within 6 m, the 6
    nearest: measured on the three real logs (relation error, whole logs, CPU of the matching on a loaded
    machine): every 3rd node / 3 m / 3 submaps gave intel 0.0216, aces 0.0375, fr079 0.0684 m (10, 2, 5 s);
    3 / 6 m / 6 gave 0.0209, 0.0373, 0.0683 (15, 4, 9 s); 2 / 5 m / 5 gave intel 0.0203 (20 s); rigid submaps
    0.0311, 0.0387, 0.0704. With local SLAM's laser prediction (2026-12-02), every 2nd node instead of every 3rd:
    intel 0.0195 -> 0.0190 m, aces 0.0368 -> 0.0367, fr079 0.0661 -> 0.0660 (0.454 -> 0.442 deg), and the
    simulated household's anchors 5.3 -> 4.9 mm (every node: 4.9 mm at 3x the matches), for about 1.5x the
    matching (intel +4 s). 5 deg covers the solved anchors' heading error (0.2-0.5 deg) with margin (20 deg
    gave the same poses at 1.5x the cost)."""

    enabled: bool = True
    sample_every: int = 2  # nodes: match every k-th node (Cartographer samples 30 % of node-submap pairs)
    keyframe_distance_m: float = 6.0  # m: an old submap is tried when one of its keyframes lies this near the node
    max_submaps: int = 6  # old submaps tried per node, the nearest first
    skip_recent: int = 2  # submaps this many before or after the node's own are its chain neighbours: skipped
    angular_window_deg: float = 5.0  # deg, half-width of the correlative window (the anchors are solved)
    min_score: float = 0.55  # mean probability, as a loop closure's (``LoopConfig.min_score``)
    max_shift_m: float = 0.3  # m from the solved anchors' seed; farther is an alias
    # the node solve: consecutive nodes' relative pose from their matched poses, 1 sigma = floor + rate x step.
    # Floor: a 5 cm cell's lattice (1.4 cm) and 0.5 deg (the matcher's angular step at 6 m); rate: the in-submap
    # motion scale error measured on intel (2 % short of the ground truth's over 1,308 short relations)
    step_sigma_m: float = 0.01
    step_sigma_deg: float = 0.5
    step_sigma_rate: float = 0.02  # per unit of the step (m/m and rad/rad)
    huber_k: float = 1.0  # whitened residual where a node match's cost turns linear (a match may be an alias)
    match_floor_m: float = 0.01  # m, floor of a node match's sigma (the score surface's lattice floor is 1.4 cm)
    match_floor_deg: float = 0.2
    # threads matching nodes at once (0: one per core). The matches are independent and the matcher's kernels
    # release the GIL, so the result is the same for any count (it sets the stage's wall time, not its result)
    threads: int = 0

    def __post_init__(self) -> None:
        from holoslam.errors import ConfigError

        if self.sample_every < 1 or self.max_submaps < 1 or self.skip_recent < 0 or self.threads < 0:
            raise ConfigError(f"frontend.revisits: sample_every and max_submaps must be >= 1, skip_recent and threads "
                              f">= 0, got {self.sample_every}, {self.max_submaps}, {self.skip_recent}, {self.threads}")
        positive = {"keyframe_distance_m": self.keyframe_distance_m, "angular_window_deg": self.angular_window_deg,
                    "max_shift_m": self.max_shift_m, "step_sigma_m": self.step_sigma_m,
                    "step_sigma_deg": self.step_sigma_deg, "huber_k": self.huber_k,
                    "match_floor_m": self.match_floor_m, "match_floor_deg": self.match_floor_deg}
        bad = [f"{k} = {v}" for k, v in positive.items() if not v > 0]
        if bad or self.step_sigma_rate < 0:
            raise ConfigError(f"frontend.revisits: {', '.join(bad) or f'step_sigma_rate = {self.step_sigma_rate}'} "
                              "must be > 0 (step_sigma_rate >= 0); fix the run configuration")


@dataclass(frozen=True, eq=False)
class Nodes:
    """The run's keyframes, once each, by stamp: the submap they were matched into (``host``) and their base pose
    there with its covariance, and their scan points (base frame); ``second`` the other submap a node was inserted
    into (-1: none) and its pose there, ``second_aTb``."""

    stamps_ns: np.ndarray  # (N,)
    host: np.ndarray  # (N,)
    aTb: np.ndarray  # (N, 3)
    cov_aTb: np.ndarray  # (N, 3, 3)
    b_points: tuple[np.ndarray, ...]
    second: np.ndarray | None = None  # (N,) int, -1 where none; None: not known (every node in its host only)
    second_aTb: np.ndarray | None = None  # (N, 3)

    def __len__(self) -> int:
        return len(self.stamps_ns)


@dataclass(frozen=True, eq=False)
class NodeMatches:
    """Node ``node[m]`` matched into submap ``submap[m]``: its base pose ``aTb[m]`` there, covariance, score."""

    submap: np.ndarray  # (M,)
    node: np.ndarray  # (M,)
    aTb: np.ndarray  # (M, 3)
    cov_aTb: np.ndarray  # (M, 3, 3)
    score: np.ndarray  # (M,)
    tried: int = 0

    def __len__(self) -> int:
        return len(self.node)


def graph_nodes(submaps: Sequence[Any]) -> Nodes:
    """Every keyframe of ``submaps`` once: a node inserted into two submaps (the older one it was matched into and
    the younger one it was carried into rigidly) belongs to the older, its host."""
    seen: dict[int, tuple[int, np.ndarray, np.ndarray, np.ndarray]] = {}
    second: dict[int, tuple[int, np.ndarray]] = {}
    for sm in sorted(submaps, key=lambda s: s.index):
        for t, a, c, p in zip(sm.scan_stamps_ns, np.reshape(sm.aTb, (-1, 3)), np.reshape(sm.cov_aTb, (-1, 3, 3)),
                              sm.scan_points, strict=True):
            if int(t) in seen:
                second.setdefault(int(t), (int(sm.index), np.asarray(a, np.float64)))
                continue
            seen[int(t)] = (int(sm.index), np.asarray(a, np.float64), np.asarray(c, np.float64),
                            np.asarray(p, np.float64))
    ts = sorted(seen)
    none = (-1, np.zeros(3))
    return Nodes(np.array(ts, np.int64), np.array([seen[t][0] for t in ts], np.int64),
                 np.array([seen[t][1] for t in ts]).reshape(-1, 3), np.array([seen[t][2] for t in ts]).reshape(-1, 3, 3),
                 tuple(seen[t][3] for t in ts), np.array([second.get(t, none)[0] for t in ts], np.int64),
                 np.array([second.get(t, none)[1] for t in ts]).reshape(-1, 3))


def disputed_nodes(nodes: Nodes, wTa: np.ndarray, max_shift_m: float) -> np.ndarray:
    """(N,) bool: the nodes the solved anchors ``wTa`` place more than ``max_shift_m`` apart by their host and by
    their second submap (module docstring)."""
    out = np.zeros(len(nodes), bool)
    if nodes.second is None or nodes.second_aTb is None or not len(nodes):
        return out
    wTa = np.asarray(wTa, np.float64).reshape(-1, 3)
    two = np.flatnonzero(nodes.second >= 0)
    if not two.size:
        return out
    by_host = g.compose(wTa[nodes.host[two]], nodes.aTb[two])
    by_second = g.compose(wTa[nodes.second[two]], nodes.second_aTb[two])
    out[two] = np.hypot(by_host[:, 0] - by_second[:, 0], by_host[:, 1] - by_second[:, 1]) > max_shift_m
    return out


def _nearest_owners(owners: np.ndarray, dists: np.ndarray, count: int) -> list[int]:
    """The ``count`` submaps nearest by their nearest keyframe, nearest first (ties: the lower index first);
    ``owners`` is non-decreasing (keyframes listed submap by submap)."""
    ks, start = np.unique(owners, return_index=True)
    nearest = np.minimum.reduceat(dists, start)
    return [int(k) for k in ks[np.argsort(nearest, kind="stable")[:count]]]


def _cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one)."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:  # no affinity call (macOS, Windows)
        return os.cpu_count() or 1


def _keyframes(by_index: dict[int, Any], wTa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every submap's keyframes placed by the solved ``wTa``: their world positions (K, 2) and submaps (K,), submap
    by submap."""
    order = sorted(by_index)
    if not order:
        return np.zeros((0, 2)), np.zeros(0, np.int64)
    return (np.vstack([g.compose(np.broadcast_to(wTa[k], np.shape(by_index[k].aTb)),
                                 np.asarray(by_index[k].aTb))[:, :2] for k in order]),
            np.concatenate([np.full(len(by_index[k].aTb), k) for k in order]))


def _tasks(by_index: dict[int, Any], wTa: np.ndarray, keyframes: tuple[np.ndarray, np.ndarray], wTn: np.ndarray,
           host: np.ndarray, which: Iterable[int], cfg: RevisitConfig) -> list[tuple[int, int, np.ndarray]]:
    """(submap, node, the node's predicted pose in the submap) for the nodes ``which`` placed at ``wTn`` (world),
    into the old submaps (not ``host``'s chain neighbours) with one of the ``keyframes`` (``_keyframes``) within
    ``keyframe_distance_m``."""
    positions, owner = keyframes
    tasks = []
    for n in which:
        d = np.hypot(positions[:, 0] - wTn[n, 0], positions[:, 1] - wTn[n, 1])
        near = (d <= cfg.keyframe_distance_m) & (np.abs(owner - host[n]) > cfg.skip_recent)
        if not near.any():
            continue
        for k in _nearest_owners(owner[near], d[near], cfg.max_submaps):
            grid = by_index[k].grid
            if grid is not None and hasattr(grid, "prob"):
                tasks.append((k, int(n), g.compose(g.inverse(wTa[k]), wTn[n])))
    return tasks


#: matches handed to a thread at once at most (``match_nodes``): ~0.1 s of matching, 15 runs a household log
_CHUNK = 400


def match_nodes(submaps: Sequence[Any], nodes: Nodes, wTa: np.ndarray, cfg: RevisitConfig | None = None,
                match_cfg: MatchConfig | None = None,
                progress: Callable[[int, int], None] | None = None) -> NodeMatches:
    """Match sampled nodes into the old submaps around them (module docstring), seeded by the solved ``wTa``; the
    disputed nodes (``disputed_nodes``), every one, from their second placement too (a match from the host's
    placement kept first where both seeds find one)."""
    cfg = cfg or RevisitConfig()
    match_cfg = match_cfg or MatchConfig()
    wTa = np.asarray(wTa, np.float64).reshape(-1, 3)
    by_index = {int(sm.index): sm for sm in submaps}
    mcfg = replace(match_cfg, angular_window_deg=cfg.angular_window_deg)
    wTn = g.compose(wTa[nodes.host], nodes.aTb) if len(nodes) else np.zeros((0, 3))
    keyframes = _keyframes(by_index, wTa)
    tasks = _tasks(by_index, wTa, keyframes, wTn, nodes.host, range(0, len(nodes), cfg.sample_every), cfg)
    disputed = np.flatnonzero(disputed_nodes(nodes, wTa, cfg.max_shift_m))
    if disputed.size and nodes.second is not None and nodes.second_aTb is not None:  # (disputed: both are known)
        wTn2 = wTn.copy()
        wTn2[disputed] = g.compose(wTa[nodes.second[disputed]], nodes.second_aTb[disputed])
        tasks += _tasks(by_index, wTa, keyframes, wTn2, nodes.second, disputed, cfg)

    def one(task: tuple[int, int, np.ndarray]):
        k, n, pred = task
        grid = by_index[k].grid
        return match_scan(grid.prob, grid.origin, grid.resolution, nodes.b_points[n], pred, mcfg)

    # the matches are independent and their kernels run without the GIL: a thread per core, results in order,
    # handed to the threads in runs of ``_CHUNK`` (a future per match cost ~50 us of a 230 us match in handing
    # over: the household's 5,748 matches took 1.6 s on one thread of a pool against 1.3 s in a plain loop)
    workers = max(1, min(cfg.threads or _cores(), len(tasks)))
    size = max(1, min(_CHUNK, -(-len(tasks) // workers)))  # fewer tasks than workers x _CHUNK: each worker a run
    chunks = [tasks[i:i + size] for i in range(0, len(tasks), size)]
    out: list[tuple[int, int, np.ndarray, np.ndarray, float]] = []
    kept: set[tuple[int, int]] = set()
    with ThreadPoolExecutor(max_workers=workers) as pool:
        done = 0
        for chunk, matches in zip(chunks, pool.map(lambda c: [one(t) for t in c], chunks), strict=True):
            if progress is not None:
                progress(done, len(tasks))
            done += len(chunk)
            for (k, n, pred), m in zip(chunk, matches, strict=True):
                if ((k, n) not in kept and m.ok and m.score >= cfg.min_score
                        and np.hypot(*(m.aTb[:2] - pred[:2])) <= cfg.max_shift_m):
                    out.append((k, n, m.aTb, m.cov_aTb, m.score))
                    kept.add((k, n))
    tried = len(tasks)
    if not out:
        return NodeMatches(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3, 3)),
                           np.zeros(0), tried)
    return NodeMatches(np.array([o[0] for o in out], np.int64), np.array([o[1] for o in out], np.int64),
                       np.array([o[2] for o in out]), np.array([o[3] for o in out]), np.array([o[4] for o in out]),
                       tried)
