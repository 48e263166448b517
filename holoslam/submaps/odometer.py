"""How far the wheel odometer is off, measured against the scan-matched trajectory: a check of the odometer's
calibration, in the run report beside the laser mounting check (:mod:`holoslam.submaps.mounting`).

A wheel odometer's systematic errors are a distance scale (a wheel radius or ticks per metre mis-set: every
metre measured as ``scale`` metres) and a heading drift on straight motion (two wheels of slightly different
radius: the odometer turns a fixed angle per metre driven). Between the scan-matched keyframes of a run (a
few centimetres off the truth on the shared real logs, far better than the wheels) both show on straight
stretches: the odometry's chord over the scans' chord, and the odometry's heading change minus the scans' per
metre. Each stretch is ``STRETCH_M`` of the scans' path that turns at most ``STRAIGHT_DEG`` and whose chord is at
least ``CHORD_SHARE`` of it (no back and forth); the medians
over the stretches (a few wrong matches or slips do not move them), with standard errors from the spread.

Measured on the shared real logs (``holoslam run``, its trajectory at the scans against the raw odometry; 23 /
113 / 62 stretches): intel +3.4 % and -3.5 deg/m, aces +1.0 % and +0.2 deg/m, fr079 -0.7 % and -0.9 deg/m (the
same within 0.3 % and 0.3 deg/m with 3 m stretches or 10 deg): real odometers are off by percents and degrees
per metre (``holoslam.derive.bias_odometry``'s 5 % and 0.5 deg/m in ``benchmarks/bench_realdata.py``
are within what they show).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from holoslam.geometry import compose, interpolate_poses, wrap

__all__ = ["OdometerBias", "odometer_bias", "odometer_text", "OdometerCorrectionConfig", "OdometerCorrection",
           "odometer_correction", "is_blind", "OdometerWatch", "STRETCH_M", "STRAIGHT_DEG", "CHORD_SHARE", "MAX_STEP_M",
           "MIN_STRETCHES", "WARN_SCALE", "WARN_DEG_PER_M"]

# m of the scans' path per stretch: long enough that a keyframe's centimetre of error is ~0.5 % of it, short
# enough that a robot drives that far straight often (the shared logs: 23 / 113 / 62 straight 2 m stretches,
# 8 / 66 / 35 of 3 m, intel's then at MIN_STRETCHES; the same readings within 0.3 % and 0.3 deg/m either way)
STRETCH_M = 2.0
# deg: a stretch is straight when the scans turn at most this much along it (a turning error of a few percent,
# the other systematic error of an odometer, then adds < 0.2 deg per metre to the heading drift)
STRAIGHT_DEG = 15.0
# and when its chord is at least this share of its path (no back and forth)
CHORD_SHARE = 0.9
# m: a stretch with a step between consecutive keyframes longer than this is left out (a break of local SLAM or
# a carried robot: the keyframes on either side are not one continuous scan-matched motion)
MAX_STEP_M = 1.0
# straight stretches needed for a measurement
MIN_STRETCHES = 8
# the report flags a scale this far from 1 (and three standard errors): 2 % is 2 cm per metre, the shared
# logs' relation errors over a metre; and a heading drift of this many deg per metre (0.5 deg/m: 4 mm sideways
# after a metre, 0.44 m after 10 m driven straight)
WARN_SCALE = 0.02
WARN_DEG_PER_M = 0.5


@dataclass(frozen=True)
class OdometerBias:
    """The odometer against the scans on straight stretches: ``scale`` the odometry's distance per metre of
    the scans' (1 = right), ``yaw_deg_per_m`` the odometry's heading change minus the scans' per metre driven
    (+ = the odometer turns left of the robot), each with its standard error; ``stretches`` straight stretches
    over ``distance_m`` metres."""

    scale: float
    scale_std: float
    yaw_deg_per_m: float
    yaw_std: float
    stretches: int
    distance_m: float

    @property
    def off(self) -> bool:
        """The odometer is measurably off (``WARN_SCALE`` or ``WARN_DEG_PER_M``, and three standard errors)."""
        s = abs(self.scale - 1.0)
        y = abs(self.yaw_deg_per_m)
        return bool((s > WARN_SCALE and s > 3 * self.scale_std) or (y > WARN_DEG_PER_M and y > 3 * self.yaw_std))

    def to_dict(self) -> dict[str, float | int | bool]:
        return {"scale": round(self.scale, 4), "scale_std": round(self.scale_std, 4),
                "yaw_deg_per_m": round(self.yaw_deg_per_m, 3), "yaw_std": round(self.yaw_std, 3),
                "stretches": self.stretches, "distance_m": round(self.distance_m, 1), "off": self.off}


def _median_and_error(v: np.ndarray) -> tuple[float, float]:
    """The median and its standard error (1.2533 sigma / sqrt(n), sigma from the median absolute deviation)."""
    m = float(np.median(v))
    sigma = 1.4826 * float(np.median(np.abs(v - m)))
    return m, float(1.2533 * sigma / np.sqrt(v.size))


def odometer_bias(key_stamps_ns: np.ndarray, wTk: np.ndarray, odom_stamps_ns: np.ndarray, odomTb: np.ndarray,
                  stretch_m: float = STRETCH_M, straight_deg: float = STRAIGHT_DEG,
                  blind: np.ndarray | None = None) -> OdometerBias | None:
    """The odometer's scale and heading drift from scan-matched keyframe poses ``wTk`` (K, 3) at sorted
    ``key_stamps_ns`` and the raw odometry ``odomTb`` (N, 3) at sorted ``odom_stamps_ns``; None when the run
    has fewer than ``MIN_STRETCHES`` straight stretches. ``blind`` (K,) bool: the keyframes whose scan match was
    blind along the track (``is_blind``): a stretch holding one is left out, for there the keyframes follow the
    odometer and read it as right. The simulated building's odometer 6.6 % long (``bench_building_slam.py
    --no-compass --odometer 1.05 0.5``, seed 26, local SLAM's nodes placed by the loop-closed estimate): +6.1 % at a
    tenth of the run and +6.1 % at 90 % over all stretches, +6.65 % and +6.67 % over those without a blind match;
    4.0 % long (seed 28 at 1.025): +3.3 % and +3.9 % against +4.1 % and +4.2 %."""
    key = np.asarray(key_stamps_ns, np.int64)
    wTk = np.asarray(wTk, np.float64).reshape(-1, 3)
    if key.size < 2 or np.size(odom_stamps_ns) < 2:
        return None
    odo = interpolate_poses(np.asarray(odom_stamps_ns, np.int64), odomTb, key)
    step = np.hypot(*np.diff(wTk[:, :2], axis=0).T)
    path = np.concatenate([[0.0], np.cumsum(step)])
    # stretch boundaries: the first keyframe at or beyond each multiple of stretch_m along the path
    cuts = np.unique(np.searchsorted(path, np.arange(0.0, path[-1] + 1e-9, stretch_m)))
    a, b = cuts[:-1], cuts[1:]
    length = path[b] - path[a]
    chord = np.hypot(*(wTk[b, :2] - wTk[a, :2]).T)
    longest = np.maximum.reduceat(step, a) if a.size else np.zeros(0)
    # heading along the path, unwrapped step by step (no keyframe step turns half a turn)
    dk = np.concatenate([[0.0], np.cumsum(wrap(np.diff(wTk[:, 2])))])
    do = np.concatenate([[0.0], np.cumsum(wrap(np.diff(odo[:, 2])))])
    ok = ((length >= 0.8 * stretch_m) & (chord >= CHORD_SHARE * length) & (longest <= MAX_STEP_M)
          & (np.abs(dk[b] - dk[a]) <= np.radians(straight_deg)))
    if blind is not None:  # stretches holding a keyframe whose match was blind along the track are left out
        blind_before = np.concatenate([[0], np.cumsum(np.asarray(blind, bool))])
        ok &= blind_before[b + 1] == blind_before[a]
    if int(ok.sum()) < MIN_STRETCHES:
        return None
    a, b, chord = a[ok], b[ok], chord[ok]
    odo_chord = np.hypot(*(odo[b, :2] - odo[a, :2]).T)
    yaw = np.degrees((do[b] - do[a]) - (dk[b] - dk[a])) / chord
    scale, scale_std = _median_and_error(odo_chord / chord)
    drift, drift_std = _median_and_error(yaw)
    return OdometerBias(scale, scale_std, drift, drift_std, int(ok.sum()), float(chord.sum()))


def _measures(m: Mapping[str, Any]) -> str:
    pct = 100.0 * (m["scale"] - 1.0)
    y = m["yaw_deg_per_m"]
    return (f"{abs(pct):.1f} % {'long' if pct >= 0 else 'short'} (+/- {100 * m['scale_std']:.1f} %) and turns "
            f"{abs(y):.2f} deg per metre to the {'left' if y >= 0 else 'right'} (+/- {m['yaw_std']:.2f})")


def odometer_text(m: Mapping[str, Any]) -> list[str]:
    """The run report's lines of an odometer check (``OdometerBias.to_dict``, with the front end's correction
    under ``corrected``: ``OdometerCorrection.to_dict``)."""
    lines = []
    if "scale" in m:
        lines.append(f"  odometer: on {m['stretches']} straight stretches ({m['distance_m']:.0f} m) its raw odometry "
                     f"measures {_measures(m)} against the scans")
        if m["off"]:
            lines.append("    the odometer is off by more than a wheel calibration allows (2 %, 0.5 deg/m): check "
                         "the wheel radii and track width of its driver; the scans carry the map, but where they "
                         "cannot see motion (a long bare corridor) the map follows the odometer")
    c = m.get("corrected")
    if c:
        who = (f"local SLAM's check at matched node {c['nodes']} found it" if c.get("nodes")
               else "a first pass found it")
        lines.append(f"    corrected: {who} {_measures(c)} on {c['stretches']} straight stretches, with "
                     f"{100 * c['blind_share']:.0f} % of its scan matches blind along the track (there the map "
                     "follows the odometer); the run mapped again with the odometry corrected by as much")
    return lines


# ------------------------------------------------------------------------------------ the correction


@dataclass(frozen=True)
class OdometerCorrectionConfig:
    """When a run maps a second time on corrected odometry (``odometer_correction``): after the first pass the
    odometer check (its raw odometry against the solved keyframes, ``odometer_bias``) finds its distance scale
    off by more than ``min_scale_error`` and three standard errors over ``min_stretches`` straight stretches,
    and local SLAM's scans were blind along the track often enough for the map to have followed the odometer:
    ``blind_share`` of the matched nodes, each one's score surface a ridge (its position standard deviation
    along one direction ``blind_ratio`` times that across, ``is_blind``).

    Why after a whole pass: along a bare corridor local SLAM follows the odometer, so its own poses read an
    odometer 6 % long as right (the simulated building: +0.8 % against +6.1 % found after the loops are closed);
    the solved keyframes, closed into loops, read it, on the stretches without a blind match (over all
    stretches they read +6.1 %: the blind ones still follow the odometer). Why the scale only: a corridor's walls
    fix the heading (the scans see a heading drift), not the position along it; once a pass is called for the
    drift is corrected with the scale. Why 3 %: on the simulated 350 m building without its compass (``bench_building_slam.py``, seeds 26
    / 27 / 28) a first pass reading +2.1 % mapped no better corrected (revisits 0.156 / 3.22 / 0.119 m -> 0.068 /
    5.66 / 0.281, anchors of 26 and 28 0.571 / 0.246 -> 0.975 / 0.626 m, relations 5-30 s apart 0.069-0.074 ->
    0.071-0.080 m), one reading +3.8-3.9 % better (relations 5-30 s apart 0.108-0.149 -> 0.067-0.076 m, runs with
    revisits over 1 m off 2 -> 1 of 3), and one reading +5.9-6.2 % much better (0.137-0.160 -> 0.064-0.067 m). Why the gate: where the scans see motion every
    way the odometer is only the matcher's prior: on the shared real logs correcting it (intel +3.1 % and
    -3.4 deg/m) moves their error within what a 0.2 % change of the odometer moves it anyway (intel 0.0186 m at
    the laser; corrected 0.0207; scaled 1.002 / 0.998: 0.0205 / 0.0192); there 0-1.7 % of the matches are
    ridges (aces decimated to 1.4 Hz with half its beams: 4.8-5.3 %, its odometer within 1 %), in the building
    9-18 %."""

    enabled: bool = True
    # straight stretches (``STRETCH_M``) of the first pass: with 20 the medians' standard errors are ~0.3 % and
    # ~0.1 deg/m on the shared logs, a tenth of what a correction is for
    min_stretches: int = 20
    # the distance scale's error (fraction) that calls for a second pass, beside three standard errors
    min_scale_error: float = 0.03
    blind_ratio: float = 5.0  # a match is blind along the track when its sd along one direction is this x across
    # matched nodes between the checks local SLAM makes while it runs (``OdometerWatch``): on the building the
    # check (its stretches without a blind match) reads the odometer's scale from a tenth of the log on (+6.65 %
    # at 10 %, +6.67 % at 90 %; truth +6.6 %)
    check_every_nodes: int = 500
    blind_share: float = 0.05  # the share of matched nodes that must be blind (the shared real logs: 0-5.3 %)

    def open_for(self, blind_share: float) -> bool:
        """Whether a run whose matches were blind along the track at ``blind_share`` may be corrected at all."""
        return self.enabled and blind_share >= self.blind_share

    def __post_init__(self) -> None:
        if self.min_stretches < MIN_STRETCHES:
            raise ValueError(f"odometer.min_stretches must be >= {MIN_STRETCHES}, got {self.min_stretches}")
        if not (self.blind_ratio > 1.0 and 0.0 <= self.blind_share <= 1.0 and self.min_scale_error >= 0.0
                and self.check_every_nodes >= 1):
            raise ValueError("odometer: blind_ratio must be > 1, blind_share in [0, 1], min_scale_error >= 0 and "
                             f"check_every_nodes >= 1; got {self.blind_ratio}, {self.blind_share}, "
                             f"{self.min_scale_error}, {self.check_every_nodes}")


def is_blind(cov_aTb: np.ndarray, ratio: float) -> bool:
    """A match's covariance (3x3, x y yaw) is a ridge: its position sd along one direction over ``ratio`` x
    that across (a corridor's scan fixes the position across it, not along it)."""
    ev = np.linalg.eigvalsh(np.asarray(cov_aTb, np.float64)[:2, :2])
    return bool(ev[1] > ratio * ratio * max(float(ev[0]), 1e-12))


@dataclass(frozen=True)
class OdometerCorrection:
    """The odometer's bias a first pass found (``bias``: the raw odometry against its solved keyframes), with
    ``blind_share`` of its matched nodes blind along the track; the run mapped again on ``apply(log)``."""

    bias: OdometerBias
    blind_share: float
    nodes: int = 0  # local SLAM's matched nodes when its check found it (``OdometerWatch``); 0: after a whole pass

    def apply(self, log: Any) -> Any:
        """``log`` with its odometry corrected: each step's distance divided by the scale, the drift per metre
        taken off its heading (``holoslam.derive.bias_odometry``, the inverse of the bias found)."""
        from holoslam.derive import bias_odometry

        return bias_odometry(log, 1.0 / self.bias.scale, -self.bias.yaw_deg_per_m)

    def to_dict(self) -> dict[str, Any]:
        return {**self.bias.to_dict(), "blind_share": round(self.blind_share, 3), "nodes": self.nodes}

    def notice(self) -> str:
        """One line for the run's progress: why the front end maps again."""
        b = self.bias
        return (f"the odometer measures {100 * (b.scale - 1):+.1f} % and {b.yaw_deg_per_m:+.2f} deg/m against the "
                f"scans, {100 * self.blind_share:.0f} % of them blind along the track: mapping again on the "
                "corrected odometry")


def odometer_correction(bias: OdometerBias | None, blind_share: float, cfg: OdometerCorrectionConfig,
                        nodes: int = 0) -> OdometerCorrection | None:
    """The correction a first pass calls for (``OdometerCorrectionConfig``), or None: the distance scale off by
    more than ``min_scale_error`` and three standard errors. A heading drift alone calls for none: a corridor's walls
    fix the heading (the scans see it), not the position along it; once a pass is called for, the drift is
    corrected with the scale."""
    if not cfg.open_for(blind_share) or bias is None or bias.stretches < cfg.min_stretches:
        return None
    off = abs(bias.scale - 1.0)
    if off > cfg.min_scale_error and off > 3 * bias.scale_std:
        return OdometerCorrection(bias, blind_share, nodes)
    return None


class OdometerWatch:
    """The check while the first pass runs, so that a run need not finish it to find the odometer off: local
    SLAM's matched nodes (stamp, submap, pose in it, blind or not), placed every ``check_every_nodes`` by the
    anchors' current estimate (the loop closures so far in) and checked against the raw odometry
    (``odom_stamps_ns``, ``odomTb``); ``check`` returns the correction once one is called for
    (``odometer_correction``) and the front end starts again on corrected odometry. Where the loops come late the
    estimate still follows the odometer, the check reads it as right, and the run's end decides
    (``holoslam.optimise.odometer_pass``)."""

    def __init__(self, cfg: OdometerCorrectionConfig, odom_stamps_ns: np.ndarray, odomTb: np.ndarray) -> None:
        self.cfg = cfg
        self._odo = (np.asarray(odom_stamps_ns, np.int64), np.asarray(odomTb, np.float64))
        self._stamps: list[int] = []
        self._submaps: list[int] = []
        self._aTb: list[np.ndarray] = []
        self._blind: list[bool] = []
        self.nodes = 0
        self._blind_nodes = 0  # sum(self._blind), kept: the front end reads the share at every node

    @property
    def blind_share(self) -> float:
        return self._blind_nodes / max(self.nodes, 1)

    @property
    def blind_stamps_ns(self) -> np.ndarray:
        """The stamps of the matched nodes whose match was blind along the track."""
        return np.array(self._stamps, np.int64)[np.array(self._blind, bool)] if self._stamps else np.zeros(0, np.int64)

    def add(self, stamp_ns: int, submap: int, aTb: np.ndarray, blind: bool) -> bool:
        """One matched node; True when a check is due."""
        self._stamps.append(int(stamp_ns))
        self._submaps.append(int(submap))
        self._aTb.append(np.asarray(aTb, np.float64))
        self._blind.append(bool(blind))
        self.nodes += 1
        self._blind_nodes += bool(blind)
        return self.cfg.enabled and self.nodes % self.cfg.check_every_nodes == 0

    def check(self, est_wTa: np.ndarray) -> OdometerCorrection | None:
        """The correction the nodes so far call for, placed by the anchors' estimate ``est_wTa`` (N, 3)."""
        if not self.cfg.open_for(self.blind_share):
            return None
        sub = np.array(self._submaps, np.int64)
        known = sub < len(est_wTa)  # a node of a submap whose anchor is not in the graph yet waits
        wTb = compose(np.asarray(est_wTa, np.float64)[sub[known]], np.array(self._aTb)[known])
        bias = odometer_bias(np.array(self._stamps, np.int64)[known], wTb, *self._odo,
                             blind=np.array(self._blind, bool)[known])
        return odometer_correction(bias, self.blind_share, self.cfg, self.nodes)
