"""A label's normal from several readings: the robust mean of unit vectors weighted by each reading's quality.

Each reading of a label gives its outward normal from the pose of its corners (``holoslam.vision.locate``) with
the standard deviation of its direction (rad: first order in the corners' noise, raised to cover both normals of
the planar pose's flip ambiguity when the reading cannot tell them apart). The mean is the unit vector along the
sum of the readings weighted by 1 / sigma^2 (sigma at least ``MIN_SIGMA_DEG``); a reading farther than
``OUTLIER_DEG`` from that mean is left out and the mean taken again (twice), so one flipped or misread normal does
not pull the others. The mean's sigma is the larger of its information (1 / sqrt of the weights' sum) and the
kept readings' weighted spread over sqrt(n) (readings that disagree more than their sigmas say).

Pure functions on numpy arrays; any dimension (3-D normals in a frame, or their horizontal 2-D directions)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["MIN_SIGMA_DEG", "OUTLIER_DEG", "mean_direction", "angle_deg"]

# deg: no reading is trusted beyond this. A reading's sigma holds its corners' noise only; where it is used (in the
# world, for the view tests) the robot's heading at the reading adds its error (the session's solve: about 0.1-0.5
# deg on the simulated days), and the corners' noise model (0.5 px) is not the detector's truth
MIN_SIGMA_DEG = 1.0
# deg from the weighted mean: a reading beyond is an outlier. A flipped PnP normal lies at twice the angle between
# the normal and the line of sight from it (on the simulated days' readings 28-117 deg at viewing angles of 15-56
# deg), a correct one within 2 deg of the truth; 30 keeps every reading of a label that agrees within 15 times
# the floor and drops the flips of oblique views
OUTLIER_DEG = 30.0


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """The angle (deg) between two vectors."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    c = float(a @ b) / max(float(np.linalg.norm(a) * np.linalg.norm(b)), 1e-300)
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def _weighted_unit_mean(u: np.ndarray, w: np.ndarray) -> np.ndarray | None:
    m = (u * w[:, None]).sum(axis=0)
    n = float(np.linalg.norm(m))
    return m / n if n > 1e-9 else None


def mean_direction(vectors: np.ndarray, sigma_rad: np.ndarray, outlier_deg: float = OUTLIER_DEG,
                   min_sigma_deg: float = MIN_SIGMA_DEG) -> tuple[np.ndarray | None, float, np.ndarray]:
    """The robust weighted mean direction of ``vectors`` (N, d; normalised here, zero rows ignored) with their
    sigmas (N,) in rad (NaN: ``min_sigma_deg``), as in the module docstring. Returns (unit mean (d,) or None when
    there is none, its sigma in rad, the mask (N,) of the readings kept)."""
    v = np.asarray(vectors, np.float64)
    if v.ndim != 2 or not len(v):
        return None, math.nan, np.zeros(len(v), bool)
    norm = np.linalg.norm(v, axis=1)
    ok = norm > 1e-9
    if not ok.any():
        return None, math.nan, np.zeros(len(v), bool)
    u = np.zeros_like(v)
    u[ok] = v[ok] / norm[ok, None]
    s = np.asarray(sigma_rad, np.float64).reshape(len(v))
    s = np.where(np.isfinite(s), np.maximum(s, math.radians(min_sigma_deg)), math.radians(min_sigma_deg))
    w = np.where(ok, 1.0 / s**2, 0.0)
    kept = ok.copy()
    m = _weighted_unit_mean(u[kept], w[kept])
    cos_out = math.cos(math.radians(outlier_deg))
    for _ in range(2):
        if m is None:
            break
        near = ok & (u @ m >= cos_out)
        if not near.any():  # every reading disagrees with the mean (two readings far apart): the most certain one
            near = np.zeros(len(v), bool)
            near[int(np.argmax(w))] = True
        kept = near
        m = _weighted_unit_mean(u[kept], w[kept])
    if m is None:
        return None, math.nan, np.zeros(len(v), bool)
    wk = w[kept]
    ang = np.arccos(np.clip(u[kept] @ m, -1.0, 1.0))
    info = 1.0 / math.sqrt(float(wk.sum()))
    spread = math.sqrt(float((wk * ang**2).sum() / wk.sum()) / len(wk))
    return m, max(info, spread), kept
