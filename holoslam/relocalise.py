"""Global relocalisation of a new session against a map store: where the session's own frame s lies in the
store's world w (``wTs``), from an unknown start, or the answer that it cannot be placed.

Two independent sources of hypotheses, each verified before a session is joined:

- **Objects** (known data association): an object id the session located that the store knows is a
  correspondence between its position in s and its latest position in w. Two objects at least
  ``min_pair_separation_m`` apart fix an SE(2) hypothesis; every pair is tried (RANSAC over pairs, exhaustive:
  a session sees tens of objects), the hypothesis with most objects within ``object_inlier_m`` is refined by
  least squares over them. It is verified when ``min_object_inliers`` objects agree (two points always fit
  an SE(2) exactly; the third is the first check, and a moved object is simply an outlier).
- **Laser**: the scan at every session submap's anchor (``query_points``) is searched in every working submap of
  the store by a global branch-and-bound over the whole stored submap and every heading (``global_match``: the one function to swap
  for another global search), refined by the continuous matcher (its covariance). A match of session submap i
  in stored submap j gives wTs = wTa_j ∘ ajTai ∘ (sTa_i)^-1. Matches are grouped by pairwise consistency
  (``consistent_xy_m``, ``consistent_deg``); the largest group is verified when it holds ``min_consistent``
  matches (Cartographer's own relocalisation test requires at least 3 cross-trajectory constraints) from at
  least ``min_session_submaps`` session submaps and no inconsistent group comes close to it
  (``runner_up_ratio``: a symmetric home or two alike rooms give two groups).

No optimiser here: the joint solve (``holoslam.lifelong``) refines the verified hypothesis.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from holoslam.relocalise_parts import (
    Hypothesis,
    LaserMatch,
    Relocalisation,
    RelocaliseConfig,
    _agree,
    _checked,
    _consistent,
    checked_hypothesis,
    fit_se2,
    global_match,
    join_agreement,
    laser_groups,
    laser_hypothesis,
    laser_matches,
    local_matches,
    object_hypothesis,
    precompute_stored,
)
from holoslam.relocalise_predict import Prediction, predict, predicted_hypothesis

__all__ = ["RelocaliseConfig", "LaserMatch", "Hypothesis", "Relocalisation", "global_match", "precompute_stored", "laser_matches",
           "laser_hypothesis", "checked_hypothesis", "laser_groups", "Prediction", "predict", "predicted_hypothesis", "object_hypothesis", "relocalise", "fit_se2", "local_matches", "join_agreement"]

_DEFAULTS = RelocaliseConfig()  # frozen: the default of ``relocalise``


def relocalise(session_submaps, session_sTa: np.ndarray, session_objects: dict[str, np.ndarray],
               stored_submaps, stored_objects: dict[str, np.ndarray],
               cfg: RelocaliseConfig = _DEFAULTS) -> Relocalisation:
    """Both sources, verified and combined: laser and objects verified and agreeing -> "both"; one verified and
    the other absent, unverified but agreeing, or unverified and disagreeing -> that one; both verified but
    disagreeing -> not placed (said why); neither verified -> not placed."""
    t0, c0 = time.perf_counter(), time.process_time()
    obj = object_hypothesis(session_objects, stored_objects, cfg)
    # a verified object hypothesis only chooses where the laser looks first; the laser's matches stay global
    matches, searches = laser_matches(session_submaps, session_sTa, stored_submaps, cfg,
                                      obj if obj is not None and obj.verified else None)
    las, refused, refuted = _checked(matches, session_submaps, session_sTa, stored_submaps, cfg)
    if las is not None and not las.verified:
        pred, tried = predicted_hypothesis(matches, session_submaps, session_sTa, stored_submaps, cfg, refuted)
        if pred is not None and pred.verified:
            las = dataclasses.replace(pred, why=f"verified by prediction: {pred.why} (the global matches alone: "
                                                f"{las.why})")
        elif tried:
            las = dataclasses.replace(las, why=f"{las.why}; predictions: " + "; ".join(p.text() for p in tried))
    if las is not None and refused:
        las = dataclasses.replace(las, why=las.why + "; " + "; ".join(refused))
    lv, ov = las is not None and las.verified, obj is not None and obj.verified
    chosen: Hypothesis | None = None
    if lv and ov:
        assert las is not None and obj is not None
        if _agree(las, obj, cfg):
            chosen, by, why = las, "both", f"laser: {las.why}; objects: {obj.why}"
        else:
            chosen, by, why = None, "none", (f"the laser and the objects disagree (laser: {las.why}; objects: "
                                             f"{obj.why}): not joined")
    elif lv:
        assert las is not None
        by = "both" if obj is not None and obj.support >= 2 and _agree(las, obj, cfg) else "laser"
        chosen, why = las, f"laser: {las.why}" + ("" if obj is None else f"; objects: {obj.why}")
    elif ov:
        assert obj is not None
        chosen, by, why = obj, "objects", f"objects: {obj.why}" + ("" if las is None else f"; laser: {las.why}")
    else:
        by = "none"
        why = "no verified hypothesis: " + "; ".join(
            [f"laser: {las.why}" if las is not None else "laser: no match above the score" + "".join(
                f"; {r}" for r in refused),
             f"objects: {obj.why}" if obj is not None else "objects: fewer than two known to the store"])
    consistent: tuple[LaserMatch, ...] = ()
    if chosen is not None:
        T = np.array([m.wTs for m in matches]).reshape(-1, 3)
        consistent = tuple(m for m, ok in zip(matches, _consistent(T, chosen.wTs[None], cfg)[:, 0], strict=True)
                           if ok)
    return Relocalisation(by, chosen, las, obj, consistent, searches, time.perf_counter() - t0, why,
                          tuple(matches), time.process_time() - c0)
