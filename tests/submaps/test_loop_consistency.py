"""Consistency among loop closures: two right closures move the new part of the map by one rigid correction,
an alias does not (holoslam.submaps.loop_consistency)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from holoslam import geometry as g
from holoslam.submaps.loop_consistency import ConsistencyConfig, LoopConsistency, agreement


@dataclass(frozen=True)
class Closure:
    old: int
    new: int
    mTn: np.ndarray
    cov_mTn: np.ndarray
    travelled: float


# truth: anchors 0, 1 (old corridor) and 2, 3 (the new part, 6 m of travel apart); the estimate of the new part
# has drifted by a rigid 20 m / 25 deg, as after a long loop
TRUE = np.array([[0.0, 0.0, 0.0], [8.0, 0.0, 0.0], [1.0, 3.0, math.pi], [7.0, 3.0, math.pi]])
DRIFT = np.array([20.0, -5.0, math.radians(25.0)])
EST = np.vstack([TRUE[:2], g.compose(np.broadcast_to(DRIFT, (2, 3)), TRUE[2:])])
TRAVEL = np.array([0.0, 8.0, 300.0, 306.0])
COV = np.diag([0.05, 0.05, 0.01]) ** 2


def closure(old: int, new: int, travelled: float, error=(0.0, 0.0, 0.0)) -> Closure:
    return Closure(old, new, g.compose(g.between(TRUE[old], TRUE[new]), np.asarray(error, float)), COV, travelled)


def test_two_right_closures_from_distant_nodes_agree_and_an_alias_does_not():
    cfg = ConsistencyConfig()
    right_a, right_b = closure(0, 2, 300.0), closure(1, 3, 306.0)
    alias = closure(1, 3, 306.0, error=(3.0, 0.0, 0.0))  # the same corridor 3 m further along
    assert agreement(right_a, right_b, EST, TRAVEL, cfg) < 1.0
    # 14 m of travel between them allow 0.48 m (1 sigma): 3 m is 6 sigma
    assert agreement(right_a, alias, EST, TRAVEL, cfg) > 2 * cfg.gate


def test_closures_of_nearby_nodes_cannot_vouch_for_each_other():
    # two nodes 1 m apart see the same walls: an alias of one is an alias of the other
    cfg = ConsistencyConfig()
    assert math.isinf(agreement(closure(0, 2, 300.0), closure(1, 2, 301.0), EST, TRAVEL, cfg))


def test_the_allowance_grows_with_the_travel_between_the_closures():
    cfg = ConsistencyConfig()
    off = (2.5, 0.0, 0.0)  # 2.5 m of drift between the two: too much for 14 m of travel, fine for 68 m
    near = agreement(closure(0, 2, 300.0), closure(1, 3, 306.0, off), EST, TRAVEL, cfg)
    far_travel = TRAVEL.copy()
    far_travel[3] = 360.0
    far = agreement(closure(0, 2, 300.0), closure(1, 3, 360.0, off), EST, far_travel, cfg)
    assert near > cfg.gate > far


def test_a_closure_waits_until_enough_agree_with_one_another_and_aliases_never_join():
    pool = LoopConsistency()
    assert pool.offer(closure(0, 2, 300.0), EST, TRAVEL) == []
    assert pool.offer(closure(1, 3, 306.0, error=(3.0, 0.0, 0.0)), EST, TRAVEL) == []  # alias: waits
    assert pool.offer(closure(1, 3, 306.5), EST, TRAVEL) == []  # two agree: not yet (min_agreeing 3)
    accepted = pool.offer(closure(0, 3, 312.0), EST, TRAVEL)
    assert {(c.old, c.new, c.travelled) for c in accepted} == {(0, 2, 300.0), (1, 3, 306.5), (0, 3, 312.0)}
    assert len(pool.pending) == 1 and pool.pending[0].travelled == 306.0  # the alias still waits, alone
    # once a join is accepted, one closure agreeing with it is enough, and the alias still never joins
    assert pool.offer(closure(1, 2, 320.0), EST, TRAVEL) != []
    assert pool.offer(closure(1, 3, 330.0, error=(3.0, 0.0, 0.0)), EST, TRAVEL) == []


def test_two_wrong_closures_that_agree_with_each_other_do_not_join_alone():
    pool = LoopConsistency()
    wrong = (4.0, 1.0, 0.3)
    assert pool.offer(closure(0, 2, 300.0, wrong), EST, TRAVEL) == []
    assert pool.offer(closure(1, 3, 306.0, wrong), EST, TRAVEL) == []  # they agree, but only two
    assert pool.offer(closure(0, 3, 312.0), EST, TRAVEL) == []  # a right one disagrees with both


def test_closures_too_far_apart_to_tell_a_half_turn_do_not_vouch_for_each_other():
    # 3 km of travel between two closures would allow 150 deg (1 sigma): a half-turn alias would agree. The
    # allowance is capped (max_allowance_deg): such closures do not vouch for each other at all
    cfg = ConsistencyConfig()
    far = TRAVEL.copy()
    far[3] = 3300.0
    half_turn = closure(1, 3, 3300.0, error=(0.0, 0.0, math.pi))
    assert math.isinf(agreement(closure(0, 2, 300.0), half_turn, EST, far, cfg))
    # uncapped, the same pair would pass the gate: the cap is what keeps it out
    loose = ConsistencyConfig(max_allowance_deg=1e9)
    assert agreement(closure(0, 2, 300.0), half_turn, EST, far, loose) < loose.gate
    # a right pair just under 280 m apart (new sides and old sides' travel together) is still judged
    mid = TRAVEL.copy()
    mid[3] = 300.0 + (cfg.max_allowance_deg - cfg.sigma_deg) / cfg.deg_rate - (TRAVEL[1] - TRAVEL[0]) - 1.0
    assert agreement(closure(0, 2, 300.0), closure(1, 3, float(mid[3])), EST, mid, cfg) < 1.0


def test_a_clique_waits_while_a_rival_pair_has_as_many_certain_closures():
    """``rival_max_sd_m``: three closures 12-16 m along a corridor agree (two of them kept with metres of spread
    along it), but two certain ones at the truth agree with each other and not with them: the alias waits, and
    with the rule off it is accepted. A clique of three certain closures is accepted beside the same rivals' pair
    only when it has more certain members."""
    wide = np.diag([2.5, 0.1, 0.01]) ** 2  # 2.5 m along the corridor (x), 0.1 m across
    TRAV = np.array([0.0, 8.0, 300.0, 306.0])

    def offers(pool: LoopConsistency) -> list:
        pool.offer(closure(0, 2, 300.0), EST, TRAV)  # right
        pool.offer(closure(1, 3, 306.0), EST, TRAV)  # right: two agree, not enough
        pool.offer(closure(0, 2, 312.0, (12.0, 0.0, 0.0)), EST, TRAV)  # the alias, certain
        pool.offer(replace(closure(1, 3, 318.0, (16.0, 0.0, 0.0)), cov_mTn=wide), EST, TRAV)
        return pool.offer(replace(closure(0, 3, 324.0, (14.0, 0.0, 0.0)), cov_mTn=wide), EST, TRAV)

    every = ConsistencyConfig(vouch_max_sd_m=math.inf)  # the uncertain closures vouch too: the rival rule alone
    waits = LoopConsistency(every)
    assert offers(waits) == [] and waits.rivalled  # the report counts it: "waiting, a rival clique as certain"
    accepted = offers(LoopConsistency(replace(every, rival_max_sd_m=math.inf)))
    assert sorted(c.travelled for c in accepted) == [312.0, 318.0, 324.0]  # the alias, without the rule
    # the right side's third arrives: three certain against the alias's one, accepted
    pool = LoopConsistency(every)
    offers(pool)
    assert sorted(c.travelled for c in pool.offer(closure(1, 2, 330.0), EST, TRAV)) == [300.0, 306.0, 330.0]


def test_only_certain_closures_vouch_for_a_clique():
    """``vouch_max_sd_m``: a closure kept with metres of spread along a corridor agrees with the right place and
    its aliases alike. An alias 14 m along the corridor, certain, with two such closures agreeing waits (one
    certain closure of the three ``min_agreeing``); with every closure counting it is accepted. Three certain right
    closures are accepted, and an uncertain one agreeing with them then joins; closures certain to 1.5 m vouch."""
    wide = np.diag([2.5, 0.1, 0.01]) ** 2  # 2.5 m sd along the corridor (x)
    alias = (14.0, 0.0, 0.0)

    def offer_alias(pool: LoopConsistency) -> list:
        pool.offer(closure(0, 2, 300.0, alias), EST, TRAVEL)
        pool.offer(replace(closure(1, 3, 306.0, alias), cov_mTn=wide), EST, TRAVEL)
        return pool.offer(replace(closure(0, 3, 312.0, alias), cov_mTn=wide), EST, TRAVEL)

    pool = LoopConsistency()
    assert offer_alias(pool) == [] and len(pool.pending) == 3
    accepted = offer_alias(LoopConsistency(ConsistencyConfig(vouch_max_sd_m=math.inf)))
    assert sorted(c.travelled for c in accepted) == [300.0, 306.0, 312.0]
    right = LoopConsistency()
    assert right.offer(closure(0, 2, 300.0), EST, TRAVEL) == []
    assert right.offer(closure(1, 3, 306.0), EST, TRAVEL) == []
    assert len(right.offer(closure(0, 3, 312.0), EST, TRAVEL)) == 3
    assert len(right.offer(replace(closure(1, 2, 320.0), cov_mTn=wide), EST, TRAVEL)) == 1  # trusted ones vouch
    # right closures certain to 1.5 m (a sparse laser's corrections after a corridor, 0.9-1.5 m on the simulated
    # building) vouch for each other by default; at 1 m they would wait for certain ones that never come
    corridor = np.diag([1.5, 0.1, 0.01]) ** 2

    def offer_corridor(pool: LoopConsistency) -> list:
        pool.offer(replace(closure(0, 2, 300.0), cov_mTn=corridor), EST, TRAVEL)
        pool.offer(replace(closure(1, 3, 306.0), cov_mTn=corridor), EST, TRAVEL)
        return pool.offer(replace(closure(0, 3, 312.0), cov_mTn=corridor), EST, TRAVEL)

    assert len(offer_corridor(LoopConsistency())) == 3
    assert offer_corridor(LoopConsistency(ConsistencyConfig(vouch_max_sd_m=1.0))) == []


def test_closures_of_two_parts_of_the_run_do_not_vouch_for_each_other():
    """Across a break of local SLAM (the robot carried 30 m and turned 90 deg) the new part's estimate stands on
    nothing: aliases found near it leave it where it is, as does a right closure of the part before the break,
    so all three agree by construction. Told which part each anchor is in, the aliases wait, and three right
    closures of the carried part join it (intel at 1.4 Hz with half its beams, kidnapped at two thirds: two aliases
    14 and 26 m off, vouched for by a closure before the kidnap, joined the parts 8 m and 97 deg off)."""
    truth = np.array([[0.0, 0.0, 0.0], [8.0, 0.0, 0.0], [4.0, 2.0, 0.0], [6.0, 3.0, math.pi]])
    est = truth.copy()
    est[3] = g.compose(np.array([30.0, 0.0, math.pi / 2]), truth[3])  # the carried part, where its odometry says
    travel = np.array([0.0, 8.0, 300.0, 340.0])
    parts = np.array([0, 0, 0, 1])

    def as_estimated(old, new, travelled):  # a match that leaves the estimate as it is
        return Closure(old, new, g.between(est[old], est[new]), COV, travelled)

    def right(old, new, travelled):
        return Closure(old, new, g.between(truth[old], truth[new]), COV, travelled)

    before, alias_a, alias_b = right(0, 2, 300.0), as_estimated(0, 3, 340.0), as_estimated(1, 3, 346.0)
    blind = LoopConsistency()
    assert blind.offer(before, est, travel) == [] and blind.offer(alias_a, est, travel) == []
    assert len(blind.offer(alias_b, est, travel)) == 3  # without the parts: the aliases join
    told = LoopConsistency()
    for c in (before, alias_a, alias_b):
        assert told.offer(c, est, travel, parts) == []
    assert told.offer(right(0, 3, 352.0), est, travel, parts) == []
    assert told.offer(right(1, 3, 358.0), est, travel, parts) == []
    joined = told.offer(right(0, 3, 364.0), est, travel, parts)
    assert sorted(c.travelled for c in joined) == [352.0, 358.0, 364.0]
