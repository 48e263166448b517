"""Rendering of the PTZ camera's snapshots.

The image is drawn from the true geometry: a background of floor, walls and ceiling (each pixel's ray is
intersected with the floor plane, the ceiling plane at ``CEILING`` and the walls, per image column, with a
wood-plank floor texture and distance shading), then every label in front of the camera and not occluded is
drawn as a textured planar square: the QR code made by ``segno`` (with its white quiet zone of
``LABEL_MARGIN_MODULES`` modules) is warped into the image with the homography of its true pose and the
camera's K (``cv2.warpPerspective``, anti-aliased through a warped coverage mask). Finally: a global gain
and a lighting gradient (lighting variation, gain U(0.75, 1.15)), a Gaussian blur (sigma U(0.4, 0.8) px,
optics and focus), additive Gaussian noise (sigma 2 grey levels), and JPEG compression.
"""

from __future__ import annotations

import numpy as np

from holoslam.sim.camera import IMAGE_SIZE, LABEL_MARGIN_MODULES, label_corners_world, project
from holoslam.sim.world import World, raycast

__all__ = ["render_image", "render_pixels", "CEILING"]

CEILING = 2.6


def _background(
    world: World, K: np.ndarray, wRc: np.ndarray, wtc: np.ndarray, size: tuple[int, int]
) -> np.ndarray:
    w, h = size
    u = np.arange(w, dtype=np.float64)
    v = np.arange(h, dtype=np.float64)
    dirc = np.stack(np.meshgrid((u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]), -1)
    dirc = np.concatenate([dirc, np.ones((h, w, 1))], -1)
    dw = dirc @ wRc.T  # ray directions in map, (h, w, 3)
    horiz = np.hypot(dw[..., 0], dw[..., 1]) + 1e-12
    # wall distance per column (use the middle row's horizontal direction)
    col_dir = dw[h // 2]
    ang = np.arctan2(col_dir[:, 1], col_dir[:, 0])
    rw = raycast(world.wall_segments(), wtc[None, :2], ang[None, :], 50.0)[0]
    rw = np.where(np.isfinite(rw), rw, 50.0)
    rwall = rw[None, :] * np.ones((h, 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = np.where(dw[..., 2] < 0, wtc[2] / -dw[..., 2], np.inf)
        t_ceil = np.where(dw[..., 2] > 0, (CEILING - wtc[2]) / dw[..., 2], np.inf)
    r_floor = t_floor * horiz
    r_ceil = t_ceil * horiz
    floor = r_floor < rwall
    ceil = r_ceil < rwall
    img = np.empty((h, w, 3), dtype=np.float32)
    # walls: warm off-white with distance shading
    shade = np.clip(1.0 - 0.05 * rwall, 0.6, 1.0)[..., None]
    img[:] = np.array([176, 196, 212], np.float32) * shade
    # floor: wooden planks along x
    tf = np.where(floor, t_floor, 0.0)
    fx = wtc[0] + dw[..., 0] * tf
    fy = wtc[1] + dw[..., 1] * tf
    plank = (np.floor(fy / 0.15) % 2).astype(np.float32)
    grain = 0.06 * np.sin(fx * 9.0 + 3.0 * np.floor(fy / 0.15))
    wood = np.array([70, 110, 150], np.float32) * (0.9 + 0.1 * plank + grain)[..., None]
    fsh = np.clip(1.0 - 0.04 * np.where(np.isfinite(r_floor), r_floor, 0), 0.6, 1.0)[..., None]
    img = np.where(floor[..., None], wood * fsh, img)
    img = np.where(ceil[..., None], np.array([225, 228, 230], np.float32), img)
    return img


def render_pixels(
    world: World,
    modules: dict[str, np.ndarray],
    K: np.ndarray,
    wRc: np.ndarray,
    wtc: np.ndarray,
    draw_ids: list[str],
    rng: np.random.Generator,
    size: tuple[int, int] = IMAGE_SIZE,
) -> np.ndarray:
    """The BGR uint8 image (H, W, 3) before JPEG compression."""
    import cv2

    w, h = size
    img = _background(world, K, wRc, wtc, size)
    for oid in draw_ids:
        o = world.object(oid)
        m = modules[oid]
        n = m.shape[0]
        plate = label_corners_world(o, LABEL_MARGIN_MODULES, n)
        uv, _ = project(K, wRc, wtc, plate)
        side_px = np.linalg.norm(uv - np.roll(uv, -1, 0), axis=1).max()
        scale = int(np.clip(round(2.0 * side_px / (n + 2 * LABEL_MARGIN_MODULES)), 2, 10))
        code = np.pad(~m, LABEL_MARGIN_MODULES, constant_values=True).astype(np.uint8) * 255
        tex = cv2.resize(code, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
        T = tex.shape[0]
        src = np.array([[0, 0], [T, 0], [T, T], [0, T]], dtype=np.float32) - 0.5
        Hm = cv2.getPerspectiveTransform(src, (uv - 0.0).astype(np.float32))
        paper = np.array([238, 242, 242], np.float32)
        ink = np.array([25, 25, 30], np.float32)
        warped = cv2.warpPerspective(
            tex.astype(np.float32) / 255.0,
            Hm,
            (w, h),
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=0,
        )
        cover = cv2.warpPerspective(
            np.ones((T, T), np.float32),
            Hm,
            (w, h),
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=0,
        )
        with np.errstate(divide="ignore", invalid="ignore"):
            val = np.where(cover > 1e-6, warped / np.maximum(cover, 1e-6), 0.0)
        col = ink + (paper - ink) * np.clip(val, 0, 1)[..., None]
        a = np.clip(cover, 0, 1)[..., None]
        img = img * (1 - a) + col * a
    # lighting: global gain and a smooth gradient across the image
    gain = rng.uniform(0.75, 1.15)
    gx, gy = rng.uniform(-0.15, 0.15, 2)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    light = gain * (1 + gx * (xx / w - 0.5) + gy * (yy / h - 0.5))
    img = img * light[..., None]
    sigma = rng.uniform(0.4, 0.8)
    img = cv2.GaussianBlur(img, (0, 0), sigma)
    img = img + rng.normal(0.0, 2.0, img.shape).astype(np.float32)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def render_image(
    world: World,
    modules: dict[str, np.ndarray],
    K: np.ndarray,
    wRc: np.ndarray,
    wtc: np.ndarray,
    draw_ids: list[str],
    rng: np.random.Generator,
    quality: int = 55,
    size: tuple[int, int] = IMAGE_SIZE,
) -> bytes:
    """The JPEG bytes of one snapshot."""
    import cv2

    img = render_pixels(world, modules, K, wRc, wtc, draw_ids, rng, size)
    ok, buf = cv2.imencode(
        ".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(quality), cv2.IMWRITE_JPEG_OPTIMIZE, 1]
    )
    if not ok:  # pragma: no cover - OpenCV always encodes a uint8 BGR image
        raise RuntimeError("OpenCV failed to encode a JPEG")
    return buf.tobytes()
