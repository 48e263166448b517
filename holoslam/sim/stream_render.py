"""Rendering of the camera-stream frames (``holoslam.sim.stream``): the snapshot renderer's model
(``holoslam.sim.render``: background of floor, walls and ceiling, labels warped by their true homography,
lighting gain and gradient, optics blur, sensor noise, JPEG) at the cost a stream needs, plus motion blur.

Same look, cheaper arithmetic: the background is one compiled pass in float32 (``holoslam.sim._stream_fast``),
each label is warped into its bounding box only, and the noise comes from OpenCV's generator seeded from the
frame's ``numpy`` generator (so a run stays deterministic). The snapshot renderer is left as it is, so the
bundled log does not change.

Motion blur: the robot moves during the exposure, so every scene point sweeps a short path in the image. The
frame is convolved with a linear kernel along ``blur_uv`` (the image displacement over the exposure, in
pixels, measured at the point the camera looks at; ``holoslam.sim.stream``), the standard model of uniform
linear motion blur (a box along the motion), before the optics blur, noise and JPEG.
"""

from __future__ import annotations

import math

import numpy as np

from holoslam.sim.camera import IMAGE_SIZE, LABEL_MARGIN_MODULES, label_corners_world, project
from holoslam.sim.render import CEILING
from holoslam.sim.world import World, raycast

__all__ = ["render_stream_frame", "motion_kernel"]

_PAPER = np.array([238, 242, 242], np.float32)
_INK = np.array([25, 25, 30], np.float32)


def motion_kernel(blur_uv: np.ndarray) -> np.ndarray | None:
    """The normalised linear blur kernel (odd square, float32) of a uniform motion by ``blur_uv`` (2,) pixels
    during the exposure; None when the motion is below half a pixel (no visible blur)."""
    v = np.asarray(blur_uv, np.float64).reshape(2)
    length = float(np.hypot(*v))
    if not math.isfinite(length) or length < 0.5:
        return None
    r = int(math.ceil(length / 2)) + 1
    k = np.zeros((2 * r + 1, 2 * r + 1), np.float32)
    n = max(8, int(math.ceil(4 * length)))
    for s in np.linspace(-0.5, 0.5, n):  # bilinear splat of points spread evenly along the path
        x, y = r + s * v[0], r + s * v[1]
        x0, y0 = int(math.floor(x)), int(math.floor(y))
        fx, fy = x - x0, y - y0
        k[y0, x0] += (1 - fx) * (1 - fy)
        k[y0, x0 + 1] += fx * (1 - fy)
        k[y0 + 1, x0] += (1 - fx) * fy
        k[y0 + 1, x0 + 1] += fx * fy
    return k / k.sum()


def _draw_label(img: np.ndarray, world: World, modules: dict[str, np.ndarray], oid: str, K: np.ndarray,
                wRc: np.ndarray, wtc: np.ndarray) -> None:
    """Warp the label's code (with its quiet zone) into ``img`` (in place) over its bounding box only."""
    import cv2

    h, w = img.shape[:2]
    m = modules[oid]
    n = m.shape[0]
    uv, _ = project(K, wRc, wtc, label_corners_world(world.object(oid), LABEL_MARGIN_MODULES, n))
    x0, y0 = (int(max(0, math.floor(v) - 2)) for v in uv.min(axis=0))
    x1, y1 = int(min(w, math.ceil(uv[:, 0].max()) + 3)), int(min(h, math.ceil(uv[:, 1].max()) + 3))
    if x1 - x0 < 2 or y1 - y0 < 2:
        return
    side_px = np.linalg.norm(uv - np.roll(uv, -1, 0), axis=1).max()
    scale = int(np.clip(round(2.0 * side_px / (n + 2 * LABEL_MARGIN_MODULES)), 2, 10))
    code = np.pad(~m, LABEL_MARGIN_MODULES, constant_values=True).astype(np.float32)
    tex = cv2.resize(code, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    T = tex.shape[0]
    src = np.array([[0, 0], [T, 0], [T, T], [0, T]], dtype=np.float32) - 0.5
    Hm = cv2.getPerspectiveTransform(src, (uv - [x0, y0]).astype(np.float32))
    size = (x1 - x0, y1 - y0)
    warped = cv2.warpPerspective(tex, Hm, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                                 borderValue=0)
    cover = cv2.warpPerspective(np.ones((T, T), np.float32), Hm, size, flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    val = np.clip(warped / np.maximum(cover, 1e-6), 0, 1)
    col = _INK + (_PAPER - _INK) * val[..., None]
    a = np.clip(cover, 0, 1)[..., None]
    roi = img[y0:y1, x0:x1]
    roi[:] = roi * (1 - a) + col * a


def render_stream_frame(
    world: World,
    modules: dict[str, np.ndarray],
    K: np.ndarray,
    wRc: np.ndarray,
    wtc: np.ndarray,
    draw_ids: list[str] | tuple[str, ...],
    blur_uv: np.ndarray,
    rng: np.random.Generator,
    quality: int = 55,
    size: tuple[int, int] = IMAGE_SIZE,
) -> bytes:
    """The JPEG bytes of one stream frame: background, the labels ``draw_ids``, lighting (gain U(0.75, 1.15),
    gradient U(-0.15, 0.15) per axis), motion blur along ``blur_uv`` (px over the exposure), optics blur
    (sigma U(0.4, 0.8) px), noise (sigma 2 grey levels), JPEG at ``quality``."""
    import cv2

    from holoslam.sim._stream_fast import background

    w, h = size
    col_dir = wRc @ np.column_stack([(np.arange(w) - K[0, 2]) / K[0, 0], np.zeros(w), np.ones(w)]).T
    ang = np.arctan2(col_dir[1], col_dir[0])
    rw = raycast(world.wall_segments(), wtc[None, :2], ang[None, :], 50.0)[0]
    rw = np.where(np.isfinite(rw), rw, 50.0)
    img: np.ndarray = np.empty((h, w, 3), np.float32)
    background(np.ascontiguousarray(K, np.float64), np.ascontiguousarray(wRc, np.float64),
               np.ascontiguousarray(wtc, np.float64), rw.astype(np.float64), CEILING, img)
    for oid in draw_ids:
        _draw_label(img, world, modules, oid, K, wRc, wtc)
    gain = rng.uniform(0.75, 1.15)
    gx, gy = rng.uniform(-0.15, 0.15, 2)
    lx = (1 + gx * (np.arange(w, dtype=np.float32) / w - 0.5))[None, :]
    ly = (gy * (np.arange(h, dtype=np.float32) / h - 0.5))[:, None]
    img *= (gain * (lx + ly))[..., None].astype(np.float32)
    kern = motion_kernel(blur_uv)
    if kern is not None:
        img = cv2.filter2D(img, -1, kern, borderType=cv2.BORDER_REPLICATE)
    img = cv2.GaussianBlur(img, (0, 0), rng.uniform(0.4, 0.8))
    noise = np.empty_like(img)
    cv2.setRNGSeed(int(rng.integers(0, 2**31 - 1)))
    cv2.randn(noise, np.zeros(3), np.full(3, 2.0))
    img = img + noise
    px = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    ok, buf = cv2.imencode(".jpg", px, [cv2.IMWRITE_JPEG_QUALITY, int(quality), cv2.IMWRITE_JPEG_OPTIMIZE, 1])
    if not ok:  # pragma: no cover - OpenCV always encodes a uint8 BGR image
        raise RuntimeError("OpenCV failed to encode a JPEG")
    return buf.tobytes()
