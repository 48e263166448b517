"""The run's located objects: each landmark of the solution as a graph record (``ObjectInfo``: kind and
attributes from its label, height from its sightings, covariance from the solution, feature set, sightings), and
how each was located (``located_by``)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from holoslam.errors import HoloslamError
from holoslam.graph.keys import is_before, object_of

__all__ = ["located_objects", "located_by", "OBJECT_HEIGHT_SIGMA_M"]

# The located objects' height sigma (m), put in their covariance's z entry: the solve is planar and does not
# estimate heights (they are the sightings' median). The value the run has always written; not a measured spread.
OBJECT_HEIGHT_SIGMA_M = 0.02


def located_objects(problem: Any, solution: Any, seen: Any) -> tuple:
    """The located objects as graph records (``holoslam.maps.holographic.ObjectInfo``), from the SLAM problem,
    its solution and the run's sightings (``holoslam.sightings.Sightings``: observations, feature sets, and the
    views beyond one per landmark measurement, which count as sightings too). A moved object's earlier place
    (``<id>@...``) stays in the solution, not as a separate object."""
    from holoslam.graph.problem import MeasurementFamily
    from holoslam.maps.holographic import ObjectInfo

    payload = {o.object_id: o.payload for o in seen.observations}
    lm = problem.landmarks
    rejected = {r.index for r in solution.rejected if r.family is MeasurementFamily.LANDMARK}
    kept = Counter(
        object_of(name) for k, name in enumerate(lm.landmark if lm is not None else ()) if k not in rejected
    )
    objs = []
    for k, oid in enumerate(solution.landmark_ids):
        if is_before(oid):
            continue
        z = _height(lm, oid)
        kind, attrs, text = _label(payload, oid)
        xy = solution.w_landmarks[k]
        feats = _feature_attrs(seen.features[oid]) if seen.features and oid in seen.features else {}
        objs.append(
            ObjectInfo(
                oid,
                kind,
                np.array([xy[0], xy[1], 0.0 if not np.isfinite(z) else z]),
                _covariance(solution, k),
                attrs,
                text,
                feats,
                sightings=kept[oid] + seen.extra_sightings.get(oid, 0),
            )
        )
    return tuple(objs)


def _height(lm: Any, oid: str) -> float:
    """The median height of the landmark's (and its earlier places') sightings, NaN when none has one."""
    if lm is None or not len(lm.landmark):
        return np.nan
    base = object_of(oid)
    sel = np.array([object_of(name) == base for name in lm.landmark])
    zs = lm.z[sel]
    zs = zs[np.isfinite(zs)]
    return float(np.median(zs)) if zs.size else np.nan


def _covariance(solution: Any, k: int) -> np.ndarray:
    """Landmark k's world covariance (x, y, z); NaN when the solve computed none."""
    if solution.cov_w_landmarks is None:
        return np.full((3, 3), np.nan)
    cov = np.zeros((3, 3))
    cov[:2, :2] = solution.cov_w_landmarks[k]
    cov[2, 2] = OBJECT_HEIGHT_SIGMA_M**2
    return cov


def _label(payload: dict[str, str], oid: str) -> tuple[str, tuple, str]:
    """Kind, attributes and text of the label object ``oid`` was read from."""
    from holoslam.vision.label import FOREIGN_PREFIX, parse_label

    base = object_of(oid)
    try:
        label = parse_label(payload.get(base, ""))
        return label.kind, label.attributes, payload[base]
    except HoloslamError:  # an anonymous landmark (a foreign code keyed by its payload), or unknown
        return ("qr_code" if base.startswith(FOREIGN_PREFIX) else "unknown"), (), payload.get(base, "")


def _feature_attrs(f: Any) -> dict[str, Any]:
    """The object feature set (Eq. 13) as node attributes: scalars and small arrays."""
    s = f.to_summary()
    return {
        "size_m": s["size_m"] if s["size_m"] is not None else float("nan"),
        "range_m": s["range_m"] if s["range_m"] is not None else float("nan"),
        "n_crops": s["n_crops"],
        "n_sift": s["n_sift"],
        "texture_lbp": np.asarray(s["texture_lbp"], dtype=np.float64),
        "colours_lab": np.asarray(s["colours_lab"], dtype=np.float64),
        "colour_weights": np.asarray(s["colour_weights"], dtype=np.float64),
    }


def located_by(observations: Sequence[Any], objects: Sequence[Any]) -> dict[str, dict[str, str]]:
    """Per located object: where its sightings came from ("images", "tags", "images+tags") and how it was
    located ("pnp", "triangulation", "pnp+triangulation")."""
    src: dict[str, set[str]] = {}
    how: dict[str, set[str]] = {}
    for o in observations:
        src.setdefault(o.object_id, set()).add(o.source or "?")
        how.setdefault(o.object_id, set()).add(o.method)
    return {
        o.object_id: {"source": "+".join(sorted(src.get(o.object_id, {"?"}))),
                      "method": "+".join(sorted(how.get(o.object_id, {"?"}), key=lambda m: m != "pnp"))}
        for o in objects
    }
