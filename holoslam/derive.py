"""Harder logs derived from a real one: fewer scans, fewer beams, shorter ranges, and a kidnapped robot.

Real scans beat any simulator, so the hard cases of the loop search (a sparse, slow laser on a large building;
a robot carried away with its wheels turning; a session started where the map does not know it) are made from the
shared real logs by taking information away, never by inventing any. Each function takes a
:class:`holoslam.types.LogData` and returns a new one; nothing else of the log changes, so every stamp of the
original's ground truth (``.relations``) still names the same scan.

- :func:`decimate_scans`: keep scans at most ``rate_hz``, the first of each period (the Freiburg hospital log's
  laser runs at 1.4 Hz where intel's runs at 5 Hz);
- :func:`drop_beams`: keep every k-th beam of every scan (180 beams over 180 degrees -> 90);
- :func:`cap_ranges`: returns beyond ``max_range_m`` become no-returns (a cheaper laser);
- :func:`drop_returns`: each return becomes a no-return with a given probability, drawn from a seeded generator
  (a laser that misses dark and shiny surfaces: the Freiburg hospital log's leaves 12 % of its beams without one);
- :func:`kidnap`: from stamp ``at_ns`` on, the odometry (and the odometry frame's transforms) is moved by a
  rigid transform the mapper is not told about, and the scans of the ``gap_s`` after it are removed, so the
  two parts of the log share no scan that would let the local matcher bridge them: only a global search can;
- :func:`bias_odometry`: the odometer's motions scaled and turned by a fixed bias per metre (a worn or mis-sized
  wheel: its distance a few per cent off, its heading drifting with the distance), the error that grows along a
  corridor where the laser cannot see motion along it;
- :func:`repeat`: the log driven ``times`` times, the robot carried back to its start between copies with its
  laser on and its odometer counting on from where it stopped (a second apart: no gap in the laser to tell).
  Its stamps are new, the copy ``k``'s stamps being the original's plus ``k`` times :func:`repeat_span_ns`.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from holoslam import geometry as g
from holoslam.types import LogData, Odometry, Pose2, Scan

__all__ = ["decimate_scans", "drop_beams", "cap_ranges", "drop_returns", "kidnap", "bias_odometry", "repeat", "repeat_span_ns"]


def decimate_scans(log: LogData, rate_hz: float) -> LogData:
    """The log with scans at most ``rate_hz``: a scan is kept when at least 1/rate_hz has passed since the last
    kept one (the first is kept)."""
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"decimate_scans: rate_hz must be a finite number > 0, got {rate_hz}")
    period = int(round(1e9 / rate_hz))
    kept: list[Scan] = []
    for s in log.scans:
        if not kept or s.stamp_ns - kept[-1].stamp_ns >= period:
            kept.append(s)
    return replace(log, scans=tuple(kept))


def drop_beams(log: LogData, keep_every: int) -> LogData:
    """The log with every ``keep_every``-th beam of each scan (the first beam kept; the angular step grows
    by that factor)."""
    if keep_every < 1:
        raise ValueError(f"drop_beams: keep_every must be >= 1, got {keep_every}")
    scans = tuple(replace(s, ranges=s.ranges[::keep_every], valid=s.valid[::keep_every],
                          angle_increment=s.angle_increment * keep_every) for s in log.scans)
    return replace(log, scans=scans)


def cap_ranges(log: LogData, max_range_m: float) -> LogData:
    """The log with every return beyond ``max_range_m`` made a no-return (its beam invalid)."""
    if not (math.isfinite(max_range_m) and max_range_m > 0):
        raise ValueError(f"cap_ranges: max_range_m must be a finite number > 0, got {max_range_m}")
    scans = tuple(replace(s, valid=s.valid & (s.ranges <= max_range_m), range_max=min(s.range_max, max_range_m))
                  for s in log.scans)
    return replace(log, scans=scans)


def drop_returns(log: LogData, fraction: float, seed: int = 0) -> LogData:
    """The log with each return made a no-return (its beam invalid) with probability ``fraction``, independently,
    from ``numpy.random.default_rng(seed)`` drawn scan by scan in the log's order (the same log and seed: the same
    holes)."""
    if not (math.isfinite(fraction) and 0.0 <= fraction <= 1.0):
        raise ValueError(f"drop_returns: fraction must be a number in [0, 1], got {fraction}")
    rng = np.random.default_rng(seed)
    scans = tuple(replace(s, valid=s.valid & (rng.random(s.valid.shape) >= fraction)) for s in log.scans)
    return replace(log, scans=scans)


def kidnap(log: LogData, at_ns: int, jump: np.ndarray, gap_s: float = 30.0) -> LogData:
    """The log with the robot kidnapped at ``at_ns``: every odometry pose from then on is ``jump`` ∘ odomTb
    (``jump`` = (x, y, theta) in the odometry frame: the odometer believes the robot was carried by it), the
    dynamic transforms from the odometry frame likewise, and the scans in [at_ns, at_ns + gap_s) removed. The
    compass is left as it is (it measures the true heading). Ground truth, images and tags are unchanged."""
    jump = np.asarray(jump, np.float64).reshape(3)
    if not np.all(np.isfinite(jump)):
        raise ValueError(f"kidnap: jump must be finite (x, y, theta), got {jump}")
    if not (math.isfinite(gap_s) and gap_s >= 0):
        raise ValueError(f"kidnap: gap_s must be a finite number >= 0, got {gap_s}")
    odo: list[Odometry] = []
    for o in log.odometry:
        if o.stamp_ns >= at_ns:
            x, y, th = g.compose(jump, o.odomTb.as_array())
            cov = o.cov_odomTb
            if cov is not None:  # the covariance is in the odometry frame's axes: rotate it with the jump
                R = np.eye(3)
                R[:2, :2] = [[math.cos(jump[2]), -math.sin(jump[2])], [math.sin(jump[2]), math.cos(jump[2])]]
                cov = R @ cov @ R.T
            o = replace(o, odomTb=Pose2(float(x), float(y), float(th)), cov_odomTb=cov)
        odo.append(o)
    odom_frames = {o.frame_id for o in log.odometry}
    transforms = tuple(_moved_transform(t, jump) if (not t.static and t.parent in odom_frames
                                                     and t.stamp_ns >= at_ns) else t for t in log.transforms)
    gap_end = at_ns + int(round(gap_s * 1e9))
    scans = tuple(s for s in log.scans if not at_ns <= s.stamp_ns < gap_end)
    return replace(log, odometry=tuple(odo), transforms=transforms, scans=scans)


def bias_odometry(log: LogData, scale: float, yaw_deg_per_m: float) -> LogData:
    """The log with a biased odometer: each odometry step (the motion between two odometry poses, in the
    earlier pose's frame) has its translation times ``scale`` and its rotation plus ``yaw_deg_per_m`` per metre of
    the (scaled) step, integrated from the first pose; the dynamic transforms from the odometry frame are moved
    with the pose at their stamp. Scans, compass, ground truth and the rest are unchanged (the compass, if any,
    keeps measuring the true heading)."""
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"bias_odometry: scale must be a finite number > 0, got {scale}")
    if not math.isfinite(yaw_deg_per_m):
        raise ValueError(f"bias_odometry: yaw_deg_per_m must be finite, got {yaw_deg_per_m}")
    if not log.odometry:
        return log
    P = np.array([o.odomTb.as_array() for o in log.odometry], np.float64)
    steps = g.between(P[:-1], P[1:])
    steps[:, :2] *= scale
    steps[:, 2] += math.radians(yaw_deg_per_m) * np.hypot(steps[:, 0], steps[:, 1])
    # integrated from the first pose: step k turns by the headings before it
    th = P[0, 2] + np.concatenate([[0.0], np.cumsum(steps[:, 2])])
    c, s = np.cos(th[:-1]), np.sin(th[:-1])
    xy = P[0, :2] + np.concatenate([[[0.0, 0.0]], np.cumsum(np.stack([c * steps[:, 0] - s * steps[:, 1],
                                                                         s * steps[:, 0] + c * steps[:, 1]], 1), 0)])
    Q = np.column_stack([xy, g.wrap(th)])
    odo = tuple(replace(o, odomTb=Pose2(float(q[0]), float(q[1]), float(q[2])))
                for o, q in zip(log.odometry, Q, strict=True))
    stamps = np.array([o.stamp_ns for o in log.odometry], np.int64)
    corr = g.compose(Q, g.inverse(P))  # biased ∘ true^-1 at each odometry stamp: how far the odometer has moved
    odom_frames = {o.frame_id for o in log.odometry}

    def moved(t):
        if t.static or t.parent not in odom_frames:
            return t
        k = max(0, int(np.searchsorted(stamps, t.stamp_ns, side="right")) - 1)
        return _moved_transform(t, corr[k])

    return replace(log, odometry=odo, transforms=tuple(moved(t) for t in log.transforms))


def _moved_transform(t, jump: np.ndarray):
    """A planar jump ∘ parentTchild for a 3D transform (z and the tilt kept)."""
    c, s = math.cos(jump[2]), math.sin(jump[2])
    x, y, z = t.translation
    qx, qy, qz, qw = t.rotation_xyzw
    hc, hs = math.cos(jump[2] / 2), math.sin(jump[2] / 2)  # q_jump = (0, 0, hs, hc); q' = q_jump * q
    q = (hc * qx - hs * qy, hc * qy + hs * qx, hc * qz + hs * qw, hc * qw - hs * qz)
    return replace(t, translation=(jump[0] + c * x - s * y, jump[1] + s * x + c * y, z), rotation_xyzw=q)


def repeat_span_ns(log: LogData) -> int:
    """ns between a scan of one copy of :func:`repeat` and the same scan of the next: the scans' span plus 1 s."""
    if not log.scans:
        raise ValueError("repeat: the log has no scans")
    return int(log.scans[-1].stamp_ns - log.scans[0].stamp_ns) + 1_000_000_000


def repeat(log: LogData, times: int) -> LogData:
    """The log's odometry, scans and headings played ``times`` times end to end, each copy a
    :func:`repeat_span_ns` after the last: the robot carried back to where it started with its laser on, the
    odometer going on from where it stopped (each copy's odometry composed onto the last pose of the copy before),
    the compass as it was (it measures the true heading), the ground truth as it was too (the robot drives the
    same path again, so each copy's accuracy is scored). Images, tags and transforms are the first copy's only."""
    if not (isinstance(times, int) and times >= 1):
        raise ValueError(f"repeat: times must be an integer >= 1, got {times!r}")
    if not log.odometry:
        raise ValueError("repeat: the log has no odometry")
    span = repeat_span_ns(log)
    odo, scans, heads, truth = list(log.odometry), list(log.scans), list(log.headings), list(log.ground_truth)
    o_first = log.odometry[0].odomTb.as_array()
    for k in range(1, times):
        T = g.compose(odo[-1].odomTb.as_array(), g.inverse(o_first))
        odo += [replace(o, stamp_ns=o.stamp_ns + k * span, odomTb=Pose2.from_array(g.compose(T, o.odomTb.as_array())))
                for o in log.odometry]
        scans += _later(log.scans, k * span)
        heads += _later(log.headings, k * span)
        truth += _later(log.ground_truth, k * span)
    return replace(log, odometry=tuple(odo), scans=tuple(scans), headings=tuple(heads), ground_truth=tuple(truth))


def _later(records, dt_ns: int) -> list:
    """The stamped records (frozen dataclasses with ``stamp_ns``) ``dt_ns`` later."""
    return [replace(r, stamp_ns=r.stamp_ns + dt_ns) for r in records]
