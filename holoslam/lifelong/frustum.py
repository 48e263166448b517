"""Whether an object's place was in the camera's view: the images the session's camera actually took, each with
its own pose and intrinsics, tested against the place.

A label is read from an image (``holoslam.vision``) when it lies inside the picture, faces the camera, is large
enough in it to resolve its modules, and nothing stands in between. So an image whose frustum held a stored
object's place under those conditions, where the session did not read the object, is evidence that it is no
longer there; an object merely unseen (the camera looked elsewhere) is not. ``covering_images`` counts such
images per place:

- **frustum**: the label's centre (its stored x, y and height) projects inside the image, ``edge_margin`` of its
  size away from every border (the code's own extent and the pose's error at the place);
- **facing**: the camera within ``readable_deg`` of the label's normal (in 3-D, the normal horizontal) less two
  of the normal's sigmas and the place's error, when its readings told it, else within ``facing_deg`` of the
  side it was seen from before (``lifelong.facing``);
- **resolution**: the label's module would span ``min_module_px`` pixels (its printed side from its payload's
  ``s`` attribute, the module count of its QR code from the payload);
- **laser free space**: no occupied cell of the store's merged grid on the line from the camera to the place (the
  last ``skip_end_m`` before it left out: the furniture it stands on).

The camera's pose at an image: the session's trajectory (in the world by the relocalisation's wTs) interpolated
at the image's stamp, composed with the base -> camera transform of the log's TF tree at that stamp."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from holoslam import geometry as g

__all__ = ["FrustumConfig", "CameraViews", "camera_views", "covering_images", "module_count", "world_cameras"]


@dataclass(frozen=True, slots=True)
class FrustumConfig:
    # the simulated camera reads a label facing it within 60 deg (holoslam.sim.sensors.MAX_FACING_DEG); the
    # direction the label was seen from is a mean over its sightings, hence a margin
    facing_deg: float = 45.0
    # deg from the label's normal, in 3-D from the camera, that the camera reads at (the simulated camera's
    # MAX_FACING_DEG; QR decoders read to about 60 deg off frontal). An image counts within this less
    # ``normal_sigmas`` of the normal's sigma and ``normal_margin_deg``: the checks of a place the simulated
    # camera aims at it come at up to 60 deg from the true normal (seed 1 day 7: O17's two at 52 and 54 deg; seed
    # 3 day 9: O46's at 36 and 57), and the store's normals erred by at most 0.92 deg on seeds 1-3
    readable_deg: float = 60.0
    normal_sigmas: float = 2.0
    # deg: the direction from the place to the camera errs by the place's error over the range (2-3 cm at a metre
    # or more: 1-2 deg)
    normal_margin_deg: float = 2.0
    normal_max_sigma_deg: float = 2.5  # deg: a less certain normal is not used (``ChangeConfig``'s)

    def normal_facing_deg(self, normal_sigma_rad: float) -> float:
        """The largest angle (deg) from a normal of this sigma at which an image counts."""
        return self.readable_deg - self.normal_sigmas * math.degrees(normal_sigma_rad) - self.normal_margin_deg
    # px per module: holoslam.sim.sensors reads a label from 3 px (MIN_MODULE_PX) and zooms to 5 (TARGET_MODULE_PX);
    # 4 leaves a margin for the place's error
    min_module_px: float = 4.0
    # fraction of the image's width / height kept clear at each border (a code inside the picture entirely, and
    # a place known to a few cm seen from metres: 10 % of a 60 deg view is 6 deg)
    edge_margin: float = 0.1
    max_range_m: float = 3.5  # m: the simulated camera's snapshot range (MAX_SNAPSHOT_RANGE)
    p_occupied: float = 0.65  # a merged-grid cell above this blocks the line of sight (map_server's occupied)
    skip_end_m: float = 0.6  # m before the object that never block: the furniture it stands on
    default_side_m: float = 0.05  # m: a label without a printed size (s attribute) is taken this large


@dataclass(frozen=True, eq=False)
class CameraViews:
    """The session's images: stamps (I,), base -> camera transforms (I, 4, 4), intrinsics (I, 3, 3) and sizes
    (I, 2) as (width, height)."""

    stamps_ns: np.ndarray
    bTc: np.ndarray
    K: np.ndarray
    size: np.ndarray

    def __len__(self) -> int:
        return int(self.stamps_ns.shape[0])


def camera_views(log: Any, tolerance_ns: int = 50_000_000) -> CameraViews:
    """Every image of ``log`` with its camera transform and intrinsics (those without either are left out: they
    could not be read into sightings either)."""
    from holoslam.errors import HoloslamError
    from holoslam.frames import TransformTree

    infos = tuple(log.camera_infos)
    images = tuple(log.images)
    if not infos or not images:
        return CameraViews(np.zeros(0, np.int64), np.zeros((0, 4, 4)), np.zeros((0, 3, 3)), np.zeros((0, 2)))
    tree = TransformTree(log.transforms)
    ist = np.array([i.stamp_ns for i in infos], np.int64)
    rows = []
    for im in images:
        j = int(np.clip(np.searchsorted(ist, im.stamp_ns), 0, len(ist) - 1))
        j = min((k for k in (j - 1, j) if 0 <= k < len(ist)), key=lambda k: abs(int(ist[k]) - im.stamp_ns))
        if abs(int(ist[j]) - im.stamp_ns) > tolerance_ns:
            continue
        info = infos[j]
        try:
            bTc = tree.lookup(log.base_frame, im.frame_id or info.frame_id, im.stamp_ns)
        except HoloslamError:
            continue
        rows.append((im.stamp_ns, bTc, info.K, (info.width or im.width, info.height or im.height)))
    if not rows:
        return CameraViews(np.zeros(0, np.int64), np.zeros((0, 4, 4)), np.zeros((0, 3, 3)), np.zeros((0, 2)))
    return CameraViews(np.array([r[0] for r in rows], np.int64), np.array([r[1] for r in rows], np.float64),
                       np.array([r[2] for r in rows], np.float64), np.array([r[3] for r in rows], np.float64))


def module_count(payload: str) -> int:
    """Modules across the payload's QR code (segno's smallest version at error level M, as labels are printed)."""
    import segno

    try:
        return int(segno.make_qr(payload, error="m").symbol_size(border=0)[0])
    except Exception:  # noqa: BLE001 - a payload segno cannot encode: the largest code
        return 177


def _label_side(payload: str, default_m: float) -> float:
    from holoslam.errors import HoloslamError
    from holoslam.vision.label import parse_label

    try:
        s = parse_label(payload).size_m
    except HoloslamError:
        s = None
    return float(s) if s else default_m


def world_cameras(views: CameraViews, stamps_ns: np.ndarray, w_wTb: np.ndarray) -> np.ndarray:
    """wTc (I, 4, 4): the base's world pose at each image (interpolated) composed with its camera transform."""
    if not len(views):
        return np.zeros((0, 4, 4))
    wTb = g.interpolate_poses(stamps_ns, w_wTb, views.stamps_ns)
    T = np.zeros((len(views), 4, 4))
    c, s = np.cos(wTb[:, 2]), np.sin(wTb[:, 2])
    T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = c, -s, s, c
    T[:, 2, 2] = T[:, 3, 3] = 1.0
    T[:, 0, 3], T[:, 1, 3] = wTb[:, 0], wTb[:, 1]
    return T @ views.bTc


def covering_images(w_xyz: np.ndarray, view: np.ndarray | None, payload: str, views: CameraViews,
                    wTc: np.ndarray, merged: Any, cfg: FrustumConfig = FrustumConfig(),
                    normal: np.ndarray | None = None, normal_sigma_rad: float = math.nan) -> int:
    """How many of the session's images held the place ``w_xyz`` (x, y, label height) readable (module
    docstring); ``normal`` the label's horizontal normal in the world with its sigma (None: not known), ``view``
    the unit direction it was seen from (the fallback; None: any side), ``wTc`` from ``world_cameras``."""
    from holoslam.lifelong.facing import facing, facing_cos

    if not len(views):
        return 0
    p = np.asarray(w_xyz, np.float64)
    cam = wTc[:, :3, 3]
    d = p[None] - cam
    rng = np.linalg.norm(d, axis=1)
    ok = (rng <= cfg.max_range_m) & (rng > 0.1)
    f = facing(view, normal, normal_sigma_rad, cfg.facing_deg, cfg.normal_facing_deg(normal_sigma_rad),
               cfg.normal_max_sigma_deg)
    ok &= facing_cos(f, -d if f.from_normal else (cam[:, :2] - p[None, :2]))
    c = np.einsum("nji,nj->ni", wTc[:, :3, :3], d)  # the place in each camera frame (z forward)
    z = c[:, 2]
    ok &= z > 0.1
    zs = np.where(z > 0.1, z, 1.0)
    u = views.K[:, 0, 0] * c[:, 0] / zs + views.K[:, 0, 2]
    v = views.K[:, 1, 1] * c[:, 1] / zs + views.K[:, 1, 2]
    W, H = views.size[:, 0], views.size[:, 1]
    m = cfg.edge_margin
    ok &= (u >= m * W) & (u <= (1 - m) * W) & (v >= m * H) & (v <= (1 - m) * H)
    module_px = views.K[:, 0, 0] * _label_side(payload, cfg.default_side_m) / module_count(payload) / zs
    ok &= module_px >= cfg.min_module_px
    idx = np.flatnonzero(ok)
    if idx.size and merged is not None:
        blocked = merged.occupied_between(cam[idx, :2], np.broadcast_to(p[:2], (idx.size, 2)), cfg.p_occupied,
                                          cfg.skip_end_m)
        ok[idx[blocked]] = False
    return int(ok.sum())

