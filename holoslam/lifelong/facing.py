"""The side an object's label is read from, for the view tests of change detection (``changes.in_view_mask``:
the robot's time with the place in view; ``frustum.covering_images``: the images that held it readable).

A label is read only from in front of it: the simulated camera, like QR decoding, within 60 deg of its normal.
Two estimates of that side:

- its **normal** (``session_normals``): each reading's normal from the pose of the label's corners
  (``ObjectObservation.b_normal``, ``holoslam.vision.locate``), turned into the world by the robot's heading at
  the reading, its horizontal direction averaged over the session's readings by their quality
  (``holoslam.vision.normals.mean_direction``), and kept across sessions while the label stays at its place
  (``updated_normal``). The view tests then count a place in view within ``normal_facing_deg`` of it;
- the **mean direction it was seen from** (``changes.view_directions``): the fallback when no normal is known
  (a log of robot tag sightings without corners, a store written before the normal was kept). A label seen once
  or twice obliquely lies far off that direction (43-54 deg measured on the simulated days), so the test keeps to
  ``view_facing_deg`` around it.

``facing`` picks one: the normal when it is known within ``max_sigma_deg``, else the seen direction."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from holoslam import geometry as g

__all__ = ["Facing", "facing", "facing_cos", "session_normals", "updated_normal"]


@dataclass(frozen=True, slots=True)
class Facing:
    """The side a label is read from: a horizontal unit direction in the world (None: any side) and the largest
    angle (deg) from it at which its place counts as in view; ``from_normal`` whether it is the label's normal."""

    direction: np.ndarray | None
    half_angle_deg: float
    from_normal: bool = False


def facing(view: np.ndarray | None, normal: np.ndarray | None, normal_sigma_rad: float, view_deg: float,
           normal_deg: float, max_sigma_deg: float) -> Facing:
    """The normal within ``normal_deg`` when it is known (sigma at most ``max_sigma_deg``), else the direction the
    label was seen from within ``view_deg``, else any side (module docstring)."""
    if normal is not None and np.isfinite(normal_sigma_rad) and math.degrees(normal_sigma_rad) <= max_sigma_deg:
        return Facing(np.asarray(normal, np.float64), normal_deg, True)
    if view is not None:
        return Facing(np.asarray(view, np.float64), view_deg)
    return Facing(None, 180.0)


def facing_cos(f: Facing, d: np.ndarray) -> np.ndarray:
    """Per row of ``d`` (M, 2 or 3: from the place to the robot or camera), whether it lies within the facing's
    angle (the normal is horizontal: a 3-D ``d`` is tested in 3-D, as a camera above the label sees it)."""
    d = np.asarray(d, np.float64)
    if f.direction is None:
        return np.ones(len(d), bool)
    n = np.zeros(d.shape[1])
    n[:2] = f.direction[:2]
    cosang = (d @ n) / np.maximum(np.linalg.norm(d, axis=1), 1e-9)
    return np.asarray(cosang >= math.cos(math.radians(f.half_angle_deg)))


def session_normals(observations: Sequence[Any], stamps_ns: np.ndarray, w_wTb: np.ndarray,
                    max_tilt_deg: float) -> dict[str, tuple[np.ndarray, float]]:
    """Per object, its label's normal in the world from the session's readings (``ObjectObservation`` with
    ``b_normal``): each turned by the robot's heading at its stamp (``w_wTb`` (N, 3) at ``stamps_ns``, in the
    world), its horizontal direction averaged by ``mean_direction``; a reading whose normal is more than
    ``max_tilt_deg`` from horizontal (a label lying flat: no side to be read from in the plane) is left out.
    Returns object id -> (unit (2,), sigma in rad)."""
    from holoslam.vision.normals import mean_direction

    rows = [o for o in observations if getattr(o, "b_normal", None) is not None]
    if not rows or not len(stamps_ns):
        return {}
    yaw = g.interpolate_poses(stamps_ns, w_wTb, np.array([o.stamp_ns for o in rows], np.int64))[:, 2]
    b = np.array([o.b_normal for o in rows], np.float64)
    c, s = np.cos(yaw), np.sin(yaw)
    w = np.column_stack([c * b[:, 0] - s * b[:, 1], s * b[:, 0] + c * b[:, 1]])
    flat = np.hypot(w[:, 0], w[:, 1]) < math.cos(math.radians(max_tilt_deg))
    sigma = np.array([o.normal_sigma_rad for o in rows], np.float64)
    ids = np.array([o.object_id for o in rows], dtype=object)
    out: dict[str, tuple[np.ndarray, float]] = {}
    for oid in sorted(set(ids.tolist())):
        sel = (ids == oid) & ~flat
        if not sel.any():
            continue
        m, sd, _ = mean_direction(w[sel], sigma[sel])
        if m is not None:
            out[oid] = (m, sd)
    return out


def updated_normal(old: np.ndarray | None, old_sigma_rad: float, new: np.ndarray | None, new_sigma_rad: float,
                   agree_deg: float) -> tuple[np.ndarray | None, float]:
    """The normal of a label seen at its stored place again: the stored and the session's averaged (weighted by
    their sigmas) when they agree within ``agree_deg``; else the session's (the label was turned in place: the
    newer reading wins, as the newer session's cells do in the merged map); the stored one when the session
    has none."""
    from holoslam.vision.normals import mean_direction

    if new is None:
        return old, old_sigma_rad
    if old is None or not np.isfinite(old_sigma_rad):
        return new, new_sigma_rad
    cos = float(np.asarray(old) @ np.asarray(new))
    if cos < math.cos(math.radians(agree_deg)):
        return new, new_sigma_rad
    m, _sd, _ = mean_direction(np.array([old, new], np.float64), np.array([old_sigma_rad, new_sigma_rad]),
                               outlier_deg=agree_deg, min_sigma_deg=0.0)
    info = 1.0 / math.sqrt(1.0 / max(old_sigma_rad, 1e-9) ** 2 + 1.0 / max(new_sigma_rad, 1e-9) ** 2)
    return (new, new_sigma_rad) if m is None else (m, info)
