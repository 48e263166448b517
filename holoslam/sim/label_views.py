"""Rendered views of QR labels with known ground truth, for tests and benchmarks.

A label is a printed square QR code (side ``side_m``, the outer edges of the finder patterns, quiet zone
excluded) on a white sticker with a quiet zone of ``quiet_modules`` modules. Its frame ``o`` has the origin
at the code centre, x to the right along the printed top edge, y up along the printed left edge and z out of
the printed face (towards a viewer). In that frame the code's corners in the code's own order (TL, TR, BR, BL)
are ``(-s/2, s/2), (s/2, s/2), (s/2, -s/2), (-s/2, -s/2)`` (z = 0): the order OpenCV's
``SOLVEPNP_IPPE_SQUARE`` expects.

Images are rendered by warping the code image with the homography of the true pose ``cTo`` (the label pose in
the camera's optical frame: z forward, x right, y down) and the intrinsics ``K``, at 2x supersampling, over a
cluttered background, then optional lighting gradient, motion blur, Gaussian noise and JPEG. Pixel centres are
at integer coordinates (OpenCV's convention), so the true corners are ``project(K, cTo, corners)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from holoslam.sim.camera import project, qr_modules

__all__ = [
    "LabelInView",
    "RenderConditions",
    "label_corners_o",
    "look_at_label",
    "project_points",
    "qr_module_matrix",
    "render_label_view",
    "render_labels_view",
    "module_size_px",
]

_SUPERSAMPLE = 2


def label_corners_o(side_m: float) -> np.ndarray:
    """The code's corners TL, TR, BR, BL in the label frame, (4, 3)."""
    h = side_m / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def qr_module_matrix(payload: str, error: str = "m") -> np.ndarray:
    """The (N, N) uint8 module matrix (1 = dark) of a full-size QR code (never Micro QR) for ``payload``,
    the error level raised where the version has room (segno's default)."""
    return qr_modules(payload, error, boost_error=True).astype(np.uint8)


def project_points(K: np.ndarray, cTo: np.ndarray, o_points: np.ndarray) -> np.ndarray:
    """Pinhole projection (no distortion) of (N, 3) points of frame o into pixels, (N, 2): ``sim.camera.project``
    with frame o as the world (the camera at oTc = cTo^-1)."""
    R, t = cTo[:3, :3], cTo[:3, 3]
    return project(np.asarray(K, dtype=np.float64), R.T, -R.T @ t, np.asarray(o_points, dtype=np.float64))[0]


def look_at_label(
    distance_m: float,
    yaw_deg: float = 0.0,
    pitch_deg: float = 0.0,
    roll_deg: float = 0.0,
    offset_xy: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """``cTo`` for a label ``distance_m`` in front of the camera at lateral/vertical offset ``offset_xy`` (m,
    optical x right / y down), facing the camera, then turned by yaw (about its own y), pitch (about its x)
    and rolled in-plane (about its z). Roll 0 shows the code upright."""

    def rx(a: float) -> np.ndarray:
        c, s = math.cos(a), math.sin(a)
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])

    def ry(a: float) -> np.ndarray:
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])

    def rz(a: float) -> np.ndarray:
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])

    # facing the camera: label x = camera x, label y = -camera y (up), label z = -camera z (towards camera)
    cRo = (
        np.diag([1.0, -1.0, -1.0])
        @ ry(math.radians(yaw_deg))
        @ rx(math.radians(pitch_deg))
        @ rz(math.radians(roll_deg))
    )
    T = np.eye(4)
    T[:3, :3] = cRo
    T[:3, 3] = (offset_xy[0], offset_xy[1], distance_m)
    return T


@dataclass(frozen=True, slots=True)
class LabelInView:
    """One label to render: payload text, printed code side (m) and its pose in the camera frame."""

    payload: str
    side_m: float
    cTo: np.ndarray
    quiet_modules: int = 4


@dataclass(frozen=True, slots=True)
class RenderConditions:
    """Image degradations. ``light_gain``/``light_offset`` scale/shift intensities, ``light_gradient`` adds a
    left-to-right illumination ramp (fraction of full scale), ``blur_px``/``blur_angle_deg`` a linear motion
    blur, ``noise_sigma`` Gaussian noise (grey levels), ``jpeg_quality`` 0 = no JPEG, ``clutter`` random
    rectangles and lines in the background."""

    light_gain: float = 1.0
    light_offset: float = 0.0
    light_gradient: float = 0.0
    blur_px: float = 0.0
    blur_angle_deg: float = 0.0
    noise_sigma: float = 0.0
    jpeg_quality: int = 0
    clutter: int = 12


def module_size_px(K: np.ndarray, label: LabelInView, n_modules: int) -> float:
    """The mean side of one module in the image (pixels) for ``label`` with ``n_modules`` per side."""
    p = project_points(K, label.cTo, label_corners_o(label.side_m))
    sides = np.linalg.norm(p - np.roll(p, -1, axis=0), axis=1)
    return float(sides.mean() / n_modules)


def _background(shape: tuple[int, int], rng: np.random.Generator, clutter: int) -> np.ndarray:
    import cv2

    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    a, b, c = rng.uniform(-0.15, 0.15, 3)
    img = 140.0 + 60.0 * (a * xx / w + b * yy / h) + 20.0 * c
    img = img.astype(np.float32)
    for _ in range(clutter):
        x0, y0 = int(rng.integers(0, w)), int(rng.integers(0, h))
        col = float(rng.uniform(30, 230))
        if rng.random() < 0.6:
            x1, y1 = x0 + int(rng.integers(5, w // 3)), y0 + int(rng.integers(5, h // 3))
            cv2.rectangle(img, (x0, y0), (x1, y1), col, -1)
        else:
            x1, y1 = int(rng.integers(0, w)), int(rng.integers(0, h))
            cv2.line(img, (x0, y0), (x1, y1), col, int(rng.integers(1, 4)))
    return img


def render_labels_view(
    labels: list[LabelInView] | tuple[LabelInView, ...],
    K: np.ndarray,
    size_wh: tuple[int, int] = (640, 480),
    conditions: RenderConditions | None = None,
    seed: int = 0,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Render several labels into one grey image.

    Returns ``(image (H, W) uint8, [true corners (4, 2) per label in code order TL, TR, BR, BL])``.
    Labels must be in front of the camera (z > 0 at every corner); later labels are painted over earlier ones.
    """
    import cv2

    cond = conditions or RenderConditions()
    rng = np.random.default_rng(seed)
    w, h = size_wh
    f = _SUPERSAMPLE
    big = _background((h * f, w * f), rng, cond.clutter)
    K = np.asarray(K, dtype=np.float64)
    # image pixel (x, y) -> supersampled pixel f*(x+0.5)-0.5
    S = np.array([[f, 0, 0.5 * f - 0.5], [0, f, 0.5 * f - 0.5], [0, 0, 1.0]])
    truths = []
    for lab in labels:
        m = qr_module_matrix(lab.payload)
        n = m.shape[0]
        q = lab.quiet_modules
        # texture: ppm pixels per module, chosen so a texture pixel is at most ~1 supersampled pixel
        mod_px = module_size_px(K, lab, n) * f
        ppm = int(min(16, max(2, math.ceil(mod_px))))
        tex = np.pad(1 - m, q, constant_values=1).astype(np.float32) * 255.0
        tex = np.kron(tex, np.ones((ppm, ppm), np.float32))
        side_tex = (n + 2 * q) * ppm
        # texture pixel (u, v) centre -> label-frame metres; the code spans modules q .. q+n
        s_mod = lab.side_m / n
        A = np.array(
            [
                [s_mod / ppm, 0, (0.5 / ppm - q) * s_mod - lab.side_m / 2],
                [0, -s_mod / ppm, lab.side_m / 2 - (0.5 / ppm - q) * s_mod],
                [0, 0, 1.0],
            ]
        )
        P = K @ np.column_stack([lab.cTo[:3, 0], lab.cTo[:3, 1], lab.cTo[:3, 3]])  # plane z=0 homography
        H = S @ P @ A
        warped = cv2.warpPerspective(
            tex, H, (w * f, h * f), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0
        )
        mask = cv2.warpPerspective(
            np.ones((side_tex, side_tex), np.float32),
            H,
            (w * f, h * f),
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=0.0,
        )
        big = big * (1.0 - mask) + np.clip(warped, 0, 255) * mask
        truths.append(project_points(K, lab.cTo, label_corners_o(lab.side_m)))
    img = cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA)
    # print contrast: paper white ~ 235, ink ~ 25 (scaled after compositing to keep background plausible)
    img = 25.0 + img * (210.0 / 255.0)
    if cond.light_gradient:
        ramp = np.linspace(-0.5, 0.5, w, dtype=np.float32)[None, :]
        img = img * (1.0 + cond.light_gradient * ramp)
    img = img * cond.light_gain + cond.light_offset
    if cond.blur_px > 0:
        L = max(1, int(round(cond.blur_px)))
        ksz = 2 * L + 1
        ker = np.zeros((ksz, ksz), np.float32)
        a = math.radians(cond.blur_angle_deg)
        c0 = (L, L)
        p0 = (int(round(L - cond.blur_px / 2 * math.cos(a))), int(round(L - cond.blur_px / 2 * math.sin(a))))
        p1 = (int(round(L + cond.blur_px / 2 * math.cos(a))), int(round(L + cond.blur_px / 2 * math.sin(a))))
        cv2.line(ker, p0, p1, 1.0, 1)
        if ker.sum() == 0:
            ker[c0] = 1.0
        img = cv2.filter2D(img, -1, ker / ker.sum(), borderType=cv2.BORDER_REFLECT)
    if cond.noise_sigma > 0:
        img = img + rng.normal(0.0, cond.noise_sigma, img.shape).astype(np.float32)
    out: np.ndarray = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if cond.jpeg_quality > 0:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(cond.jpeg_quality)])
        decoded = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
        if decoded is None:  # pragma: no cover - OpenCV reads the JPEG it has just written
            raise RuntimeError("OpenCV could not read back the JPEG it encoded")
        out = decoded
    return out, truths


def render_label_view(
    payload: str,
    side_m: float,
    cTo: np.ndarray,
    K: np.ndarray,
    size_wh: tuple[int, int] = (640, 480),
    conditions: RenderConditions | None = None,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Render one label; returns ``(image (H, W) uint8, true corners (4, 2) TL, TR, BR, BL)``."""
    img, truths = render_labels_view(
        [LabelInView(payload, side_m, np.asarray(cTo, dtype=np.float64))], K, size_wh, conditions, seed
    )
    return img, truths[0]
