"""Camera-stream mode of the simulated PTZ camera (``SimConfig.camera_rate_hz`` > 0; ``holoslam simulate
--camera-rate HZ``): every frame at the given rate for the whole drive, like a real robot's camera topic, most
of them without a readable code.

The head. The operator's snapshot logic (``holoslam.sim.sensors.camera_snapshots``, at most
``image_rate_hz`` aims per second, new labels first, a second view 0.5 m away, resnap after ``resnap_s``)
decides when the head turns to a label; it then *tracks* that label for ``dwell_s`` seconds (pan and tilt
re-aimed at every frame from the true pose, the aim's pointing error of that snapshot kept; the snapshot's
zoom). The rest of the time the head looks straight ahead at zoom 1 (pan 0, tilt 0), where most labels are
too small to read (a 29-module, 0.1 m code at 1 m spans 1.8 px per module at f = 525 px).

Motion blur. The head holds its commanded pan and tilt during a frame's exposure (``exposure_s``) while the
base moves along its true trajectory, so a scene point P moves in the image by ``blur_uv`` = the difference
of its projections at the start and the end of the exposure. The frame is rendered with the linear blur
kernel of the motion of the point the camera looks at (the tracked label's centre; ahead of the camera at
``IDLE_LOOK_M`` when idle; the whole image gets that one kernel: rotation, the main part, blurs the image
uniformly). A label is readable (published on ``/tags`` and in ``/ground_truth/visible``) under the
snapshot rules (fully in the image, facing within 60 deg, not occluded, >= 3 px per module) and when its own
blur is at most ``MAX_BLUR_MODULES`` modules.

Frames are ``Snapshot`` records like the snapshots (``target_id`` "" when the head is idle;
``blur_px`` the length of the frame's blur), so the writer and every reader handle both modes alike.
"""

from __future__ import annotations

import math

import numpy as np

from holoslam.geometry import interpolate_poses, wrap
from holoslam.sim.camera import IMAGE_SIZE, camera_pose_world, intrinsics, project, qr_modules
from holoslam.sim.sensors import Snapshot, camera_snapshots, readable_labels
from holoslam.sim.world import World

__all__ = ["camera_stream", "MAX_BLUR_MODULES", "IDLE_LOOK_M", "frame_blur"]

# modules: a label is readable when its motion blur is at most this long. A uniform (box) blur of length L over
# a one-module bar of width m keeps the bar's centre at full contrast only while L <= m (the convolution's
# plateau is min(L, m) / L of the contrast): beyond one module, isolated modules fade toward the mean grey and a
# decoder's binarisation starts to flip them.
MAX_BLUR_MODULES = 1.0
# m: where the idle camera's blur is measured, on the optical axis: about the distance to the walls and
# furniture a robot sees ahead of it in the household's rooms (3-5 m across).
IDLE_LOOK_M = 2.0


def _aim(pose: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    """(pan, tilt) that point the camera at ``target`` (3,) from base pose ``pose`` (3,)."""
    _, cam = camera_pose_world(pose, 0.0, 0.0)
    rel = np.asarray(target, np.float64) - cam
    pan = float(wrap(math.atan2(rel[1], rel[0]) - pose[2]))
    return pan, math.atan2(rel[2], math.hypot(rel[0], rel[1]))


def frame_blur(K: np.ndarray, pose0: np.ndarray, pose1: np.ndarray, pan: float, tilt: float,
               points_w: np.ndarray) -> np.ndarray:
    """Image displacement (M, 2) px of world points (M, 3) between the base poses at the start (``pose0``) and
    the end (``pose1``) of an exposure, the head holding ``pan`` / ``tilt``."""
    wRc0, wtc0 = camera_pose_world(pose0, pan, tilt)
    wRc1, wtc1 = camera_pose_world(pose1, pan, tilt)
    uv0, _ = project(K, wRc0, wtc0, points_w)
    uv1, _ = project(K, wRc1, wtc1, points_w)
    return uv1 - uv0


def _head_plan(world: World, stamps_ns: np.ndarray, wTb: np.ndarray, rng: np.random.Generator,
               image_rate_hz: float, resnap_s: float, size: tuple[int, int]) -> list[Snapshot]:
    """The operator's aims (not rendered): when the head turns to which label, its pointing error and zoom."""
    if image_rate_hz <= 0:
        return []
    return camera_snapshots(world, stamps_ns, wTb, rng, image_rate_hz=image_rate_hz, resnap_s=resnap_s,
                            size=size, render=False)


def camera_stream(
    world: World,
    stamps_ns: np.ndarray,
    wTb: np.ndarray,
    rng: np.random.Generator,
    *,
    rate_hz: float,
    exposure_s: float,
    dwell_s: float,
    image_rate_hz: float = 0.25,
    resnap_s: float = 60.0,
    jpeg_quality: int = 55,
    size: tuple[int, int] = IMAGE_SIZE,
    offset_ns: int = 7_000_000,
    render: bool = True,
) -> list[Snapshot]:
    """Every camera frame at ``rate_hz`` along the true trajectory (see the module docstring)."""
    from holoslam.sim.stream_render import render_stream_frame

    aims = _head_plan(world, stamps_ns, wTb, rng, image_rate_hz, resnap_s, size)
    modules = {o.object_id: qr_modules(o.payload) for o in world.all_codes}
    period = 1e9 / rate_hz
    n = int(math.floor((stamps_ns[-1] - stamps_ns[0] - offset_ns - exposure_s * 5e8) / period)) + 1
    at = stamps_ns[0] + offset_ns + np.round(np.arange(max(n, 0)) * period).astype(np.int64)
    half = int(round(exposure_s * 5e8))
    poses = interpolate_poses(stamps_ns, wTb, at)
    p0 = interpolate_poses(stamps_ns, wTb, np.maximum(at - half, stamps_ns[0]))
    p1 = interpolate_poses(stamps_ns, wTb, np.minimum(at + half, stamps_ns[-1]))
    aim_stamps = np.array([a.stamp_ns for a in aims], np.int64)
    aim_err: list[tuple[float, float]] = []
    for a in aims:  # the snapshot's pointing error, kept while the head tracks its label
        pose = interpolate_poses(stamps_ns, wTb, np.array([a.stamp_ns]))[0]
        pan, tilt = _aim(pose, np.asarray(world.object(a.target_id).position))
        aim_err.append((float(wrap(a.pan - pan)), a.tilt - tilt))
    out: list[Snapshot] = []
    for k, t in enumerate(at):
        j = int(np.searchsorted(aim_stamps, t, side="right")) - 1
        tracking = j >= 0 and t - aim_stamps[j] < dwell_s * 1e9
        if tracking:
            target = aims[j].target_id
            look = np.asarray(world.object(target).position, np.float64)
            pan, tilt = _aim(poses[k], look)
            pan, tilt, zoom = float(wrap(pan + aim_err[j][0])), tilt + aim_err[j][1], aims[j].zoom
        else:
            target, pan, tilt, zoom = "", 0.0, 0.0, 1.0
        K = intrinsics(zoom, size)
        wRc, wtc = camera_pose_world(poses[k], pan, tilt)
        if not tracking:
            look = wtc + IDLE_LOOK_M * wRc[:, 2]
        blur_uv = frame_blur(K, p0[k], p1[k], pan, tilt, look[None, :])[0]
        ids, corners, draw = readable_labels(world, modules, K, wRc, wtc, size)
        ids = _sharp_enough(world, modules, K, p0[k], p1[k], pan, tilt, ids, corners)
        jpeg = b""
        if render:
            jpeg = render_stream_frame(world, modules, K, wRc, wtc, draw, blur_uv, rng, jpeg_quality, size)
        tags = tuple((world.object(i).payload, corners[i] + 0.3 * rng.standard_normal((4, 2))) for i in ids)
        out.append(Snapshot(int(t), pan, tilt, zoom, K, jpeg, tuple(ids), tags, target,
                            float(np.hypot(*blur_uv))))
    return out


def _sharp_enough(world: World, modules: dict[str, np.ndarray], K: np.ndarray, pose0: np.ndarray,
                  pose1: np.ndarray, pan: float, tilt: float, ids: list[str],
                  corners: dict[str, np.ndarray]) -> list[str]:
    """The readable ``ids`` whose own motion blur is at most ``MAX_BLUR_MODULES`` of their modules."""
    if not ids:
        return ids
    centres = np.array([world.object(i).position for i in ids], np.float64)
    blur = np.hypot(*frame_blur(K, pose0, pose1, pan, tilt, centres).T)
    keep = []
    for i, b in zip(ids, blur, strict=True):
        c = corners[i]
        module_px = float(np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1).min()) / modules[i].shape[0]
        if b <= MAX_BLUR_MODULES * module_px:
            keep.append(i)
    return keep

