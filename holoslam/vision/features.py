"""The object feature set F = {size, texture, dominant colour set, SIFT keypoints} (seed 002, Eq. 13),
computed from the image crops that show an object.

- size: the printed label side (m) and, when PnP poses are given, the median label-centre range;
- texture: a rotation-invariant uniform LBP histogram (8 neighbours, radius 1: 10 bins), averaged over crops;
- dominant colours: ``cv2.kmeans`` in CIE Lab (OpenCV's 8-bit Lab scaled back to L 0-100, a/b -128..127) of
  the crops' pixels, centres sorted by weight;
- SIFT: ``cv2.SIFT_create`` keypoints (x, y, size, angle, crop index) and 128-d descriptors of every crop.

``crop_around_label`` cuts the region around a label (the object it is stuck on) from an image.

Wiring: ``object_features_from_log(log, items)`` takes the label sightings of a log (``Sighting`` records from
``holoslam.vision.observe``, robot ``TagSighting`` records, or ``ObjectObservation`` records, whose corners
are found again from the log's tags or by decoding the image), cuts a colour crop around the label in every
image that shows it, and computes each object's feature set; ``accepted=`` restricts it to the landmarks
accepted after consistent decodes (``accept_landmarks``). ``object_crops_from_log`` is the step before,
returning the crops and one line per item that gave no crop (no image at its stamp, label outside the image,
...).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from holoslam.errors import HoloslamError, ImageDecodeError, PayloadError, VisionError
from holoslam.types import LogData, ObjectObservation, TagSighting

if TYPE_CHECKING:
    from holoslam.vision.label import ObjectLabel
    from holoslam.vision.observe import Sighting

__all__ = [
    "ObjectFeatures",
    "ObjectCrop",
    "lbp_histogram",
    "dominant_colours",
    "crop_around_label",
    "label_mask",
    "object_features",
    "object_crops_from_log",
    "object_features_from_log",
    "best_views",
]

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
    crop_stamps_ns: tuple[int, ...] = ()

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
            "crop_stamps_ns": [int(t) for t in self.crop_stamps_ns],
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


def lbp_histogram(img: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """The normalised rotation-invariant uniform LBP(8, 1) histogram (10,) of an image (vectorised), over the
    pixels where ``mask`` (same shape, non-zero = use) is set, or all of them."""
    g = _gray(img).astype(np.int16)
    if g.shape[0] < 3 or g.shape[1] < 3:
        raise VisionError(f"crop of shape {g.shape} is too small for a texture descriptor (>= 3x3)")
    c = g[1:-1, 1:-1]
    offs = [(-1, -1), (-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1)]
    code = np.zeros(c.shape, np.int64)
    H, W = g.shape
    for k, (dy, dx) in enumerate(offs):  # 8 whole-array comparisons, no per-pixel loop
        code |= (g[1 + dy : H - 1 + dy, 1 + dx : W - 1 + dx] >= c).astype(np.int64) << k
    codes = _RIU2[code]
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != (H, W):
            raise VisionError(f"mask of shape {m.shape} does not match the crop's {(H, W)}")
        codes = codes[m[1:-1, 1:-1] != 0]
        if codes.size == 0:
            raise VisionError("the mask leaves no pixel for the texture descriptor")
    hist = np.bincount(codes.ravel(), minlength=_LBP_BINS).astype(np.float64)
    return hist / hist.sum()


def dominant_colours(
    crops: Sequence[np.ndarray],
    k: int = 3,
    max_pixels: int = 20000,
    seed: int = 0,
    masks: Sequence[np.ndarray | None] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` dominant colours (k, 3) in Lab (L 0-100, a, b) of the crops' pixels and their weights (k,),
    heaviest first (``cv2.kmeans``; grey crops give a = b = 0)."""
    import cv2

    pix = []
    for i, im in enumerate(crops):
        a = np.asarray(im)
        bgr = cv2.cvtColor(a, cv2.COLOR_GRAY2BGR) if a.ndim == 2 else a
        if bgr.dtype != np.uint8 or bgr.ndim != 3 or bgr.shape[2] != 3:
            raise VisionError(f"crop of shape {a.shape} / {a.dtype} is not a uint8 grey or BGR image")
        lab_px = cv2.cvtColor(bgr, cv2.COLOR_BGR2Lab).reshape(-1, 3)
        if masks is not None and masks[i] is not None:
            lab_px = lab_px[np.asarray(masks[i]).reshape(-1) != 0]
        pix.append(lab_px)
    P = np.concatenate(pix).astype(np.float32)
    if len(P) == 0:
        raise VisionError("no pixels left for the dominant colours (empty crops or masks)")
    if len(P) > max_pixels:
        P = P[np.random.default_rng(seed).choice(len(P), max_pixels, replace=False)]
    Pi = P.astype(np.int64)
    k = int(min(k, len(np.unique((Pi[:, 0] << 16) | (Pi[:, 1] << 8) | Pi[:, 2]))))
    cv2.setRNGSeed(seed)
    _, lab, centres = cv2.kmeans(  # type: ignore[call-overload, unused-ignore]  # bestLabels None: OpenCV allocates them
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
    x0, y0, x1, y1 = _crop_box(image.shape[:2], corners, scale)
    return image[y0:y1, x0:x1]


def _crop_box(shape_hw: tuple[int, ...], corners: np.ndarray, scale: float) -> tuple[int, int, int, int]:
    c = np.asarray(corners, np.float64).reshape(4, 2)
    centre = c.mean(axis=0)
    half = 0.5 * scale * float(np.max(c.max(axis=0) - c.min(axis=0)))
    h, w = shape_hw
    x0, y0 = int(max(0, np.floor(centre[0] - half))), int(max(0, np.floor(centre[1] - half)))
    x1, y1 = int(min(w, np.ceil(centre[0] + half) + 1)), int(min(h, np.ceil(centre[1] + half) + 1))
    if x1 - x0 < 3 or y1 - y0 < 3:
        raise VisionError(f"the label at {np.round(centre, 1)} lies outside the {w}x{h} image")
    return x0, y0, x1, y1


def label_mask(shape_hw: tuple[int, int], corners: np.ndarray, margin: float = 1.4) -> np.ndarray:
    """A (H, W) uint8 mask, 255 on the object and 0 on the label: the code's quadrilateral ``corners`` (4, 2)
    grown by ``margin`` about its centre (1.4 covers a 4-module quiet zone of codes up to version 4 and the
    sticker edge), so the object's texture and colours are not the code's black and white."""
    import cv2

    c = np.asarray(corners, np.float64).reshape(4, 2)
    centre = _diagonal_centre(c)
    grown = centre + margin * (c - centre)
    m = np.full(shape_hw, 255, np.uint8)
    cv2.fillConvexPoly(m, np.round(grown * 16).astype(np.int32), 0, cv2.LINE_8, 4)
    return m


def _diagonal_centre(c: np.ndarray) -> np.ndarray:
    d1, d2 = c[2] - c[0], c[3] - c[1]
    A = np.column_stack([d1, -d2])
    if abs(np.linalg.det(A)) < 1e-12:
        return c.mean(axis=0)
    return c[0] + np.linalg.solve(A, c[1] - c[0])[0] * d1


def object_features(
    object_id: str,
    crops: Sequence[np.ndarray],
    size_m: float = float("nan"),
    ranges_m: Sequence[float] = (),
    n_colours: int = 3,
    max_sift: int = 200,
    crop_stamps_ns: Sequence[int] = (),
    masks: Sequence[np.ndarray | None] | None = None,
) -> ObjectFeatures:
    """Eq. 13's feature set of one object from its crops (grey or BGR uint8); ``crop_stamps_ns`` records
    which images the crops came from; ``masks`` (one per crop, or None) restrict texture, colours and SIFT to
    the object's pixels."""
    import cv2

    if not crops:
        raise VisionError(f"object {object_id}: no image crops to compute features from")
    if masks is not None and len(masks) != len(crops):
        raise VisionError(f"object {object_id}: {len(masks)} masks for {len(crops)} crops")
    ms = list(masks) if masks is not None else [None] * len(crops)
    texture = np.mean([lbp_histogram(c, m) for c, m in zip(crops, ms, strict=True)], axis=0)
    colours, weights = dominant_colours(crops, n_colours, masks=ms)
    sift = cv2.SIFT_create(nfeatures=max_sift)  # type: ignore[attr-defined]  # in cv2 since 4.4; not in its stub
    kps, descs = [], []
    for i, c in enumerate(crops):
        m = None if ms[i] is None else (np.asarray(ms[i]) != 0).astype(np.uint8) * 255
        k, d = sift.detectAndCompute(_gray(c), m)
        if d is None or not k:
            continue
        kps.append(np.array([(p.pt[0], p.pt[1], p.size, p.angle, i) for p in k], np.float64))
        descs.append(d.astype(np.float32))
    keypoints = np.concatenate(kps) if kps else np.zeros((0, 5))
    descriptors = np.concatenate(descs) if descs else np.zeros((0, 128), np.float32)
    rng = float(np.median(ranges_m)) if len(ranges_m) else float("nan")
    return ObjectFeatures(
        object_id,
        float(size_m),
        rng,
        len(crops),
        texture,
        colours,
        weights,
        keypoints,
        descriptors,
        tuple(int(t) for t in crop_stamps_ns),
    )


# ------------------------------------------------------------------------------------------------ wiring


@dataclass(frozen=True, slots=True)
class ObjectCrop:
    """A colour crop (H, W, 3) uint8 BGR around one label in one image, the label's corners (4, 2) in the
    full image, its printed side (m, NaN if the label has no ``s``) and the camera -> label-centre range by
    PnP (m, NaN when unknown)."""

    object_id: str
    stamp_ns: int
    image_index: int
    crop: np.ndarray
    corners: np.ndarray
    side_m: float
    range_m: float
    mask: np.ndarray | None = None

    @property
    def label_px(self) -> float:
        """Mean side of the label in the image (pixels)."""
        c = self.corners
        return float(np.mean(np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1)))


def _nearest_index(stamps: np.ndarray, stamp_ns: int, tol_ns: int) -> int:
    if not len(stamps):
        return -1
    i = int(np.searchsorted(stamps, stamp_ns))
    cand = [j for j in (i - 1, i) if 0 <= j < len(stamps)]
    j = min(cand, key=lambda k: abs(int(stamps[k]) - stamp_ns))
    return j if abs(int(stamps[j]) - stamp_ns) <= tol_ns else -1


class _CropSource:
    """The log's images as ``object_crops_from_log`` reads them: image and camera-info stamps, the robot's tag
    sightings by stamp, and each image decoded (and its codes detected) at most once. Problem lines are
    appended to ``problems`` in the order they are met."""

    def __init__(self, log: LogData, stamp_tolerance_ns: int) -> None:
        self.log = log
        self.tol_ns = stamp_tolerance_ns
        self.img_stamps = np.array([im.stamp_ns for im in log.images], dtype=np.int64)
        self.info_stamps = np.array([ci.stamp_ns for ci in log.camera_infos], dtype=np.int64)
        self.tags_at: dict[int, list[TagSighting]] = {}
        for t in log.tags:
            self.tags_at.setdefault(t.stamp_ns, []).append(t)
        self.pixels: dict[int, np.ndarray | None] = {}
        self.decoded: dict[int, list] = {}
        self.problems: list[str] = []

    def object_label(self, item: Sighting | TagSighting | ObjectObservation) -> tuple[str, ObjectLabel] | None:
        """The item's object id and parsed label, or None (with a problem line) when its payload is not a
        holoslam label."""
        from holoslam.vision.label import parse_label

        oid = getattr(item, "object_id", None)
        label = getattr(item, "label", None)
        payload = getattr(item, "payload", "")
        if label is None:
            try:
                label = parse_label(payload)
            except PayloadError as e:
                what = "tag sighting" if oid is None else f"{oid}"
                why = "not a holoslam label" if oid is None else "payload is not a holoslam label"
                self.problems.append(f"{what} at {item.stamp_ns} ns: {why}: {e}")
                return None
        if oid is None:  # a TagSighting: the id is in the payload
            oid = label.object_id
        return oid, label

    def image_index(self, item: Sighting | TagSighting | ObjectObservation, where: str) -> int:
        """The item's image (its own index, else the image nearest its stamp), or -1 with a problem line."""
        k = int(getattr(item, "image_index", -1))
        if k < 0 or k >= len(self.log.images):
            k = _nearest_index(self.img_stamps, int(item.stamp_ns), self.tol_ns)
        if k < 0:
            self.problems.append(f"{where}: no image within {self.tol_ns / 1e6:g} ms of the sighting")
        return k

    def tag_corners(self, oid: str, k: int) -> np.ndarray | None:
        """The corners of ``oid``'s label among the robot's tag sightings at image ``k``'s stamp, if any."""
        from holoslam.vision.label import parse_label

        for t in self.tags_at.get(self.log.images[k].stamp_ns, []):
            try:
                if parse_label(t.payload).object_id == oid:
                    return t.corners
            except PayloadError:
                continue
        return None

    def image_pixels(self, k: int, where: str) -> np.ndarray | None:
        """Image ``k`` as 8-bit BGR (decoded once), or None with a problem line."""
        if k not in self.pixels:
            try:
                px = self.log.images[k].decode()
            except ImageDecodeError as e:
                self.problems.append(f"{where}: {e}")
                px = None
            if px is not None and (px.dtype != np.uint8 or px.ndim not in (2, 3)):
                self.problems.append(
                    f"{where}: image {k} is {px.dtype} {px.shape}, not an 8-bit grey/colour image"
                )
                px = None
            if px is not None and px.ndim == 2:
                import cv2

                px = cv2.cvtColor(px, cv2.COLOR_GRAY2BGR)
            self.pixels[k] = px
        return self.pixels[k]

    def decoded_corners(self, oid: str, k: int, px: np.ndarray, where: str) -> np.ndarray | None:
        """The corners of ``oid``'s label decoded in image ``k`` (``detect_qr``, once an image), or None with
        a problem line."""
        from holoslam.vision.qr import detect_qr

        if k not in self.decoded:
            self.decoded[k] = detect_qr(px)
        hits = [d for d in self.decoded[k] if d.label is not None and d.label.object_id == oid]
        if not hits:
            self.problems.append(f"{where}: the label is not among the codes decoded in image {k}")
            return None
        return hits[0].corners

    def label_range(self, corners: np.ndarray, side: float, k: int, where: str) -> float:
        """PnP's range to the label centre (m) with the camera info nearest image ``k``; NaN when the label's
        size or the camera info is unknown, or (with a problem line) when PnP fails."""
        from holoslam.vision.camera import PinholeCamera
        from holoslam.vision.locate import pnp_label

        j = _nearest_index(self.info_stamps, self.log.images[k].stamp_ns, self.tol_ns)
        if not (np.isfinite(side) and j >= 0):
            return float("nan")
        try:
            est = pnp_label(corners, side, PinholeCamera.from_camera_info(self.log.camera_infos[j]))
        except HoloslamError as e:
            self.problems.append(f"{where}: no range ({e})")
            return float("nan")
        return float(np.linalg.norm(est.c_position))


def _cut_crop(px: np.ndarray, corners: np.ndarray, crop_scale: float, mask_label: bool,
              max_side_px: int) -> tuple[np.ndarray, np.ndarray | None]:
    """The crop around ``corners`` (``crop_scale`` times the label), its label mask (``mask_label``), both
    shrunk to ``max_side_px`` at most. Raises VisionError when the box leaves the image."""
    import cv2

    x0, y0, x1, y1 = _crop_box(px.shape[:2], corners, crop_scale)
    crop = px[y0:y1, x0:x1]
    mask = label_mask(crop.shape[:2], corners - np.array([x0, y0], np.float64)) if mask_label else None
    f = max_side_px / max(crop.shape[:2])
    if f < 1.0:
        size = (max(3, round(crop.shape[1] * f)), max(3, round(crop.shape[0] * f)))
        crop = cv2.resize(crop, size, interpolation=cv2.INTER_AREA)
        if mask is not None:
            mask = cv2.resize(mask, size, interpolation=cv2.INTER_NEAREST)
    return crop, mask


def object_crops_from_log(
    log: LogData,
    items: Sequence[Sighting | TagSighting | ObjectObservation],
    accepted: Collection[str] | None = None,
    crop_scale: float = 3.0,
    stamp_tolerance_ns: int = 1_000_000,
    mask_label: bool = True,
    max_side_px: int = 256,
) -> tuple[dict[str, list[ObjectCrop]], list[str]]:
    """Colour crops around each label sighting in ``items`` (``Sighting``, ``TagSighting`` or
    ``ObjectObservation`` records of ``log``), grouped by object id and in stamp order, plus one problem line
    per item that gave no crop. ``accepted`` (ids, or the dict ``accept_landmarks`` returns) keeps only those
    objects; the same object in the same image is cropped once.

    Corners come from the item (sightings), else from the log's robot tag sightings at the image stamp, else
    from decoding the image (``detect_qr``). The range is PnP's when the label carries its size ``s`` and a
    ``CameraInfo`` is within ``stamp_tolerance_ns`` of the image. With ``mask_label`` each crop carries a
    mask (``label_mask``) that leaves the label and its quiet zone out of the object's features. Crops larger
    than ``max_side_px`` are shrunk to it (``INTER_AREA``; bounds SIFT's cost and evens out the scale);
    ``ObjectCrop.corners`` stay in full-image pixels."""
    if crop_scale <= 1.0:
        raise VisionError(f"crop_scale must be > 1 (crop larger than the label), got {crop_scale}")
    keep = None if accepted is None else set(accepted)
    src = _CropSource(log, stamp_tolerance_ns)
    out: dict[str, list[ObjectCrop]] = {}
    done: set[tuple[str, int]] = set()
    for item in items:
        named = src.object_label(item)
        if named is None:
            continue
        oid, label = named
        if keep is not None and oid not in keep:
            continue
        where = f"{oid} at {int(item.stamp_ns)} ns"
        k = src.image_index(item, where)
        if k < 0 or (oid, k) in done:
            continue
        corners = getattr(item, "corners", None)
        if corners is None:
            corners = src.tag_corners(oid, k)
        px = src.image_pixels(k, where)
        if px is None:
            continue
        if corners is None:
            corners = src.decoded_corners(oid, k, px, where)
            if corners is None:
                continue
        corners = np.asarray(corners, np.float64).reshape(4, 2)
        try:
            crop, mask = _cut_crop(px, corners, crop_scale, mask_label, max_side_px)
        except VisionError as e:
            src.problems.append(f"{where}: {e}")
            continue
        side = label.size_m if label.size_m is not None else float("nan")
        rng = src.label_range(corners, side, k, where)
        done.add((oid, k))
        out.setdefault(oid, []).append(
            ObjectCrop(
                oid, int(log.images[k].stamp_ns), k, np.ascontiguousarray(crop), corners, side, rng, mask
            )
        )
    for crops in out.values():
        crops.sort(key=lambda c: c.stamp_ns)
    return out, src.problems


def best_views(items: Sequence[Sighting | TagSighting | ObjectObservation],
               per_object: int) -> list[Sighting | TagSighting | ObjectObservation]:
    """At most ``per_object`` items per object id, the ones whose label corners span the most pixels (items
    without corners or an id are all kept: their size in the image is not known before decoding), in their
    original order."""
    sized: dict[str, list[tuple[float, int]]] = {}
    keep: set[int] = set()
    for i, it in enumerate(items):
        oid, c = getattr(it, "object_id", None), getattr(it, "corners", None)
        if oid is None or c is None:
            keep.add(i)
            continue
        q = np.asarray(c, np.float64).reshape(4, 2)
        sized.setdefault(oid, []).append((float(np.linalg.norm(q - np.roll(q, -1, axis=0), axis=1).mean()), i))
    for views in sized.values():
        keep.update(i for _, i in sorted(views, key=lambda v: -v[0])[:per_object])
    return [it for i, it in enumerate(items) if i in keep]


def object_features_from_log(
    log: LogData,
    items: Sequence[Sighting | TagSighting | ObjectObservation],
    accepted: Collection[str] | None = None,
    crop_scale: float = 3.0,
    max_crops: int = 8,
    n_colours: int = 3,
    max_sift: int = 200,
) -> dict[str, ObjectFeatures]:
    """Eq. 13's feature set of every object sighted in ``items`` (see ``object_crops_from_log``; ``accepted``
    restricts it to accepted landmarks), keyed by object id: size = the printed label side (``s``), range =
    median PnP range, texture / colours / SIFT over at most ``max_crops`` crops per object (the ones showing
    the label largest, i.e. the most detail). Computed once per object from its best views, not per frame:
    only the ``2 max_crops`` sightings of an object showing its label largest (``best_views``; the spare ones
    stand in for views whose crop fails) are cropped, so a camera stream that sees a label in hundreds of
    frames costs what a few snapshots do. ``ObjectFeatures.to_summary()`` is its JSON-able form."""
    if max_crops < 1:
        raise VisionError(f"max_crops must be >= 1, got {max_crops}")
    crops_by_id, _problems = object_crops_from_log(log, best_views(items, 2 * max_crops), accepted, crop_scale)
    out: dict[str, ObjectFeatures] = {}
    for oid in sorted(crops_by_id):
        crops = crops_by_id[oid]
        best = sorted(crops, key=lambda c: -c.label_px)[:max_crops]
        best.sort(key=lambda c: c.stamp_ns)
        sides = [c.side_m for c in crops if np.isfinite(c.side_m)]
        ranges = [c.range_m for c in crops if np.isfinite(c.range_m)]
        out[oid] = object_features(
            oid,
            [c.crop for c in best],
            size_m=float(np.median(sides)) if sides else float("nan"),
            ranges_m=ranges,
            n_colours=n_colours,
            max_sift=max_sift,
            crop_stamps_ns=[c.stamp_ns for c in best],
            masks=[c.mask for c in best],
        )
    return out
