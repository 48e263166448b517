"""The loop search's settings (``holoslam.submaps.loops``): windows, scores, the ambiguity test, the global search
and the consistency among closures, each with where its default comes from."""

from __future__ import annotations

from dataclasses import dataclass, field

from holoslam.submaps.loop_consistency import ConsistencyConfig
from holoslam.submaps.loop_verify import VerifyConfig

__all__ = ["LoopConfig"]


@dataclass(frozen=True, slots=True)
class LoopConfig:
    every_nodes: int = 3  # search from every k-th node (Cartographer samples 30 % of pairs)
    # m / deg, > 0: and only once the robot moved every_m or turned every_deg (its odometry) since the node that
    # searched last. The motion filter makes a node per 0.2 m or 1 deg (or 5 s standing), so k nodes span very
    # different paths: 3 nodes are 0.14 m of the household log (a robot that turns a lot), 0.24-0.35 m of the real
    # logs at full rate and 0.66-1.03 m at 1.4 Hz. 0.2 m (the motion filter's distance) / 30 deg keeps 60 % of the
    # household's searches (957 of 1,593), 61 % of intel's and 97 % of the sparse logs'. Measured (bench_realdata
    # --variants full kidnap sparse, laser m, against main on the same day): intel 0.0187 -> 0.0186, aces 0.0355 ->
    # 0.0355, fr079 0.0429 -> 0.0429; kidnap joins kept (across max intel 0.155 -> 0.156, aces 0.275 -> 0.273, fr079
    # 0.213 -> 0.214); sparse intel 0.0934 -> 0.0914 (max 4.3-4.4, its known failure), aces 0.0424 -> 0.0426, fr079
    # 0.0552 -> 0.0552; the full intel log 52.1 -> 45.8 s CPU (back to back);
    # the household run: anchors 4.8 -> 4.7 mm, objects 9.8 -> 10.7 mm, coverage 0.977, CPU 15.8 -> 14.1 s (medians
    # of 3 at load 4-5; map_log in process 8.2 -> 7.6 s). 0.3 m / 30 deg (46 % of the household's searches) mapped
    # the real logs as well but the intel windows of tests/lifelong/test_keyframes_onto_map.py worse (across the
    # sessions 0.0257 -> 0.0273 m with the keyframe stage; 0.2 m: 0.0255); 0.3 m alone (no turn) kept 74-84 % of
    # sparse intel's and aces' searches (turns in place span few metres) and moved them (intel 0.091 -> 0.128 m,
    # aces 0.0426 -> 0.0460); every 6th node instead of every 3rd lost sparse aces' corridor revisit
    every_m: float = 0.2
    every_deg: float = 30.0
    max_constraint_distance: float = 15.0  # m between the node and an old submap's anchor (windowed searches)
    base_window_xy: float = 1.0  # m, window half-width right after a closure
    window_rate: float = 0.05  # m of window per m travelled since the last closure
    # m and deg: the largest window searched at the map's resolution, whose match is accepted on its own
    # (Cartographer's +-7 m, +-30 deg). A wider window (the drift since the last closure, or ``window_sigmas`` of
    # the node's covariance relative to the old submap, says the estimate may be further off) has no cap: it is
    # searched by the global search (``global_search``: the whole submap if need be, every heading) and its match
    # must agree with another (``consistency``)
    max_window_xy: float = 7.0
    base_window_deg: float = 10.0
    window_deg_rate: float = 1.0  # deg per m travelled since the last closure
    max_window_deg: float = 30.0
    window_sigmas: float = 3.0  # the window covers this many sigmas of the node's pose relative to the old submap
    # A window (its drift part, base + window_rate per m and base_window_deg + window_deg_rate per m, and its
    # covariance part alike) is at most the base plus this many times the distance (and the angle) between the
    # estimate of the node's submap relative to the old one and dead reckoning's alone, on a robot with a compass:
    # the estimate follows the scan matches, dead reckoning the odometer and the compass, two independent measures
    # of one relative pose, and where they agree neither can be far off. The covariance part too: on the
    # building's seed 27 a node 799 m of graph from an old submap had an estimate 0.49 m off the truth and dead
    # reckoning 0.93 m from the estimate, but 3 sigma of its covariance said 9.1 m; the window at the 7 m cap then
    # accepted a twin room 6.2 m off on its own, and the corrupted estimate drew 29 more wrong closures.
    # Measured over every span of anchors 10-600 m apart on the simulated 350 m building (compass, 2,400 m;
    # the chain of scan matches against the truth): the chain's error stayed within 1 m + 2x the disagreement on
    # all 645 spans (1 m + 1x failed 4 of the 600 m ones by up to 1.27 m); its windows at 600 m
    # become 1.6 % of the span (median) where window_rate says 5 %, and the building's anchors 20.0 m -> 0.36 m
    # RMSE (aliases of its identical rooms 30 m away were inside the 5 % windows). Without a compass dead
    # reckoning's heading is the odometry's, which local SLAM also predicts from: not independent, and on the real
    # logs (kidnapped aces) the bound cost a join 34 m later and a 0.72 m relation error; there it is not used.
    # 0: off
    agreement_factor: float = 2.0
    # Without a compass (where the bound above is not used), a window is at least the base plus this many times
    # dead reckoning's disagreement with the estimate, up to max_window_xy, on a laser of at most
    # ``disagreement_window_max_hz``: where the scans shorten a corridor the odometry measures right, the estimate
    # drifts more than window_rate allows. The shared aces log with its ranges cut at 5 m (a cheap laser): 48
    # windowed searches from its pass at 800-870 s into its first minute, 2.8-3.9 m windows, the right pose 6.2-6.7
    # m from their seeds (scoring up to 0.68 there): no closure, 0.0698 m mean relation error (2.1 m max); at 1.0:
    # 0.0501 (0.53 max). The simulated 350 m building without its compass (1.4 Hz; ``bench_building_slam.py
    # --no-compass --wobble 0.995 1 1.005``, 9 runs): runs whose revisits are over 1 m off 3 -> 1 (worst 4.9 ->
    # 3.2 m), median revisits 0.158 -> 0.143 m, anchors 0.514 -> 0.334 m, for 7 % more CPU. 0: off
    disagreement_window: float = 1.0
    # Hz: the disagreement window only on a laser this slow or slower (its median scan rate). At 4.6-5.4 Hz (the
    # shared full-rate logs) the windows reach the cap wherever the odometry's heading drifted and the loop
    # search costs 2-3x its CPU for the same error (intel 0.0187, aces 0.0355, fr079 0.0427 m at the laser; run
    # 34 -> 75 s, 24 -> 27 s, 40 -> 50 s wall): nodes come 3-4x as often as at 1.4 Hz, where the building pays 7 %.
    # The decimated shared logs (1.4 Hz) map as well either way. inf: always
    disagreement_window_max_hz: float = 2.0
    # ... and on a faster laser once this share of local SLAM's matched nodes were blind along the track
    # (``odometer.is_blind``; judged from the 500th matched node on, ``frontend._BLIND_SHARE_NODES``, and on from
    # then): a short laser in long corridors, whose scans shorten them as a slow laser's do. The shared logs' full
    # laser stays below it (blind intel 0.9 %, aces 2.4 %, fr079 0 %: unchanged, to 1e-4 m), with ranges cut at
    # 5 m (``bench_realdata.py --variants short@5``) aces 0.0698 -> 0.0501 m (max 2.14 -> 0.53 m), intel 0.0286 ->
    # 0.0237, at 8 m intel 0.0252 -> 0.0228 (run 30 -> 51 s; before the periodic test (``periodic_search_m``) an
    # alias 7.8-9.1 m along intel's corridor made it 0.0419). Judged from the 100th node instead, intel's full
    # laser turns it on (8 % of its first 100 nodes blind: 34 -> 74 s for the same error). Above 1: never
    disagreement_window_blind_share: float = 0.05
    # A windowed match beyond the ellipse inscribed in its window, scaled by this factor, is offered for agreement
    # (``loop_consistency``, as a weak match is) instead of accepted on its own: the window is the bounding box of
    # the estimate's uncertainty (or of dead reckoning's agreement), and a match in its corners lies beyond that
    # bound. On the simulated building with its compass (``bench_building_slam.py``, seed 27) the wrong closures had
    # moved 0.09-1.41 half-widths from their seeds (7 of 19 beyond 0.75), the right ones 2 of 58 beyond 0.75; the
    # first wrong ones let the estimate drift and the rest followed. At 1.0 the three seeds' anchors 0.558 / 1.889 /
    # 0.310 -> 0.403 / 0.539 / 0.296 m, revisits 0.155 / 3.867 / 0.123 -> 0.092 / 0.382 / 0.141 m (seed 27's wrong
    # closures 19 -> 2; with its odometer scaled 0.995 / 1 / 1.005 too, runs over 1 m 2 -> 1 of 9); at 0.4 seed 26
    # failed (6.05 m: its right corrections waited), at 0.6 0.568 / 0.668 / 0.292 m.
    # Without the compass (``--no-compass --wobble 0.995 1 1.005``, 9 runs): anchors median 0.345 -> 0.361 m,
    # revisits 0.156 -> 0.151 m, runs over 1 m 0 -> 1 (seed 27 x 1.005, 0.98 -> 7.6 m, at the edge before). The
    # shared logs, full, kidnapped, sparse: the same figures within 0.0004 m; the household: the same closures. inf: off
    far_from_seed: float = 1.0
    # Without a compass, a window widened by dead reckoning's disagreement (``disagreement_window``) beyond the
    # drift window (the drift since the last closure, or ``window_sigmas`` of the covariance) is searched whole,
    # but a match beyond the drift window's ellipse (scaled by ``far_from_seed``) is offered for agreement
    # instead of accepted on its own: only dead reckoning, whose heading is the odometry's and drifts by hundreds
    # of metres over a long log, says the estimate may be that far off, and a floor of identical rooms puts a
    # twin inside every widened window. On the simulated 350 m building without its compass (1.4 Hz; seed 30,
    # odometer x1.005) the first wrong closures were rooms 5-6.5 m along a corridor from estimates 0.03-0.7 m
    # right, in 7 m windows widened from drift windows of a metre or two; the drift they let in grew to 11-43 m
    # and 10 more aliases followed it (anchors 12.2 m RMSE; with the rule 0.31 m, 16 wrong closures -> 1).
    # ``bench_building_slam.py --no-compass``, 36 runs (seeds 26-35, odometer x0.995 / 1 / 1.002 / 1.005), before
    # -> after: revisits over 1 m off 5 -> 2 (worst 11.5 -> 1.74 m), anchors over 1 m RMSE 5 -> 5 but the worst
    # 12.2 / 5.2 / 4.2 m -> 2.2 / 1.9 / 1.6 m, wrong closures a run 8-27 -> 0-10. Seed 33 lost three runs to it
    # (anchors 0.26-0.36 -> 1.5-1.9 m, revisits at most 0.42 m): two global aliases joined a right clique within
    # the consistency test's drift allowance. The shared logs decimated to 1.4 Hz (``bench_realdata.py --variants
    # sparse sparse_kidnap short``): intel 0.0297 -> 0.0293 m at the laser, aces 0.0427 -> 0.0442, fr079 0.0531,
    # kidnaps joined as before; at full rate and with a compass the windows are never widened: unchanged.
    # False: off
    widened_needs_agreement: bool = True
    # m: a windowed match that moves the node more than this from its seed (the estimate) is offered for agreement
    # instead of accepted on its own, whatever its window: one scan that says the map is metres off is a
    # hypothesis, and a floor of identical rooms puts a twin one door along inside any window that wide. On the
    # shared real logs (full rate, kidnapped, cut at 8 m, at 1.4 Hz with half the beams, kidnapped and drifting so)
    # 5,261 windowed matches were accepted alone: 7 had moved their node more than 2 m, 2 more than 3 m (the largest
    # right one 3.6 m, aces at 1.4 Hz), 1 more than 4 m, and that one was wrong (5.7 m, 4.3 m off: intel at 1.4 Hz
    # kidnapped). On the simulated building without its compass the wrong ones accepted alone had moved 4.2-7.0 m
    # (a room one door along), the right ones at most 1.6 m but two corrections of 4.8 and 5.2 m. With
    # ``ConsistencyConfig.vouch_max_sd_m`` (alone it does worse than neither; README, *A biased odometer on the
    # simulated building*: a held-out run whose needed corrections over 4 m waited for ever at 1 m of vouching is
    # joined at 1.6 m). Not where the compass's agreement with dead reckoning bounds the window (a measured bound
    # of the estimate's error, not a drift allowance): there a match within it is not one scan's word against the
    # estimate. The simulated building with its compass, seed 26: 0.409 m anchors RMSE and 0.118 m revisits
    # without the rule, 1.320 / 1.04 m with it (its right corrections waited; 9 wrong closures), seeds 27-33
    # the same either way (2026-12-07). inf: off
    solo_max_offset_m: float = 4.0
    # A windowed match on its window's edge (x or y on the box's outer cells, or the heading on its outer angles)
    # is rejected: the score is largest where the window cuts it off (an optimum on the boundary of the domain
    # searched is not a peak of the score), so the match is the flank of a place beyond the window or a place (a
    # corridor's next door) scoring better than the right one inside. Where the windows are bounded by the
    # compass's agreement (``agreement_factor``: a measured bound of the estimate's error, not a drift allowance)
    # a match whose own peak box (``ambiguity_exclude_xy`` / ``_deg``, the box the second-peak search cuts out)
    # reaches the edge is rejected too: its neighbourhood lies partly outside the window, and a match at the bound
    # of the estimate's error is improbable. On the simulated building with its compass (``bench_building_slam.py
    # --seeds 26 27 28 30 31 32 33 --wobble 0.995 1 1.005``, 21 runs) the wrong closures accepted directly lay
    # 1-3 cells inside their windows' edges (box ratio 0.90-0.99 for 5 of 6 on seed 28 x 0.995, 9 of 12 on 31 x
    # 0.995), the right ones there 0-2 a run: anchors over 1 m RMSE 4 -> 0 of 21 (seed 30 x 0.995 1.944 -> 0.648 m,
    # revisits 2.659 -> 0.068 m; 28 x 0.995 1.431 -> 0.276; 31 x 0.995 1.382 -> 0.280), revisits over 1 m 2 -> 1
    # (27 x 0.995 1.864 -> 1.710 m), median anchors 0.390 -> 0.368 m, revisits 0.092 -> 0.078 m. Without the
    # compass the band cost (30 x 1: revisits 0.041 -> 0.409 m, 26 x 1.005: 0.159 -> 1.023; right matches near the
    # edge of a drift allowance are as likely as wrong ones), so there the edge only: anchors median 0.346 ->
    # 0.343 m, none over 1 m. The shared logs (no compass; full, kidnapped, sparse) and the household: as before
    reject_on_edge: bool = True
    min_score: float = 0.55
    min_score_wide: float = 0.6
    # > 0: on a laser sparser than the thresholds' reference (``score_reference``: the score scale below 1), a
    # windowed match scoring at least this (scaled like the others) and below min_score / min_score_wide is not
    # dropped but offered to the consistency test like a global one (``consistency``: min_agreeing closures from
    # nodes metres apart agreeing on one correction, and the map check); one such search of an old submap per
    # ``consistency.min_separation_m`` of travel (the lower bound prunes less: ~4x a search's cost). Measured on
    # aces at 1.4 Hz with half the beams: a corridor revisit (~410 s -> ~1000 s) whose right matches scored
    # 0.30-0.45 against the scaled 0.43 was left open and two relations were 1.24-1.30 m off; with 0.4 (0.31
    # scaled) every sparse log improved (bench_realdata --variants sparse: aces 0.0717 -> 0.0545 m, max 1.30 ->
    # 0.67; intel 0.1046 -> 0.0892, max 1.25 -> 0.95; fr079 at the laser 0.0743 -> 0.0740); the full-rate logs
    # (scale 1) are untouched. Never across a break of local SLAM (the window cannot bound a lost estimate:
    # three weak aliases agreed on a wrong join of kidnapped aces, whose median score dips below the reference;
    # only the global search joins parts). 0: off
    agree_min_score: float = 0.4
    wide_window_xy: float = 3.0  # m
    depth: int = 7
    skip_recent: int = 2  # the submaps this many before the current one are its chain neighbours
    # squared Mahalanobis distance (3 dof): the anchors are re-solved after a node's closures only when one of them
    # disagrees with the current estimate by more than this (chi2(3) at 0.99 = 11.34); a closure within its own
    # noise of the estimate moves it by less than that noise, and the windows are many sigmas wide. 0: always
    resolve_min_d2: float = 11.34
    max_per_pair: int = 4  # closures kept between one old submap and one new submap
    wide_search_spacing: float = 2.0  # m travelled between two wide searches of one old submap
    precomputed_cache: int = 64  # submaps whose max-pooled grids stay in memory (a few ms to rebuild one)
    max_searches_per_node: int = 3  # narrow searches per node, nearest old submaps first (cost where many overlap)
    # m; > 0: the branch and bound searches a scan's points thinned by an adaptive voxel filter (scan_filter:
    # voxels up to search_voxel_m, at least search_min_points; the refinement uses every point). Off by default:
    # 0.1 m halves fr079's loop search (12.3 -> 6.4 s CPU) and maps the three real logs as well or a little
    # better (intel 0.0190 -> 0.0188 m, aces 0.0367 -> 0.0366, fr079 0.0662 -> 0.0660), but the ambiguity
    # test's margin was measured on whole scans and flags far fewer second peaks on thinned ones (fr079 57 -> 4):
    # the loops' protection against aliases would rest on the final solve. Cartographer's 0.9 m broke aces (a
    # 0.96 m relation error)
    search_voxel_m: float = 0.0
    search_min_points: int = 100  # points kept at least (Cartographer's loop-closure filter: 100)
    # Ambiguity (an alias along a corridor, a similar room): after the best match, the best pose of the same window
    # *outside* a box around it is sought (the same branch and bound with the box cut out: exact; when rejecting
    # it stops at the first pose above the threshold). One scoring within ``ambiguity_margin`` of the best is a
    # second peak: the scan fits two places about equally well and the score cannot tell which is right, while
    # the refinement's covariance only describes the surface within +-0.5 m of one of them. The defaults were
    # measured on the three real logs, a loop counted wrong when it lies > 0.3 m or d^2 > 21 from the final
    # solution (``benchmarks/bench_loops_realdata.py``; with score alone aces held 29 wrong of 189, fr079 45 of
    # 367, intel 214 of 1057): 0.15 m / 2 deg / 0.03 flag 29 of aces' 29 wrong loops (24 of its 160 right ones),
    # fr079 25 of 45 (27 of 322), intel 174 of 214 (130 of 843), and no loop of the drifting two-room test is
    # wrong. Most wrong loops have a flat score surface: a pose 0.2-0.3 m away scores within 0.01.
    ambiguity: str = "reject"  # "reject": no closure; "span": kept, with the peaks' spread added to its
    # covariance (``spanning_covariance``); "off": accepted on score alone (the rule before)
    # score units (mean probability of the points, 0.1-0.9): 0.02 misses 4 of aces' 29 wrong loops, 0.04 flags 9
    # more right ones there for none more wrong (fr079 +3 wrong / +11 right, intel +20 / +40)
    ambiguity_margin: float = 0.03
    # m, half-width of the box around the best in x and y: 3 cells at 5 cm, the best's own peak (its refinement
    # may move it by 2 cells); 0.1 m / 1 deg takes the peak's own slope for a second one (aces: 48 right loops
    # flagged instead of 24), 0.25 m / 3 deg lets wrong ones through (aces 1, intel 28 more; 2 of the drifting test)
    ambiguity_exclude_xy: float = 0.15
    ambiguity_exclude_deg: float = 2.0  # deg, half-width of the box in angle (measured with the 0.15 m above)
    ambiguity_peaks: int = 1  # second peaks sought, each outside the boxes of the ones before ("span")
    # score units: how far below its own peak the window's lattice can sample a place (its points are rounded to
    # cells after each lattice pose's rotation, its angles 0.5 deg apart). With "reject", in a window the compass's
    # agreement with dead reckoning bounds (a measured bound of the estimate's error), the lattice's second
    # peaks within ``ambiguity_margin`` + this of a windowed match (up to ``ambiguity_refined_peaks``, each the
    # best outside the boxes of the ones before) are refined like the match, and one scoring within
    # ``ambiguity_margin`` of the refined match is a second peak. Measured, refined minus lattice score of the
    # windowed matches: aces 0.001-0.039 (5-95 %, 137 matches; 10-90 % 0.029 apart), the household 0.004-0.082; on
    # the simulated building with its compass (seed 27, odometer x 0.995) an identical room 2.35 m along a corridor
    # scored 0.590 on the lattice (refined 0.609) and the truth 0.552 (refined 0.587, within the margin): accepted
    # alone, it drew two more wrong closures and the revisits went 1.71 m off. Not in drift windows (no compass):
    # there the building lost right corridor closures its map needed (seeds 26-33 x 3 odometer scales, anchors
    # over 1 m RMSE 0 -> 2 of 21, wrong closures 398 -> 305). 0: off
    ambiguity_lattice_slack: float = 0.03
    ambiguity_refined_peaks: int = 2  # the lattice's second peaks refined (the best outside the boxes, in turn)
    # m: an accepted closure's scan (windowed or global) is scored along its covariance's major axis this far each
    # way, beyond its window (``holoslam.submaps.periodic``): local maxima within ``ambiguity_margin`` of its score
    # farther than ``periodic_exclude_m`` (the match's own peak) are a corridor's periodic aliases, and the closure
    # keeps their spread along that axis. 10 m: the simulated building's aliases lie a room's width (4-7 m) along its
    # corridors, intel's 7.8-9.1 m. 0: off
    periodic_search_m: float = 10.0
    periodic_exclude_m: float = 1.0
    # The global search (``global_search``) for windows beyond max_window_xy / max_window_deg. Coarse grid: 4x the
    # map's 5 cm (measured on aces' submaps: 20-70 ms per whole submap and every heading instead of 0.3-1.2 s)
    global_resolution_m: float = 0.2
    # m, points the coarse search uses (the fine steps use every point): its angular step moves a point this far by
    # one coarse cell (10 m: 1.15 deg, 314 headings; see global_bundle_voxel_m for the measurement)
    global_max_range_m: float = 10.0
    # mean probability of the node's bundle (``global_bundle_m``) on the coarse grid. Measured on aces (first 900 s,
    # the 15 nodes of its windowed closures searched over whole submaps at every heading): the right submap's best
    # scores 0.535-0.60 (10-90 %) and lies at the right pose every time; two wrong submaps' best 0.31-0.36. A
    # single scan does not separate them (right 0.64-0.77, wrong 0.49-0.61): hence the bundle
    global_coarse_min_score: float = 0.45
    # the node's own scan at the map's resolution within global_check_xy / _deg of the coarse best: right 0.58-0.73,
    # wrong 0.40-0.51 in the same measurement; a windowed closure's min_score
    global_min_score: float = 0.55
    # global searches per searching node, the least recently searched submaps first (those the window reaches);
    # global_per_node_lost where the old submap is reached only across a break of local SLAM (the robot carried,
    # the log cut): then every old submap is a candidate and the join is worth more searches. Kidnapped aces
    # (35 old submaps) gathered no three agreeing closures at 2 a round and joined at 6
    global_per_node: int = 2
    global_per_node_lost: int = 6
    # m travelled between two nodes that run global searches (each costs 20-70 ms): the bundle's length, so that the
    # closures of two rounds in a row match disjoint scans and may vouch for each other (consistency's
    # min_separation_m). At 3 m, kidnapped aces found four right closures, from rounds 3.1-3.5 m apart, and no
    # three of them could form a clique: the parts stayed apart
    global_every_m: float = 4.0
    # closures waiting for agreement whose predicted place of the node is searched first (``_hypothesis_distances``):
    # the recent ones (a pending closure's correction goes stale as the estimate drifts on)
    hypothesis_closures: int = 3
    global_check_xy: float = 1.0  # m, the fine window around the coarse best (5 coarse cells)
    global_check_deg: float = 5.0  # deg (a few coarse angular steps)
    global_ambiguity_peaks: int = 3  # second peaks of a global match: kept with their spread ("span")
    # a global match is searched over every heading but kept only within the window's heading (uncapped: the
    # drift since the last closure, base_window_deg + window_deg_rate per m, or window_sigmas of the covariance;
    # every heading after a break of local SLAM). Its position is not held to the window: the drift window's
    # position was measured too small (a revisit 13 m off where it said 8 m), its heading was not. Measured on
    # every accepted closure of the three real logs, full and at 1.4 Hz with half the beams (the correction it
    # made to the estimate against the graph distance): right ones turned <= 9.5 deg within 40 m of graph and 38
    # deg at 142 m (window 152 deg), while six closures of sparse intel, accepted by agreement, turned 56-179 deg
    # at 21-43 m (windows 31-53 deg): aliases
    global_within_heading_window: bool = True
    # and by at most this many sigmas of the node's heading relative to the old submap (its marginal covariance in
    # the graph, as the covariance window's), when that is less: the drift window's 1 deg per m of graph allows every
    # heading after 170 m, and in a building whose wings read alike turned by a quarter or a half, three such
    # aliases agreed and joined (the simulated 350 m building without its compass, seed 28: 180 deg, 79-106 m off).
    # Measured on every closure offered for agreement (the real logs, full and at 1.4 Hz with half the beams; the
    # simulated building, seeds 26-28, without its compass: 131 offered, 111 wrong, 95 of them turned by more than
    # 45 deg): right ones turned the estimate by at most 1.3 sigma; the aliases turned by more than 45 deg by 9.6-68
    # sigma, those that were accepted (by agreement) by 22-41 sigma. 10 keeps a margin for the matches' overconfident
    # covariances (an fr079 revisit at 1.4 Hz on 2026-12-04's code: 20 deg against 3 sigma of 14 deg, 4.3 sigma; a
    # right closure there turned 38 deg after 142 m of graph, some 9 sigma by today's covariances) and stays under
    # the accepted aliases by 2x. 0: off. Across a break of local SLAM the sigma is unbounded: every heading
    global_heading_sigmas: float = 10.0
    # and its position within this many times the window's uncapped half-widths (wx, wy: the drift since the last
    # closure, or window_sigmas of the covariance), ``global_ambiguous_window_ratio`` when the match has second peaks
    # (``global_ambiguity_peaks``: the scan alone does not tell where it is, so only the estimate can). Measured on
    # every global candidate of the three real logs, full and at 1.4 Hz with half the beams, against the final map
    # (and of the simulated 350 m building against its truth): right closures lay at most 2.0x their window away
    # (fr079 at 1.4 Hz, 16 m after 142 m of graph), 0.27x when ambiguous; every accepted wrong one was ambiguous,
    # 0.5-11x away (sparse intel: 8 of its 9 accepted, 19-21 m off, 1.9-7.2x; the building: 10 of 10, 3.2-11x,
    # aliases along its identical corridors), and unambiguous wrong candidates were 2.6x or more away. The ambiguous
    # limit leaves room above the right ones' 0.27x for a corridor revisit whose drift outgrew its window: the held-out
    # hospital log's out-and-back corridors opened into a V 25 m wide after some 400 m of graph (window ~21 m, 1.2x)
    global_window_ratio: float = 2.5
    global_ambiguous_window_ratio: float = 1.5
    # m of the robot's path behind the node whose scans (in the node's frame, by local SLAM's poses) the global
    # search matches together with the node's: one 180-beam scan fits many places of a building, a few metres of
    # them few; thinned by the adaptive voxel filter to voxels up to bundle_voxel_m, at least 300 points
    global_bundle_m: float = 4.0
    # m and points: the bundle's thinning for the coarse step. A whole fr079 submap (17 x 40 m) at every heading
    # costs 260 ms CPU per search with voxels of 0.15 m and points to 15 m (360-530 points), 110 ms with 0.3 m /
    # 100 points and 10 m (130-300 points), and finds the right pose as often (16 against 17 of 129 searches of
    # fr079 at 1.4 Hz, the right poses' coarse scores 0.52-0.83 either way): 1.5 coarse cells per voxel
    global_bundle_voxel_m: float = 0.3
    global_bundle_min_points: int = 100  # Cartographer's loop-closure adaptive voxel filter keeps at least 100
    consistency: ConsistencyConfig = field(default_factory=ConsistencyConfig)
    verify: VerifyConfig = field(default_factory=VerifyConfig)  # the map check of a global closure (loop_verify)
    # Every score threshold above (and the ambiguity margin, and the keyframe stage's) was measured on lasers whose
    # scans match into their own submaps at a median score of 0.67-0.75 (aces 0.666, intel 0.729, fr079 0.745;
    # 300 s of each). A sparser laser fills the grids' cells less: the same logs decimated to 1.4 Hz with every
    # second beam match at 0.505-0.562, below the loops' 0.55, and aces then closed 8 loops of 550 searches. The
    # thresholds are scaled by min(1, median / score_reference): unchanged on the full-rate logs, 0.78-0.86 of
    # themselves on the sparse ones
    score_reference: float = 0.65
