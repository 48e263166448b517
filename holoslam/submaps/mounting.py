"""Where the laser sits on the robot, measured from how the robot moves: a check of the log's laser transform.

A wheeled robot (differential drive, skid steer, synchro drive) cannot move sideways: the point it turns about
travels along its own heading, so between two scans it moves on an arc whose chord leans by half the turn.
A laser mounted ``a`` metres ahead of that point moves sideways by ``2 a tan(dtheta / 2)`` more than the arc
allows. With the scan-matched laser poses (a few millimetres apart, far better than the wheels), the lateral
residuals of thousands of scan-to-scan motions pin ``a`` down to millimetres (a least-squares line through
the origin, Huber weights against the few bad matches; its standard error robust to correlation within ten
blocks of the log). A
sideways offset of the laser is not observable this way (a point beside the centre also moves along the
heading), so only the position along the robot's x axis is measured.

Measured on the shared real logs (laser at ``a`` from the turning centre; standard error): intel +0.092 ±
0.001 m and aces +0.055 ± 0.002 m (their tf puts base_link at the laser), fr079 -0.018 ± 0.001 m, where the
log's tf says the laser is 0.04 m *ahead* of base_link. That log's ground-truth relations agree with the motion,
not the tf: scored at the turning centre its trajectory errs 0.034 m, at the tf's base_link 0.066 m.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from holoslam.geometry import compose, wrap

__all__ = ["Mounting", "laser_ahead_of_turning_centre", "mounting_check", "mounting_text", "MAX_TURN_RAD", "MAX_GAP_NS", "MIN_TURNS", "WARN_M"]

# rad: scan-to-scan motions turning more than this are left out (tan(dtheta / 2) is far from linear and a
# wrong match more likely); 0.5 rad between two scans is 2.5 rad/s at 5 Hz, faster than indoor robots turn
MAX_TURN_RAD = 0.5
# ns: scan pairs further apart than this are left out (a gap in the log, where the arc model does not hold)
MAX_GAP_NS = 500_000_000
# scan pairs turning at least 1 deg needed for a measurement; fewer is a robot that barely turned
MIN_TURNS = 50
MIN_TURN_RAD = np.radians(1.0)
# m: the report flags a base frame this far from the turning centre along the robot's x axis: a base frame off
# by L adds up to 2 L to the relative translation of two poses a half turn apart (fr079: 0.058 m off, +0.032 m
# on the mean relation error); 2 cm is ten times the standard error measured on the real logs
WARN_M = 0.02
_BLOCKS = 10


@dataclass(frozen=True)
class Mounting:
    """The laser's position along the robot's x axis from the point the robot turns about (``laser_x_m``, + ahead,
    with its standard error), against where the log's transform puts it relative to base_link (``tf_laser_x_m``).
    ``centre_in_base_x_m`` is where the turning centre lies in base_link by that transform."""

    laser_x_m: float
    laser_x_std_m: float
    pairs: int  # scan-to-scan motions used
    turns: int  # of which turning at least MIN_TURN_RAD
    tf_laser_x_m: float

    @property
    def centre_in_base_x_m(self) -> float:
        return self.tf_laser_x_m - self.laser_x_m

    @property
    def base_off_centre(self) -> bool:
        """base_link lies measurably (``WARN_M`` and three standard errors) off the point the robot turns about."""
        off = abs(self.centre_in_base_x_m)
        return off > WARN_M and off > 3.0 * self.laser_x_std_m

    def to_dict(self) -> dict[str, float | int | bool]:
        return {"laser_x_m": round(self.laser_x_m, 4), "laser_x_std_m": round(self.laser_x_std_m, 4),
                "pairs": self.pairs, "turns": self.turns, "tf_laser_x_m": round(self.tf_laser_x_m, 4),
                "centre_in_base_x_m": round(self.centre_in_base_x_m, 4), "base_off_centre": self.base_off_centre}


def _fit(w: np.ndarray, b: np.ndarray) -> tuple[float, np.ndarray]:
    """Huber-weighted least squares of ``b = a w`` (a line through the origin): (a, the weights)."""
    a = float(w @ b / (w @ w))
    h = np.ones_like(w)
    for _ in range(5):
        r = b - a * w
        k = 1.345 * 1.4826 * max(float(np.median(np.abs(r))), 1e-9)
        h = np.where(np.abs(r) <= k, 1.0, k / np.maximum(np.abs(r), 1e-12))
        a = float((h * w) @ b / ((h * w) @ w))
    return a, h


def laser_ahead_of_turning_centre(stamps_ns: np.ndarray, wTb: np.ndarray, bTs: np.ndarray) -> Mounting | None:
    """How far ahead of the robot's turning centre the laser is, from the base poses ``wTb`` (N, 3) at the scan
    stamps ``stamps_ns`` (N,) (sorted) and the laser's pose ``bTs`` (3,) in the base by the log's transform.
    None when the robot turned too little to tell (fewer than ``MIN_TURNS`` pairs turning 1 deg)."""
    wTb = np.asarray(wTb, dtype=np.float64).reshape(-1, 3)
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    if len(wTb) < 2:
        return None
    # the laser's position with the base's heading: the arc constraint is about the robot's own x axis
    wTl = compose(wTb, np.array([bTs[0], bTs[1], 0.0]))
    c, s = np.cos(wTl[:-1, 2]), np.sin(wTl[:-1, 2])
    d = np.diff(wTl[:, :2], axis=0)
    tx, ty = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    dth = wrap(np.diff(wTl[:, 2]))
    ok = (np.abs(dth) < MAX_TURN_RAD) & (np.diff(stamps_ns) < MAX_GAP_NS)
    turns = int(np.count_nonzero(ok & (np.abs(dth) >= MIN_TURN_RAD)))
    if turns < MIN_TURNS:
        return None
    tau = np.tan(dth[ok] / 2.0)
    w, b = 2.0 * tau, ty[ok] - tx[ok] * tau  # the lateral motion beyond the arc's = 2 a tan(dtheta / 2)
    a, h = _fit(w, b)
    # standard error robust to correlated neighbours: the residual scores summed in blocks of the log
    # (a cluster "sandwich" estimate; blocks that barely turn weigh little instead of swinging the spread)
    hw = h * w
    scores = [float(hw[i] @ (b[i] - a * w[i])) for i in np.array_split(np.arange(len(w)), _BLOCKS)]
    k = len(scores)
    std = float(np.sqrt(k / (k - 1) * np.sum(np.square(scores))) / (hw @ w))
    return Mounting(a, std, int(len(w)), turns, float(bTs[0]))


def mounting_check(stamps_ns: np.ndarray, wTb: np.ndarray, bTs: np.ndarray, base_frame: str,
                   laser_frame: str) -> dict[str, Any] | None:
    """``laser_ahead_of_turning_centre`` in its JSON form (the run report's ``submaps.laser_mounting``) with the
    frames it is about; None when the robot turned too little to tell."""
    m = laser_ahead_of_turning_centre(stamps_ns, wTb, bTs)
    if m is None:
        return None
    return {**m.to_dict(), "base_frame": base_frame, "laser_frame": laser_frame}


def _ahead(x: float) -> str:
    return f"{abs(x):.3f} m {'ahead of' if x >= 0 else 'behind'}"


def mounting_text(m: Mapping[str, Any]) -> list[str]:
    """The run report's lines of a mounting check (``mounting_check``'s JSON form): where the laser is, and the
    mapping line that puts base_link at the turning centre when it is off it."""
    base, laser = m.get("base_frame", "base_link"), m.get("laser_frame", "laser")
    line = (f"  laser mounting: the robot's motion ({m['turns']} turning scan pairs) puts {laser} "
            f"{_ahead(m['laser_x_m'])} the point it turns about (+/- {m['laser_x_std_m']:.3f} m); its "
            f"transform puts it {_ahead(m['tf_laser_x_m'])} {base}, so {base} is {_ahead(-m['centre_in_base_x_m'])} "
            "the turning centre")
    if not m["base_off_centre"]:
        return [line]
    return [line, f"    the trajectory is {base}'s, not the turning centre's: if {base} should be the turning centre "
            "(the midpoint of the drive wheels), put the laser there with a mapping: 'frames: {static: "
            f"[{{parent: {base}, child: {laser}, xyz: [{m['laser_x_m']:.3f}, Y, Z]}}]}}' (Y, Z as its "
            "transform; the run configuration's 'mapping:' names the file)"]
