"""The simulated days' changes as a camera could have observed them (``bench_lifelong.py --parts sim``).

The simulator's truth (``days.json``) says what happened to every object between two days. Not all of it can be
seen: an object carried to a place where no image of the day read it is, for any robot, "not seen although its
place was in view" (the issue's *gone*) on that day when its old place was in view; it is found again, *moved*
against the place it was last known at, on the first day an image reads it. The **observable truth** follows the
issue's definitions (per session an object is moved, gone or new) with "seen" meaning read in the day's images
and "in view" photographable from a pose of the day. It is decided from the simulator's truth, the day's true
trajectory and the simulator's record of what the day's images read, before and without holoslam's answer.

**Observable** (the goal's rule, ``rule="read"``): a label is observable on a day when one of the images the day's
camera actually took read it (``days.json`` ``photographed``, the simulator's record of its reading test
``holoslam.sim.sensors.readable_labels`` on each image it took; ``image_reads`` recomputes it from the log, each
image's true camera from the base's ground truth, the head's ``/tf`` and ``camera_info``, and reproduces the record
exactly on seeds 1-5). Any robot is bound by it: a label's identity, and so an object's new place or an added
object, is known only from an image that read it. The simulated camera takes one aimed image per 4 s, and a label
photographable for a few seconds of a day may be in none of them (seed 4 with whole tours, day 7: ``O35``, carried
with the office chair, photographable for 3.5 s at its new place and read in none of the day's 115 images; the
photographable rule called it "moved" that day, which no system given those images could report). A **place**
(for gone) stays observable by the rule below, photographable from a pose of the day: absence is also seen by
the laser (the thing a label stood on carried away, ``holoslam.lifelong.support``), not only in an image; asking
an image there counted the laser's right "gone" as false (400 s days, seeds 2 and 3: ``O35`` on day 2 and day 3,
its chair's old footprint seen free, no image of its place that day).

**Photographable** (``rule="photographable"``, the rule before; the bench prints its score too):

(``readable_mask``) a label (the simulator's ``WorldObject``: its centre, normal, size and
payload) at a pose of the day's true trajectory (tested every ``STEP_S``) when the PTZ camera on its mast could
hold it readable in an image, at the camera's reading limits (``holoslam.sim.sensors.readable_labels``), not the
operator's narrower aiming rule (``_can_photograph``: 3.5 m, 56.6 deg, 5 px modules), since a label is also read
in an image aimed at another: its normal within ``sensors.MAX_FACING_DEG`` (60 deg, in 3-D) of the camera, the
camera's tilt to it within ``TILT_MAX_DEG``, its module at least ``sensors.MIN_MODULE_PX`` (3 px) at the full zoom
``sensors.ZOOM_MAX`` seen face-on (a distance limit, ``max_read_m``), and no wall or furniture at least as tall
as the label in between (``sensors._occluded``). Under this rule a label is observable on a day when it was
photographable for at least ``MIN_VIEW_S`` (one tested pose: "could be photographed at all"), or read in that
day's images (``days.json`` ``photographed``), and a place when the label as it stood there was photographable.

**The rule**, per object from day 2 on, against the place the store should know it at (``known``: its place on
the last day it was observable; day 1's observable objects start it; an object there from day 1 that no day
could photograph yet has none, and its first sighting is no change):

- present, observable, and more than ``MOVED_M`` from ``known`` (also after it was reported gone): **moved**;
- an added object (not in day 1's home), observable for the first time: **new** (on that day, not the day it
  was added when nothing could photograph it then);
- not at ``known`` (taken away, or more than ``MOVED_M`` from it and not observable), not reported gone yet, and
  its place ``known`` photographable that day (the label as it stood there, ``MIN_VIEW_S``; both rules): **gone**;
  if its place could not be photographed the gone waits for the first day it can be;
- anything else: no change (an object at its place that the camera could not see keeps its state).

``raw`` truth is ``days.json``'s changes as they happened (moved / removed = gone / added = new), every one on its
day. The bench prints all three (observable, photographable, raw); the issue's goal is judged on the observable
one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

STEP_S = 0.25  # s between the poses of the day's true trajectory tested (0.1 m at the route's 0.4 m/s)
MIN_VIEW_S = STEP_S  # s photographable for a label to be observable: one tested pose ("could be photographed")
TILT_MAX_DEG = 45.0  # deg: the PTZ head's tilt range (holoslam.sim.sensors: tilt -45..+45 deg)
MOVED_M = 0.3  # m: the "moved" (> 0.3 m), holoslam.sim.days.MOVED_M
RAW_KINDS = {"moved": "moved", "removed": "gone", "added": "new"}


@dataclass(frozen=True, eq=False)
class ImageCamera:
    """One image the day's camera took, as the simulator took it: stamp, intrinsics K (3, 3), the optical frame's
    true rotation wRc (3, 3) and centre wtc (3,) in the simulator's map, and the image size (width, height)."""

    stamp_ns: int
    K: np.ndarray
    wRc: np.ndarray
    wtc: np.ndarray
    size: tuple[int, int]


def image_cameras(log_path: Path) -> list[ImageCamera]:
    """The day's images with their true camera poses: the base's ground truth interpolated at each image's stamp,
    composed with the head's transform (``/tf``: the mount and the pan / tilt the image was taken at) and the
    image's ``camera_info`` (``holoslam.lifelong.frustum.camera_views``). The simulator's own record, not holoslam's
    estimate: no estimated pose enters."""
    from holoslam import geometry as g
    from holoslam.io.mcap import read_log
    from holoslam.lifelong.frustum import camera_views

    log, _ = read_log(log_path)
    v = camera_views(log)
    t, wTb = log.ground_truth_arrays()
    if not len(v) or not len(t):
        return []
    p = g.interpolate_poses(t, wTb, v.stamps_ns)
    out = []
    for k in range(len(v)):
        c, s = math.cos(p[k, 2]), math.sin(p[k, 2])
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        out.append(ImageCamera(int(v.stamps_ns[k]), v.K[k], R @ v.bTc[k, :3, :3],
                               np.array([p[k, 0], p[k, 1], 0.0]) + R @ v.bTc[k, :3, 3],
                               (int(v.size[k, 0]), int(v.size[k, 1]))))
    return out


def image_reads(world, obj, images: list[ImageCamera]) -> int:
    """How many of ``images`` would read ``obj``'s label (a ``WorldObject``) standing where it says, in ``world``'s
    walls and furniture: the simulator's reading test (``holoslam.sim.sensors.readable_labels``) per image. The
    check of ``days.json``'s ``photographed`` record, and for a missed gone whether an image held the old place
    (``lifelong_misses``)."""
    import dataclasses

    from holoslam.sim.camera import qr_modules
    from holoslam.sim.sensors import readable_labels

    alone = dataclasses.replace(world, objects=(obj,), codes=())
    modules = {obj.object_id: qr_modules(obj.payload)}
    return sum(obj.object_id in readable_labels(alone, modules, c.K, c.wRc, c.wtc, c.size)[0] for c in images)


def camera_positions(log_path: Path, step_s: float = STEP_S) -> np.ndarray:
    """The PTZ camera's centre (N, 3) in the simulator's map at the day's true poses, one per ``step_s``."""
    from holoslam.io.mcap import read_log
    from holoslam.sim.camera import camera_pose_world

    log, _ = read_log(log_path, require=["odometry"])
    t, wTb = log.ground_truth_arrays()
    if not len(t):
        return np.zeros((0, 3))
    keep = np.r_[True, np.diff((t - t[0]) // int(step_s * 1e9)) > 0]
    return np.array([camera_pose_world(p, 0.0, 0.0)[1] for p in wTb[keep]])


@lru_cache(maxsize=256)
def _modules(payload: str) -> int:
    from holoslam.sim.camera import qr_modules

    return int(qr_modules(payload).shape[0])


def max_read_m(obj) -> float:
    """m: the farthest the camera reads ``obj``'s label, face-on at full zoom with ``MIN_MODULE_PX`` modules."""
    from holoslam.sim import sensors as S

    return S.F0 * S.ZOOM_MAX * obj.label_size / (S.MIN_MODULE_PX * _modules(obj.payload))


def readable_mask(world, obj, cams: np.ndarray) -> np.ndarray:
    """Per camera centre (N, 3), whether ``obj``'s label (a ``WorldObject``, standing where it says, in ``world``'s
    walls and furniture) is within the camera's reading limits (module docstring)."""
    from holoslam.sim import sensors as S
    from holoslam.sim.world import segments_block

    cams = np.asarray(cams, float).reshape(-1, 3)
    p = np.asarray(obj.position, float)
    d = cams - p[None]
    r = np.linalg.norm(d, axis=1)
    n = np.array([math.cos(obj.label_yaw), math.sin(obj.label_yaw), 0.0])
    ok = (d @ n) >= math.cos(math.radians(S.MAX_FACING_DEG)) * r
    ok &= np.abs(np.degrees(np.arctan2(-d[:, 2], np.hypot(d[:, 0], d[:, 1])))) <= TILT_MAX_DEG
    ok &= r <= max_read_m(obj)
    idx = np.flatnonzero(ok)
    if idx.size:
        a, b = cams[idx, :2], np.broadcast_to(p[:2], (idx.size, 2))
        blocked = segments_block(world.wall_segments(), a, b)
        blocked |= segments_block(world.furniture_segments(min_height=p[2], exclude=obj.furniture), a, b)
        ok[idx[blocked]] = False
    return ok


def photographable_s(world, obj, cams: np.ndarray, step_s: float = STEP_S) -> float:
    """Seconds of the day (``cams`` one per ``step_s``) in which ``obj``'s label could be photographed."""
    return float(readable_mask(world, obj, cams).sum()) * step_s


@dataclass
class _Known:
    obj: object  # the WorldObject as it stood where the store should know it
    gone: bool = False  # reported gone by the observable truth and not found since


@dataclass
class ObservableTruth:
    """Per day (index 0 = day 1): object -> "moved" / "gone" / "new", and per day the objects' photographable s."""

    days: list[dict[str, str]] = field(default_factory=list)
    seen_s: list[dict[str, float]] = field(default_factory=list)


def observable_truth(truth: dict, worlds: list, cams: list[np.ndarray], rule: str = "read") -> ObservableTruth:
    """The observable truth (module docstring) of ``days.json``'s ``truth``, with ``worlds`` each day's home
    (``holoslam.sim.days.household_days``) and ``cams`` each day's camera centres (``camera_positions``); ``rule``
    "read" (the goal's: a label observable when the day's images read it) or "photographable" (the rule before:
    also when it was photographable from a pose of the day)."""
    if rule not in ("read", "photographable"):
        raise ValueError(f"rule must be read or photographable, got {rule!r}")
    first = set(truth["days"][0]["objects"])
    known: dict[str, _Known] = {}
    out = ObservableTruth()
    for k, (d, world, cam) in enumerate(zip(truth["days"], worlds, cams, strict=True)):
        read = set(d.get("photographed", ()))
        here = {o.object_id: o for o in world.objects}
        secs = {oid: photographable_s(world, o, cam) for oid, o in here.items()}
        out.seen_s.append(secs)
        if rule == "photographable":
            observable = {oid for oid, s in secs.items() if s >= MIN_VIEW_S or oid in read}
        else:  # read in the day's images: the simulator's record (``image_reads`` gives the same)
            observable = read & set(here)
        if k == 0:
            known = {oid: _Known(here[oid]) for oid in observable}
            out.days.append({})
            continue
        day: dict[str, str] = {}
        for oid in sorted(set(here) | set(known)):
            o, kn = here.get(oid), known.get(oid)
            if o is not None and oid in observable:
                if kn is None:
                    if oid not in first:
                        day[oid] = "new"
                elif math.dist(o.position[:2], kn.obj.position[:2]) > MOVED_M:  # type: ignore[attr-defined]
                    day[oid] = "moved"
                known[oid] = _Known(o)
            elif kn is not None and not kn.gone and (
                    o is None or math.dist(o.position[:2], kn.obj.position[:2]) > MOVED_M):  # type: ignore[attr-defined]
                if photographable_s(world, kn.obj, cam) >= MIN_VIEW_S:  # the place in view (both rules)
                    day[oid] = "gone"
                    kn.gone = True
        out.days.append(day)
    return out


def raw_truth(day: dict) -> dict[str, str]:
    """A day's changes as the simulator made them: object -> "moved" / "gone" / "new"."""
    return {c["id"]: RAW_KINDS[c["change"]] for c in day["changes"]}


def score(truth_days: list[dict[str, str]], detected_days: list[dict[str, str]]) -> dict[str, tuple[int, int, int]]:
    """Per kind (moved, gone, new): (true positives, detected, true) summed over the days (the detection a day's
    status of an object, the same kind on the same day)."""
    out = {}
    for k in RAW_KINDS.values():
        tp = nd = nt = 0
        for tru, det in zip(truth_days, detected_days, strict=True):
            tp += sum(1 for o, v in det.items() if v == k and tru.get(o) == k)
            nd += sum(1 for v in det.values() if v == k)
            nt += sum(1 for v in tru.values() if v == k)
        out[k] = (tp, nd, nt)
    return out


def format_scores(title: str, counts: dict[str, tuple[int, int, int]]) -> str:
    """Lines of precision / recall per kind (nan when nothing was detected or true)."""
    rows = [f"{title}\n  kind    precision  recall  (correct / detected / true)"]
    for k, (tp, nd, nt) in counts.items():
        rows.append(f"  {k:<6} {tp / nd if nd else float('nan'):10.3f} {tp / nt if nt else float('nan'):7.3f}  "
                    f"({tp} / {nd} / {nt})")
    return "\n".join(rows)


def rescore(out: Path) -> None:
    """Both scores of a finished ``--parts sim`` run from its folder (``sim/days.json``, ``sim/sim_detail.json``
    and the day logs), e.g. one run before this module existed."""
    import json

    from holoslam.sim.days import household_days

    sim = out / "sim" if (out / "sim").is_dir() else out
    truth = json.loads((sim / "days.json").read_text())
    detail = json.loads((sim / "sim_detail.json").read_text())
    worlds = [d.world for d in household_days(len(truth["days"]), truth["seed"], tuple(truth.get("changes", (5, 10))),
                                              tuple(truth.get("furniture_moves", (0, 0))))]
    cams = [camera_positions(sim / d["log"]) for d in truth["days"]]
    obs = observable_truth(truth, worlds, cams)
    det = [x["detected"] for x in detail]
    n = len(det)
    print(format_scores("observable truth (the goal: labels read in the day's images)", score(obs.days[:n], det)))
    print(format_scores("photographable truth (the rule before: labels the day's poses could have photographed)",
                        score(observable_truth(truth, worlds, cams, "photographable").days[:n], det)))
    print(format_scores("raw simulator truth", score([raw_truth(d) for d in truth["days"][:n]], det)))
    for k in range(1, n):
        diff = {o: (raw_truth(truth["days"][k]).get(o), v) for o, v in obs.days[k].items()
                if raw_truth(truth["days"][k]).get(o) != v}
        diff.update({o: (v, None) for o, v in raw_truth(truth["days"][k]).items() if o not in obs.days[k]})
        if diff:
            print(f"  day {k + 1}: raw -> observable " + ", ".join(f"{o} {a} -> {b}" for o, (a, b) in sorted(diff.items())))


if __name__ == "__main__":
    import sys

    rescore(Path(sys.argv[1]))
