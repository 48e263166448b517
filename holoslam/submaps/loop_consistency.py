"""Consistency among loop closures: a closure found by a wide or global search joins the graph only when another
closure from elsewhere agrees with it.

A wide search (metres of window, any heading) has many chances to put a scan where it fits but does not belong:
the same corridor further along, the twin room on the other floor wing. One such closure looks as good as a right
one. Two right closures between the same two parts of the map, though, must move the new part by the *same*
rigid correction, and two wrong ones almost never do (Mangelson et al., "Pairwise Consistent Measurement Set
Maximization", ICRA 2018; Olson's single-cluster graph partitioning and Latif's RRR rest on the same idea).

A closure c = (m, n, mTn) says where anchor n lies once the old map's anchor m is taken as right: its world
correction is Delta_c = est(m) ∘ mTn ∘ est(n)^-1, the rigid motion that takes the current estimate of the new
part onto the old one. Closures c1, c2 agree when Delta_c1 and Delta_c2 move anchor n2 to the same pose within
their covariances plus the drift the map may have between them: ``sigma_m + rate * d`` (m) and ``sigma_deg +
deg_rate * d`` (deg), d the distance the robot travelled between n1 and n2 plus between m1 and m2 (local SLAM's
drift over that much travel; the map is rigid below it). The squared Mahalanobis distance of the difference must
stay under the chi-square(3) gate. The allowance must stay able to tell an alias: closures whose heading
allowance would exceed ``max_allowance_deg`` do not vouch for each other (thousands of metres apart, any two
corrections agree, a half turn included: a closure waiting since a robot's second carry agreed with an alias
after its third, 2,000 m later, and joined that 180 deg wrong). A closure is accepted when it and
``min_agreeing`` - 1 others all agree with one another (a clique, as in pairwise consistency maximisation); those
are accepted with it. The others wait (``pending``), at most ``max_pending``, the oldest forgotten first.

A correction moves the part of the run its new anchor lies in. Across a break of local SLAM (a gap in the laser,
the robot carried) the parts' relative pose is unknown, so two closures of different parts say nothing of each
other, and two that both leave the estimate as it is agree by construction: on intel at 1.4 Hz with half its
beams, kidnapped at two thirds, two closures of the carried part into aliases near its wrong estimate (14 and 26 m
off) were vouched for by a right closure before the kidnap, and joined the parts 8 m and 97 deg off. Closures of
different parts do not vouch for each other.

A clique can be an alias too, when a corridor repeats: its closures agree because they all put the new part one
repeat along. Then the right place is often seen as well, by closures that agree with one another and not with
the clique. Such a rival of two or more, with as many closures certain to ``rival_max_sd_m`` as the clique has,
makes the clique wait (a match kept with its peaks' spread along a corridor agrees with either side and counts
for neither): the side that gathers more certain closures is accepted. On the simulated building without its
compass, a clique of three 17-27 m along a corridor (one certain, two with 2.2-2.5 m of spread) was accepted
beside two certain right closures, and nothing undid it (seed 27, odometer x1.005: revisits 7.6 m off; waiting,
0.21 m; the other eight runs unchanged).

For the same reason only certain closures vouch: a clique is accepted when ``min_agreeing`` of its closures (the
offered one, the waiting ones, the accepted ones agreeing with it) are certain to ``vouch_max_sd_m``; an uncertain
one joins a clique of enough certain ones. Without the rule (and with ``LoopConfig.solo_max_offset_m``, which
sends more matches here), the simulated building without its compass (seed 27, odometer x0.995) accepted a
clique of one certain closure 3.5 m off and two kept with 3.8 and 5.1 m of spread, one of them 15 m off; on seed
30 a closure with 5.3 m of spread, 21 m off, vouched for two right ones and a wrong one 3.7 m off.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from holoslam import geometry as g

__all__ = ["ConsistencyConfig", "LoopConsistency", "agreement", "correction"]


@dataclass(frozen=True, slots=True)
class ConsistencyConfig:
    """Settings of the agreement test. The drift allowance is local SLAM's own drift: a few per cent of the
    distance travelled on real logs (relations 5-30 s apart on the Freiburg hospital log: 0.12 m mean over
    ~10 m; ``LocalSlamConfig.map_drift_per_m`` 0.5 % at 1 sigma inside one submap); the gate is chi-square(3)
    at 99.9 %."""

    # closures, this one included, that must all agree with one another before any of them is accepted. Two are not
    # enough: on aces kidnapped in its middle, two wrong closures from nodes 4+ m apart agreed and joined the parts
    # 54 m off, while three found the right join (Cartographer's own test of joining trajectories asks 3 too)
    min_agreeing: int = 3
    # m of travel between the nodes of two closures that may vouch for each other: nodes closer than this see the
    # same walls, and a place that aliases one of them aliases the other alike (two nodes 0.6 m apart of one aces
    # submap both put it 30 m from where it is, identically). The global search's bundle length
    # (``LoopConfig.global_bundle_m``): closer nodes' bundles share scans
    min_separation_m: float = 4.0
    sigma_m: float = 0.2  # m, floor of the allowance (two 5 cm grids' lattices and their refinements)
    sigma_deg: float = 1.0  # deg
    rate: float = 0.02  # m of allowance per m travelled between the closures' anchors
    deg_rate: float = 0.05  # deg per m travelled
    gate: float = 16.27  # chi-square(3) 99.9 %
    max_pending: int = 200  # closures waiting for agreement; older ones are forgotten
    # deg: closures whose heading allowance (sigma_deg + deg_rate * their distance) would exceed this do not vouch
    # for each other: the gate (4 sigma) then spans 60 deg either way, and wider it would pass a corridor's 90 deg
    # or a half-turn's alias as agreeing. 15 deg is 280 m of travel between the closures; the right joins of the
    # kidnapped shared logs (full rate and 1.4 Hz with half the beams) gathered their three within 176 m
    max_allowance_deg: float = 15.0
    # m: a clique waits while the waiting closures hold a rival (two or more agreeing with each other, not with
    # it) with as many closures certain to within this (the largest sd of their position) as it has (module
    # docstring); infinity: off. Two closures 1 m in sd are told apart 5.7 m away (the gate's 4 sigma of their
    # difference): a corridor's doors 5 m apart. A match kept with its peaks' spread is metres along
    rival_max_sd_m: float = 1.0
    # m: only closures certain to within this (the largest sd of their position) count toward ``min_agreeing``; an
    # uncertain one may join a clique of enough certain ones. A match kept with its peaks' spread (metres along a
    # corridor) agrees with the right place and with its aliases alike, so it vouches for neither (the rivals'
    # door-spacing argument above). Measured with ``LoopConfig.solo_max_offset_m``, whose waiting matches it keeps
    # out of cliques vouched for by spread alone (module docstring; README, *A biased odometer on the simulated
    # building*): the spreads that vouched for wrong cliques were 3.8-5.3 m. 1.6 m, not 1.0: a sparse laser's right
    # corrections after a long corridor are certain to 0.9-1.5 m (the building without its compass, seed 37 x 1:
    # three of them waited for ever at 1.0 and its revisits ended 4.84 m off; 0.25 m at 1.6). inf: every closure counts
    vouch_max_sd_m: float = 1.6


def correction(wTm: np.ndarray, mTn: np.ndarray, wTn: np.ndarray) -> np.ndarray:
    """Delta = wTm ∘ mTn ∘ wTn^-1: the world motion that puts the estimate of n where the closure says it is."""
    return g.compose(g.compose(wTm, mTn), g.inverse(wTn))


def agreement(c1, c2, est_wTa: np.ndarray, travel: np.ndarray, cfg: ConsistencyConfig,
              parts: np.ndarray | None = None) -> float:
    """The squared Mahalanobis distance between what closures ``c1`` and ``c2`` (``LoopCandidate``-like: old,
    new, mTn, cov_mTn, travelled: the odometer at the node) say of anchor c2.new (module docstring); infinite for
    closures from nodes nearer than ``min_separation_m``, for closures too far apart to tell an alias
    (``max_allowance_deg``), and for closures whose new anchors lie in different parts of the run (``parts``: per
    anchor, the breaks of local SLAM before it; module docstring)."""
    if abs(c1.travelled - c2.travelled) < cfg.min_separation_m:
        return math.inf
    if parts is not None and parts[c1.new] != parts[c2.new]:
        return math.inf
    dist = abs(travel[c1.new] - travel[c2.new]) + abs(travel[c1.old] - travel[c2.old])
    s_deg = cfg.sigma_deg + cfg.deg_rate * dist
    if s_deg > cfg.max_allowance_deg:
        return math.inf
    d1 = correction(est_wTa[c1.old], c1.mTn, est_wTa[c1.new])
    d2 = correction(est_wTa[c2.old], c2.mTn, est_wTa[c2.new])
    wTn = est_wTa[c2.new]
    e = g.between(g.compose(d1, wTn), g.compose(d2, wTn))
    e[2] = g.wrap(e[2])
    s_xy = cfg.sigma_m + cfg.rate * dist
    s_th = math.radians(s_deg)
    # both closures' covariances are of anchor n in its own frame; c1's is moved to c2's anchor
    n1Tn2 = g.between(est_wTa[c1.new], wTn)
    A = g.adjoint(g.inverse(n1Tn2))
    cov = A @ np.asarray(c1.cov_mTn) @ A.T + np.asarray(c2.cov_mTn) + np.diag([s_xy ** 2, s_xy ** 2, s_th ** 2])
    return float(e @ np.linalg.solve(cov, e))


class LoopConsistency:
    """The closures of wide searches waiting for another that agrees (module docstring)."""

    def __init__(self, cfg: ConsistencyConfig | None = None) -> None:
        self.cfg = cfg or ConsistencyConfig()
        self.pending: list = []
        self.accepted: list = []  # wide closures accepted so far (a new one may agree with these too)
        self.rivalled = False  # whether the last offer's clique waits for a rival (``_rivalled``)

    def offer(self, c, est_wTa: np.ndarray, travel: np.ndarray, parts: np.ndarray | None = None) -> list:
        """The closures to accept now: ``c`` and a set of waiting ones that agree with it and with one another
        (with the closures accepted before, which are trusted, agreeing with ``c`` counting too), when they are
        ``min_agreeing`` in all; else ``c`` waits and nothing is accepted. ``parts`` (per anchor, the breaks of
        local SLAM before it): closures whose new anchors lie in different parts do not vouch for each other."""
        est_wTa, travel = np.asarray(est_wTa), np.asarray(travel)
        gate = self.cfg.gate

        def agree(a, b) -> bool:
            return agreement(a, b, est_wTa, travel, self.cfg, parts) <= gate

        trusted = [a for a in self.accepted if agree(a, c)]
        group: list = []
        for p in reversed(self.pending):  # the most recent first: the estimate has drifted least since
            if agree(p, c) and all(agree(p, q) for q in group):
                group.append(p)
        enough = _certain([c, *group, *trusted], self.cfg.vouch_max_sd_m) >= self.cfg.min_agreeing
        self.rivalled = enough and self._rivalled(c, group, trusted, est_wTa, travel, parts)
        if enough and not self.rivalled:
            chosen = {id(p) for p in group}
            self.pending = [p for p in self.pending if id(p) not in chosen]
            out = [*group[::-1], c]
            self.accepted.extend(out)
            return out
        self.pending.append(c)
        if len(self.pending) > self.cfg.max_pending:
            self.pending.pop(0)
        return []

    def _rivalled(self, c, group: list, trusted: list, est_wTa: np.ndarray, travel: np.ndarray,
                  parts: np.ndarray | None = None) -> bool:
        """Whether the waiting closures hold a rival of the clique ``group`` + ``c`` (with the accepted closures
        ``trusted`` that agree with ``c``): two or more that agree with one another and disagree with ``c`` (near
        enough to be told apart), as many of them certain (``rival_max_sd_m``) as the clique's. Those are one
        other place seen twice, and the clique may be its alias: it waits for more closures on either side."""
        cfg = self.cfg
        if not math.isfinite(cfg.rival_max_sd_m):
            return False

        mine = {id(p) for p in group}
        # the waiting closures that can be told from c and disagree with it (a few: most are of other places)
        against = [p for p in self.pending if id(p) not in mine
                   and cfg.gate < agreement(p, c, est_wTa, travel, cfg, parts) < math.inf]
        ours = _certain([c, *group, *trusted], cfg.rival_max_sd_m)
        agree = [[agreement(p, q, est_wTa, travel, cfg, parts) <= cfg.gate for q in against] for p in against]
        for i in range(len(against)):  # the rival cliques grown from each of them, greedily
            rivals = [i]
            for j in range(len(against)):
                if j != i and all(agree[j][k] for k in rivals):
                    rivals.append(j)
            if len(rivals) >= 2 and _certain([against[k] for k in rivals], cfg.rival_max_sd_m) >= ours:
                return True
        return False


def _certain(closures: list, max_sd_m: float) -> int:
    """How many of ``closures`` are certain to ``max_sd_m`` (the largest sd of their position)."""
    return sum(_largest_sd(a.cov_mTn) <= max_sd_m for a in closures)


def _largest_sd(cov) -> float:
    """m: the largest standard deviation of a closure's position (its covariance's x-y block)."""
    return math.sqrt(max(0.0, float(np.linalg.eigvalsh(np.asarray(cov)[:2, :2])[-1])))
