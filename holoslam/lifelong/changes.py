"""Objects across sessions: each object of the store, keyed by its label id, is in this session

- **seen** where the store expected it: located within ``moved_m`` of its place, or farther but within what the
  two positions' covariances (and the session transform's) explain;
- **moved**: located farther than ``moved_m`` (the issue's 0.3 m) *and* beyond the chi-square gate of the
  displacement under its covariance (``moved_chi2``): both, so neither a poorly located object nor a millimetre
  jitter of a well located one counts;
- **gone**: not located although its place was in the robot's view: in view = within ``view_range_m`` of the
  robot, in front of its label (within ``normal_facing_deg`` of the label's normal when the readings told it,
  else within ``view_facing_deg`` of the direction it was seen from before: ``holoslam.lifelong.facing``), with
  no occupied cell of the store's merged grid between them; the camera's time is shared among the objects in view
  at once that it still has to read (a camera aimed at one label at a time reads one of them per snapshot; a
  label read ``competing_reads`` times in the session no longer competes), and an object is gone when its
  share reaches ``view_min_s``, or when at least ``min_images`` of the session's images held its place readable
  and read nothing there (``frustum``: the camera aimed at the place of an object of the map, the label's side
  facing it, its modules large enough, free space in between): the evidence of absence a robot that checks on
  the objects it knows collects; or when the session's laser observed the thing its label was on (the store's
  occupied cells next to its place) gone, nothing occupied left within ``moved_m`` (``support``: a label does not
  float);
- **new**: located and unknown to the store. An object the store called gone and located again is known by its
  label: seen or moved against the place it was last known at, as any other (on the simulated days a gone
  object seen again was a moved one not found on the day it moved, or a present label the camera had not read).

Objects neither located nor in view keep their last state (no row for this session).
Defaults from the simulator's camera, which stands for the robot's (``holoslam.sim.sensors``: labels are
readable to 3.5 m, facing the camera within 60 deg, one snapshot per 4 s at most, new labels first); the view
test is kept inside those bounds so that a label the robot merely could have seen is not called gone."""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from holoslam import geometry as g
from holoslam.lifelong.facing import Facing, facing, facing_cos
from holoslam.store.records import ObjectState, ObjectStatus

__all__ = ["ChangeConfig", "Located", "classify", "in_view_mask", "in_view_seconds", "label_facing",
           "unseen_view_seconds", "view_directions", "to_world"]


@dataclass(frozen=True, slots=True)
class ChangeConfig:
    moved_m: float = 0.3  # m: the "moved" (> 0.3 m)
    moved_chi2: float = 13.82  # chi-square(2) 0.999: the displacement is beyond what its covariance explains
    view_range_m: float = 2.5  # m from the robot's base (the simulated camera reads labels to 3.5 m)
    # deg from the direction it was seen from (when no normal is known). The camera reads within 60 deg of the
    # label's normal, but that direction is a mean of the sightings' directions, not the normal: a label seen
    # obliquely (a wardrobe's, at 1.1 m) lay 35-45 deg off it at the places the simulated camera could not read
    # it; 20 keeps inside
    view_facing_deg: float = 20.0
    # deg from the label's normal (``facing``), in the plane from the robot's base. The camera reads within 60 deg
    # of the normal in 3-D; the planar angle is smaller by the camera's height above or below the label (the
    # simulated PTZ at 1.10 m, labels at 0.38-2.0 m: up to 31 deg of elevation at 1.5 m of range, and 45 deg in
    # the plane with 31 deg of elevation is 53 deg in 3-D; 41 deg of elevation at 0.8 m: 58), and the normal errs
    # by its sigma (at most ``normal_max_sigma_deg``)
    normal_facing_deg: float = 45.0
    # deg: the normal is used only when its sigma is within this (else the seen direction): two sigmas of it and
    # the place's 2 deg leave the images' test (``FrustumConfig.normal_facing_deg``) 53 of the camera's 60. On seed
    # 1's ten simulated days the store's normals had sigmas of 0.44 deg (median), 1.0 (95th percentile), 6.2
    # (largest; 2 of 299 over 2.5), and erred by 0.18 deg (median) and 0.74 at most against the true normals
    normal_max_sigma_deg: float = 2.5
    # deg: a session's normal within this of the stored one is averaged with it; farther, the label was turned in
    # place (a chair turned but carried less than ``moved_m``) and the session's replaces it. The same angle as a
    # session's outlier test (``vision.normals.OUTLIER_DEG``): the store's normals erred by at most 0.92 deg on
    # the simulated days, so two sessions of an unturned label agree far within it
    normal_agree_deg: float = 30.0
    # deg from horizontal: a reading whose normal tilts more (a label lying flat) has no side in the plane
    normal_max_tilt_deg: float = 60.0
    # s of the camera's time (shared among the labels in view it still has to read): on 7 simulated days (seed 1,
    # 400 s each) the present labels the camera did not read reached 7.5-8.4 s; the absent ones not yet called
    # gone 2-44 s (10 or more in 14 of 25 cases); two and a half periods of the one-snapshot-per-4-s camera
    view_min_s: float = 10.0
    # a label read this many times in the session no longer competes for the camera (the simulated operator takes
    # two views of each label, the second from 0.5 m away, then photographs the ones it has not read first)
    competing_reads: int = 2
    view_step_s: float = 0.5  # s between the robot poses the view test looks at
    p_occupied: float = 0.65  # a merged-grid cell above this blocks the line of sight (map_server's occupied)
    skip_end_m: float = 0.6  # m before the object that never block: the furniture it stands on
    # images of the session whose frustum held the place readable (``holoslam.lifelong.frustum``: inside the
    # picture 10 % from its borders, the label's side facing the camera, its module >= 4 px, free space in
    # between) for an object not read there to be gone, whatever its time in view. A robot that checks on the
    # objects of its map aims its camera at their places (the simulated PTZ camera: ``sim.sensors``'
    # ``remembered``, zoomed for a 5 px module, and a place found empty looked at again in a later image): two
    # such images, each aimed on its own. One is not enough: a place known to a few cm, a pointing error of
    # 0.5 deg and the session's pose error can put one image's frustum on it while the label itself lay just
    # outside (the covering test asks the place 10 % of the picture from its borders, less than half a code
    # zoomed to 5 px a module)
    min_images: int = 2
    # the label's support (``holoslam.lifelong.support``): occupied cells of the store's grid within ``moved_m`` of
    # a place, at least this many (0.25 m of a piece of furniture's edge at 5 cm cells, not a stray cell), ...
    support_min_cells: int = 5
    # ... of which the session's laser observed this share (most of it: a part hidden behind other furniture may
    # still hold the label), none of the session's cells within ``moved_m`` occupied: the thing left, gone. On
    # the simulated days (bench_lifelong seeds 1-3, 10 days of 400 s) it called 4 labels gone, all on chairs
    # carried away (all of their 16-22 support cells observed free) and no present label; replayed offline on
    # seeds 2 and 3 no present label's support was observed without an occupied cell within 0.3 m
    support_seen_share: float = 0.8


@dataclass(frozen=True, eq=False)
class Located:
    """An object located in this session, in the world: position, 2x2 covariance, height, sightings, the
    direction it was seen from (unit vector or None), its kind and label text."""

    object_id: str
    w_xy: np.ndarray
    cov_w_xy: np.ndarray
    z: float
    sightings: int
    view: np.ndarray | None
    kind: str
    payload: str
    read_ns: tuple[int, ...] = ()  # the stamps of the session's readings of its label, in order
    normal: np.ndarray | None = None  # its label's normal in the world (``facing.session_normals``), unit (2,)
    normal_sigma_rad: float = math.nan


def to_world(s_xy: np.ndarray, cov_s_xy: np.ndarray, wTs: np.ndarray, cov_wTs: np.ndarray | None
             ) -> tuple[np.ndarray, np.ndarray]:
    """A session-frame point and covariance in the world under wTs (its covariance, body frame, propagated)."""
    R = g.rot2(float(wTs[2]))
    w = g.transform_points(wTs, np.asarray(s_xy, np.float64)[None])[0]
    cov = R @ np.asarray(cov_s_xy) @ R.T
    if cov_wTs is not None:
        J = np.zeros((2, 3))
        J[:, :2] = R
        J[:, 2] = R @ np.array([-s_xy[1], s_xy[0]])
        cov = cov + J @ cov_wTs @ J.T
    return w, 0.5 * (cov + cov.T)


def view_directions(obs_stamps_ns: np.ndarray, obs_ids: tuple[str, ...], stamps_ns: np.ndarray, w_xy_robot: np.ndarray,
                    w_objects: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per object, the mean unit vector from the object to the robot at its sightings (the side it is seen
    from), in the world."""
    out: dict[str, np.ndarray] = {}
    if not len(obs_ids):
        return out
    k = np.clip(np.searchsorted(stamps_ns, obs_stamps_ns), 0, len(stamps_ns) - 1)
    robot = w_xy_robot[k]
    for oid in set(obs_ids):
        if oid not in w_objects:
            continue
        sel = np.array([o == oid for o in obs_ids])
        d = robot[sel] - w_objects[oid]
        d = d / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)[:, None]
        m = d.mean(axis=0)
        n = float(np.hypot(*m))
        if n > 1e-6:
            out[oid] = m / n
    return out


def label_facing(view: np.ndarray | None, normal: np.ndarray | None, normal_sigma_rad: float,
                 cfg: ChangeConfig) -> Facing:
    """The side the view test counts (``facing.facing`` with ``cfg``'s angles)."""
    return facing(view, normal, normal_sigma_rad, cfg.view_facing_deg, cfg.normal_facing_deg,
                  cfg.normal_max_sigma_deg)


def in_view_mask(w_xy: np.ndarray, view: np.ndarray | None, w_xy_robot: np.ndarray, merged,
                 cfg: ChangeConfig, normal: np.ndarray | None = None, normal_sigma_rad: float = math.nan
                 ) -> np.ndarray:
    """Per robot pose, whether the object's place was in view (module docstring): within range, in front of its
    label (within ``normal_facing_deg`` of ``normal`` when known, else ``view_facing_deg`` of the seen side
    ``view``, else any side), and no occupied cell of ``merged`` (a ``MergedGrid``) in between."""
    d = w_xy_robot - np.asarray(w_xy)[None]
    r = np.hypot(d[:, 0], d[:, 1])
    ok = r <= cfg.view_range_m
    ok &= facing_cos(label_facing(view, normal, normal_sigma_rad, cfg), d)
    idx = np.flatnonzero(ok)
    if idx.size and merged is not None:
        blocked = merged.occupied_between(w_xy_robot[idx], np.broadcast_to(w_xy, (len(idx), 2)), cfg.p_occupied,
                                          cfg.skip_end_m)
        ok[idx[blocked]] = False
    return ok


def _dt(stamps_ns: np.ndarray) -> np.ndarray:
    dt = np.diff(np.asarray(stamps_ns, np.int64), append=np.int64(stamps_ns[-1])) * 1e-9
    return np.minimum(dt, 1.0)  # a gap in the stamps is not time in view


def in_view_seconds(w_xy: np.ndarray, view: np.ndarray | None, stamps_ns: np.ndarray, w_xy_robot: np.ndarray,
                    merged, cfg: ChangeConfig, normal: np.ndarray | None = None,
                    normal_sigma_rad: float = math.nan) -> float:
    """Seconds the robot spent with the object's place in view (``in_view_mask``), not shared."""
    if not len(stamps_ns):
        return 0.0
    return float(_dt(stamps_ns)[in_view_mask(w_xy, view, w_xy_robot, merged, cfg, normal, normal_sigma_rad)].sum())


def _thin(stamps_ns: np.ndarray, w_xy_robot: np.ndarray, step_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The robot poses at most every ``step_s`` (the first of each step)."""
    t = np.asarray(stamps_ns, np.int64)
    if not len(t):
        return t, w_xy_robot
    bins = (t - t[0]) // max(int(step_s * 1e9), 1)
    keep = np.r_[True, np.diff(bins) > 0]
    return t[keep], w_xy_robot[keep]


def classify(stored: Mapping[str, ObjectState], located: Mapping[str, Located], stamps_ns: np.ndarray,
             w_xy_robot: np.ndarray, merged, cfg: ChangeConfig = ChangeConfig(),
             view_s: dict[str, float] | None = None, images: Mapping[str, int] | None = None,
             support_left: Collection[str] = ()) -> dict[str, str]:
    """Each object's status in this session (module docstring): object id -> ``ObjectStatus`` value, for the
    located objects and the stored ones not located but in view (gone): its share of the camera's time in view
    reaches ``view_min_s``, or ``images`` (per stored object not located, the session's images that held its
    place readable: ``frustum.covering_images``; None for a log without images) counts ``min_images``, or it is
    in ``support_left`` (the session's laser saw the thing it was on gone from its place: ``support``).
    ``view_s``, when given, receives every stored object not located with its share."""
    out: dict[str, str] = {}
    shares = unseen_view_seconds(stored, located, stamps_ns, w_xy_robot, merged, cfg)
    if view_s is not None:
        view_s.update(shares)
    for oid, sec in shares.items():
        if sec >= cfg.view_min_s or (images is not None and images.get(oid, 0) >= cfg.min_images) \
                or oid in support_left:
            out[oid] = ObjectStatus.GONE
    for oid, loc in located.items():
        old = stored.get(oid)
        if old is None or old.w_xy is None:
            out[oid] = ObjectStatus.NEW
            continue
        d = loc.w_xy - old.w_xy
        S = loc.cov_w_xy + (old.cov_w_xy if old.cov_w_xy is not None else np.zeros((2, 2))) + np.eye(2) * 1e-8
        m2 = float(d @ np.linalg.solve(S, d))
        out[oid] = ObjectStatus.MOVED if (np.hypot(*d) > cfg.moved_m and m2 > cfg.moved_chi2) else ObjectStatus.SEEN
    return out


def unseen_view_seconds(stored: Mapping[str, ObjectState], located: Mapping[str, Located], stamps_ns: np.ndarray,
                        w_xy_robot: np.ndarray, merged, cfg: ChangeConfig) -> dict[str, float]:
    """Each stored object not located (and not gone before) with its share of the camera's time in view (s)."""
    missing = [k for k, o in stored.items() if k not in located and o.status != ObjectStatus.GONE and o.w_xy is not None]
    if not missing or not len(stamps_ns):
        return dict.fromkeys(missing, 0.0)
    t, xy = _thin(stamps_ns, w_xy_robot, cfg.view_step_s)
    places: list[tuple[Any, Any, Any, float]] = [
        (stored[k].w_xy, stored[k].view, stored[k].normal, stored[k].normal_sigma_rad) for k in missing]
    places += [(o.w_xy, o.view, o.normal, o.normal_sigma_rad) for o in located.values()]
    masks = np.array([in_view_mask(p, v, xy, merged, cfg, n, sn) for p, v, n, sn in places])
    for j, o in enumerate(located.values()):  # read enough: no longer competing for the camera
        if cfg.competing_reads > 0 and len(o.read_ns) >= cfg.competing_reads:
            masks[len(missing) + j, t > o.read_ns[cfg.competing_reads - 1]] = False
    share = (masks * _dt(t)[None]) / np.maximum(masks.sum(axis=0), 1)[None]
    return {k: round(float(s), 2) for k, s in zip(missing, share[: len(missing)].sum(axis=1), strict=True)}
