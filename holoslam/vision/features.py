"""The object feature set F = {size, texture, dominant colour set, SIFT keypoints} (seed 002, Eq. 13),
computed from the image crops that show an object.

- size: the printed label side (m) and, when PnP poses are given, the median label-centre range;
- texture: a rotation-invariant uniform LBP histogram (8 neighbours, radius 1: 10 bins), averaged over crops;
- dominant colours: ``cv2.kmeans`` in CIE Lab (OpenCV's 8-bit Lab scaled back to L 0-100, a/b -128..127) of
  the crops' pixels, centres sorted by weight;
- SIFT: ``cv2.SIFT_create`` keypoints (x, y, size, angle, crop index) and 128-d descriptors of every crop.

``crop_around_label`` cuts the region around a label (the object it is stuck on) from an image.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from holoslam.errors import VisionError

__all__ = ["ObjectFeatures", "lbp_histogram", "dominant_colours", "crop_around_label", "object_features"]

_LBP_BINS = 10


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, slots=True)
class ObjectFeatures:
    """Eq. 13 for one object. Arrays: ``texture`` (10,) LBP histogram summing to 1; ``colours_lab`` (k, 3)
    and ``colour_weights`` (k,); ``keypoints`` (M, 5) x, y, size, angle, crop index; ``descriptors`` (M, 128)
    float32."""

    object_id: str
    size_m: float
    range_m: float
    n_crops: int
    texture: np.ndarray
    colours_lab: np.ndarray
    colour_weights: np.ndarray
    keypoints: np.ndarray
    descriptors: np.ndarray

    def __post_init__(self) -> None:
        for name in ("texture", "colours_lab", "colour_weights", "keypoints", "descriptors"):
            object.__setattr__(self, name, _readonly(np.asarray(getattr(self, name))))

    def to_summary(self) -> dict:
        """A JSON-able summary (scalars and short lists) for the holographic graph."""
        return {
            "object_id": self.object_id,
            "size_m": None if not np.isfinite(self.size_m) else round(float(self.size_m), 4),
            "range_m": None if not np.isfinite(self.range_m) else round(float(self.range_m), 3),
            "n_crops": int(self.n_crops),
            "texture_lbp": [round(float(v), 4) for v in self.texture],
            "colours_lab": [[round(float(v), 1) for v in c] for c in self.colours_lab],
            "colour_weights": [round(float(w), 3) for w in self.colour_weights],
            "n_sift": int(self.keypoints.shape[0]),
        }


def _gray(img: np.ndarray) -> np.ndarray:
    import cv2

    a = np.asarray(img)
    if a.dtype != np.uint8:
        raise VisionError(f"crop dtype {a.dtype}: features need uint8 pixels")
    if a.ndim == 2:
        return a
    if a.ndim == 3 and a.shape[2] == 3:
        return cv2.cvtColor(a, cv2.COLOR_BGR2GRAY)
    raise VisionError(f"crop shape {a.shape} is not (H, W) or (H, W, 3)")


# rotation-invariant uniform LBP code of each of the 256 patterns: number of set bits if the circular pattern
# has at most two 0/1 transitions, else 9 (the "non-uniform" bin)
def _riu2_table() -> np.ndarray:
    codes = np.arange(256)
    bits = (codes[:, None] >> np.arange(8)[None, :]) & 1
    transitions = np.sum(bits != np.roll(bits, 1, axis=1), axis=1)
    return np.where(transitions <= 2, bits.sum(axis=1), 9).astype(np.int64)


_RIU2 = _riu2_table()


def lbp_histogram(img: np.ndarray) -> np.ndarray:
    """The normalised rotation-invariant uniform LBP(8, 1) histogram (10,) of an image (vectorised)."""
    g = _gray(img).astype(np.int16)
    if g.shape[0] < 3 or g.shape[1] < 3:
        raise VisionError(f"crop of shape {g.shape} is too small for a texture descriptor (>= 3x3)")
    c = g[1:-1, 1:-1]
    offs = [(-1, -1), (-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1)]
    code = np.zeros(c.shape, np.int64)
    H, W = g.shape
    for k, (dy, dx) in enumerate(offs):  # 8 whole-array comparisons, no per-pixel loop
        code |= (g[1 + dy : H - 1 + dy, 1 + dx : W - 1 + dx] >= c).astype(np.int64) << k
    hist = np.bincount(_RIU2[code].ravel(), minlength=_LBP_BINS).astype(np.float64)
    return hist / hist.sum()


def dominant_colours(
    crops: Sequence[np.ndarray], k: int = 3, max_pixels: int = 20000, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` dominant colours (k, 3) in Lab (L 0-100, a, b) of the crops' pixels and their weights (k,),
    heaviest first (``cv2.kmeans``; grey crops give a = b = 0)."""
    import cv2

    pix = []
    for im in crops:
        a = np.asarray(im)
        bgr = cv2.cvtColor(a, cv2.COLOR_GRAY2BGR) if a.ndim == 2 else a
        if bgr.dtype != np.uint8 or bgr.ndim != 3 or bgr.shape[2] != 3:
            raise VisionError(f"crop of shape {a.shape} / {a.dtype} is not a uint8 grey or BGR image")
        pix.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2Lab).reshape(-1, 3))
    P = np.concatenate(pix).astype(np.float32)
    if len(P) > max_pixels:
        P = P[np.random.default_rng(seed).choice(len(P), max_pixels, replace=False)]
    k = int(min(k, len(np.unique(P, axis=0))))
    cv2.setRNGSeed(seed)
    _, lab, centres = cv2.kmeans(
        P, k, None, (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.5), 3, cv2.KMEANS_PP_CENTERS
    )
    w = np.bincount(lab.ravel(), minlength=k).astype(np.float64)
    w /= w.sum()
    order = np.argsort(-w)
    c = centres[order].astype(np.float64)
    c = np.column_stack([c[:, 0] * 100.0 / 255.0, c[:, 1] - 128.0, c[:, 2] - 128.0])
    return c, w[order]


def crop_around_label(image: np.ndarray, corners: np.ndarray, scale: float = 3.0) -> np.ndarray:
    """The axis-aligned region ``scale`` times the label's size around its centre (clipped to the image)."""
    c = np.asarray(corners, np.float64).reshape(4, 2)
    centre = c.mean(axis=0)
    half = 0.5 * scale * float(np.max(c.max(axis=0) - c.min(axis=0)))
    h, w = image.shape[:2]
    x0, y0 = int(max(0, np.floor(centre[0] - half))), int(max(0, np.floor(centre[1] - half)))
    x1, y1 = int(min(w, np.ceil(centre[0] + half) + 1)), int(min(h, np.ceil(centre[1] + half) + 1))
    if x1 - x0 < 3 or y1 - y0 < 3:
        raise VisionError(f"the label at {np.round(centre, 1)} lies outside the {w}x{h} image")
    return image[y0:y1, x0:x1]


def object_features(
    object_id: str,
    crops: Sequence[np.ndarray],
    size_m: float = float("nan"),
    ranges_m: Sequence[float] = (),
    n_colours: int = 3,
    max_sift: int = 200,
) -> ObjectFeatures:
    """Eq. 13's feature set of one object from its crops (grey or BGR uint8)."""
    import cv2

    if not crops:
        raise VisionError(f"object {object_id}: no image crops to compute features from")
    texture = np.mean([lbp_histogram(c) for c in crops], axis=0)
    colours, weights = dominant_colours(crops, n_colours)
    sift = cv2.SIFT_create(nfeatures=max_sift)
    kps, descs = [], []
    for i, c in enumerate(crops):
        k, d = sift.detectAndCompute(_gray(c), None)
        if d is None or not k:
            continue
        kps.append(np.array([(p.pt[0], p.pt[1], p.size, p.angle, i) for p in k], np.float64))
        descs.append(d.astype(np.float32))
    keypoints = np.concatenate(kps) if kps else np.zeros((0, 5))
    descriptors = np.concatenate(descs) if descs else np.zeros((0, 128), np.float32)
    rng = float(np.median(ranges_m)) if len(ranges_m) else float("nan")
    return ObjectFeatures(
        object_id, float(size_m), rng, len(crops), texture, colours, weights, keypoints, descriptors
    )
