"""Wiring: a log's images (or the tag sightings the robot decoded itself) become object observations.

Pixels first (``holoslam.config.SightingSource``): by default (``auto``) a log with images has its images
decoded here (``holoslam.vision.qr.detect_qr``) and its robot tag topic is not used; a log without images uses
the tag topic. ``images``, ``tags`` and ``both`` (images first, then the tag sightings no image decode gave)
choose explicitly. Every sighting records its source.

``locate_from_log(log)`` takes, for each sighting, the ``CameraInfo`` with the image's stamp (nearest within
a tolerance) and the base -> camera transform at that stamp from the log's TF records
(``holoslam.frames.TransformTree``), then:

- a holoslam label with its printed size (attribute ``s``) is located by PnP in that view
  (an ``ObjectObservation`` in the base frame at the stamp);
- a label without a size, and (with ``foreign=True``) a code that is not a holoslam label, becomes a ``View``
  for triangulation over several robot poses (``holoslam.vision.multiview``), which needs the trajectory: the
  pipeline does it after the first solve. A foreign code's id is derived from its payload
  (``holoslam.vision.label.foreign_code_id``).

Nothing is silently lost: a ``VisionReport`` counts images, decodes, foreign codes, rejected payloads,
corrupt images (with their messages) and every reason a sighting gave no observation.
``observations_from_log`` is the same returning only the PnP observations and the report.

``accept_landmarks`` is the acceptance rule "a landmark only after consistent decodes": an object id is
accepted once at least ``min_decodes`` (default 3) of its sightings, expressed in one common frame, lie within
``radius_m`` (default 0.3 m) of their component-wise median.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from holoslam.config import SightingSource
from holoslam.errors import HoloslamError, ImageDecodeError, PayloadError, VisionError
from holoslam.types import CameraInfo, LogData, ObjectObservation
from holoslam.vision.camera import PinholeCamera
from holoslam.vision.label import MAGIC, ObjectLabel, foreign_code_id, parse_label
from holoslam.vision.locate import DEFAULT_SIGMA_PX, label_normal, observation_from_pnp
from holoslam.vision.multiview import View
from holoslam.vision.qr import Decoder, Fallback, detect_qr
from holoslam.vision.stream import FrameDecoder, StreamSettings

__all__ = [
    "Sighting",
    "VisionReport",
    "VisionResult",
    "AcceptedLandmark",
    "DEFAULT_MIN_DECODES",
    "resolve_source",
    "sightings_from_log",
    "locate_from_log",
    "observations_from_log",
    "accept_landmarks",
]

DEFAULT_MIN_DECODES = 3


@dataclass(frozen=True, slots=True)
class Sighting:
    """A code seen in one image: where its corners are and where they came from ("images": decoded here from
    the pixels, "tags": decoded on the robot). ``label`` is the holoslam label (None for a foreign code, whose
    ``object_id`` then comes from its payload). ``image_index`` indexes ``log.images`` (-1 for tags)."""

    stamp_ns: int
    frame_id: str
    payload: str
    label: ObjectLabel | None
    corners: np.ndarray
    source: str
    image_index: int = -1
    object_id: str = ""
    foreign: bool = False

    def __post_init__(self) -> None:
        if not self.object_id:
            oid = self.label.object_id if self.label is not None else foreign_code_id(self.payload)
            object.__setattr__(self, "object_id", oid)


@dataclass(frozen=True, slots=True)
class VisionReport:
    """What the vision stage made of a log. ``source`` is where the sightings came from ("images", "tags" or
    "both"); ``problems`` holds one line per image or sighting that gave nothing (corrupt image, missing
    calibration or transform, label without a size when triangulation is off), ``foreign_payloads`` the
    distinct texts of codes that are not holoslam labels. ``views`` counts the sightings kept for
    triangulation (labels without a size: ``sizeless``; foreign codes as landmarks: ``foreign_views``).
    On a stream (``holoslam.vision.stream``): ``full_decodes`` frames were decoded in full,
    ``skipped_no_code`` were not because the quick look found no code, ``skipped_same_view`` because they
    showed the view just decoded; ``frames_per_s`` is the frames per second (wall) of the image loop."""

    images: int = 0
    images_decoded: int = 0
    corrupt_images: int = 0
    decodes: int = 0
    labels: int = 0
    foreign: int = 0
    rejected_payloads: int = 0
    tag_sightings: int = 0
    duplicates_skipped: int = 0
    missing_camera_info: int = 0
    missing_transform: int = 0
    missing_size: int = 0
    pnp_failures: int = 0
    observations: int = 0
    object_ids: tuple[str, ...] = ()
    foreign_payloads: tuple[str, ...] = ()
    problems: tuple[str, ...] = field(default=())
    source: str = ""
    views: int = 0
    sizeless: int = 0
    foreign_views: int = 0
    full_decodes: int = 0
    skipped_no_code: int = 0
    skipped_same_view: int = 0
    frames_per_s: float = float("nan")

    def summary(self) -> str:
        return (
            f"{self.images} images ({self.images_decoded} with codes, {self.corrupt_images} corrupt; "
            f"{self.full_decodes} decoded in full, skipped: {self.skipped_no_code} without a code, "
            f"{self.skipped_same_view} the same view; {self.frames_per_s:.0f} frames/s), "
            f"{self.decodes} decodes ({self.labels} labels, {self.foreign} foreign, {self.rejected_payloads} "
            f"rejected), {self.tag_sightings} robot tag sightings, sightings from {self.source or 'nothing'}, "
            f"{self.observations} observations of {len(self.object_ids)} objects, {self.views} views to "
            "triangulate"
        )


@dataclass(frozen=True)
class VisionResult:
    """``observations``: PnP observations of labels with a size; ``views``: sightings to triangulate (labels
    without a size, foreign codes); ``sightings``: every label sighting used (for object features);
    ``report``."""

    observations: tuple[ObjectObservation, ...]
    views: tuple[View, ...]
    sightings: tuple[Sighting, ...]
    report: VisionReport


def _camera_info_at(
    infos: Sequence[CameraInfo], stamps: np.ndarray, frame_id: str, stamp_ns: int, tol_ns: int
) -> CameraInfo | None:
    if not len(infos):
        return None
    i = int(np.searchsorted(stamps, stamp_ns))
    best, best_dt = None, tol_ns + 1
    for j in (i - 1, i, i + 1):
        if 0 <= j < len(infos):
            dt = abs(int(stamps[j]) - stamp_ns)
            if dt < best_dt and (not frame_id or not infos[j].frame_id or infos[j].frame_id == frame_id):
                best, best_dt = infos[j], dt
    return best


def _shown(text: str) -> str:
    return text if len(text) <= 40 else text[:37] + "..."


def _centre(corners: np.ndarray) -> np.ndarray:
    """The intersection of the quadrilateral's diagonals (the code centre, exact under perspective)."""
    p0, p1, p2, p3 = np.asarray(corners, np.float64).reshape(4, 2)
    d1, d2 = p2 - p0, p3 - p1
    A = np.column_stack([d1, -d2])
    if abs(np.linalg.det(A)) < 1e-12:
        return np.asarray(corners, np.float64).reshape(4, 2).mean(axis=0)
    return p0 + np.linalg.solve(A, p1 - p0)[0] * d1


def _view_normal(corners: np.ndarray, cam: PinholeCamera, bTc: np.ndarray, sigma_px: float
                 ) -> tuple[np.ndarray | None, float]:
    """A code's outward normal in the base frame from its corners, without its size (``locate.label_normal``),
    and its sigma (rad); (None, NaN) when the corners give no pose."""
    try:
        c_normal, sigma = label_normal(corners, cam, sigma_px)
    except VisionError:
        return None, float("nan")
    return np.asarray(bTc, np.float64)[:3, :3] @ c_normal, sigma


def resolve_source(log: LogData, source: SightingSource | str = SightingSource.AUTO) -> SightingSource:
    """``auto`` made concrete for a log: its images when it has any, else its tag topic."""
    src = SightingSource(source)
    if src is SightingSource.AUTO:
        return SightingSource.IMAGES if log.images else SightingSource.TAGS
    return src


def sightings_from_log(
    log: LogData,
    source: SightingSource | str = SightingSource.AUTO,
    decoders: tuple[Decoder, ...] | None = None,
    fallback: Fallback | None = None,
    progress: Callable[[int, int], None] | None = None,
    foreign: bool = False,
    stream: StreamSettings | None = None,
    base_frame: str = "",
) -> tuple[list[Sighting], dict]:
    """The code sightings of a log from ``source`` (see the module docstring): holoslam labels, and with
    ``foreign`` the codes that are not labels too; and counters for the report (as a plain dict;
    ``locate_from_log`` turns it into a ``VisionReport``). ``progress(done, total)`` is called with the images
    decoded so far, about every 2 % of them. ``stream`` (default ``StreamSettings()``): the quick look and the
    same-view skip in front of the full decode (``holoslam.vision.stream``; ``base_frame`` "" = the log's)."""
    src = resolve_source(log, source)
    c: dict[str, Any] = {
        k: 0
        for k in (
            "images",
            "images_decoded",
            "corrupt_images",
            "decodes",
            "labels",
            "foreign",
            "rejected_payloads",
            "tag_sightings",
            "duplicates_skipped",
        )
    }
    problems: list[str] = []
    foreign_texts: dict[str, None] = {}
    out: list[Sighting] = []

    def classify(text: str, where: str) -> tuple[ObjectLabel | None, bool]:
        """(label, keep): a label; a foreign code (kept as a landmark with ``foreign``); a rejected payload."""
        try:
            return parse_label(text), True
        except PayloadError as e:
            if text.startswith(MAGIC + ";"):
                c["rejected_payloads"] += 1
                problems.append(f"{where}: rejected label payload: {e}")
                return None, False
            c["foreign"] += 1
            foreign_texts.setdefault(_shown(text), None)
            return None, foreign and bool(text)

    seen: set[tuple[int, str]] = set()
    frames = FrameDecoder(log, stream or StreamSettings(), base_frame,
                          lambda px, every: detect_qr(px, decoders, fallback if every else Fallback.NEVER))
    if src in (SightingSource.IMAGES, SightingSource.BOTH):
        every = max(1, -(-len(log.images) // 50))  # at most 50 calls
        for idx, im in enumerate(log.images):
            if progress is not None and idx % every == 0:
                progress(idx, len(log.images))
            c["images"] += 1
            where = f"image {idx} ({im.frame_id} at {im.stamp_ns} ns)"
            try:
                dets = frames.decode(idx, im)
            except (ImageDecodeError, VisionError) as e:
                c["corrupt_images"] += 1
                problems.append(f"{where}: {e}")
                continue
            if dets:
                c["images_decoded"] += 1
            for d in dets:
                c["decodes"] += 1
                label, keep = classify(d.payload, where)
                if not keep:
                    continue
                s = Sighting(im.stamp_ns, im.frame_id, d.payload, label, d.corners, "images", idx,
                             foreign=label is None)
                c["labels"] += label is not None
                seen.add((im.stamp_ns, s.object_id))
                out.append(s)
    if src in (SightingSource.TAGS, SightingSource.BOTH):
        for t in log.tags:
            c["tag_sightings"] += 1
            label, keep = classify(t.payload, f"tag sighting at {t.stamp_ns} ns")
            if not keep:
                continue
            s = Sighting(t.stamp_ns, t.frame_id, t.payload, label, t.corners, "tags", foreign=label is None)
            if (t.stamp_ns, s.object_id) in seen:  # the image decode of the same code came first
                c["duplicates_skipped"] += 1
                continue
            c["labels"] += label is not None
            out.append(s)
    c.update(frames.counts.for_report())
    c["problems"] = problems
    c["foreign_payloads"] = tuple(foreign_texts)
    c["source"] = src.value
    return out, c


def locate_from_log(
    log: LogData,
    base_frame: str = "",
    sigma_px: float = DEFAULT_SIGMA_PX,
    source: SightingSource | str = SightingSource.AUTO,
    decoders: tuple[Decoder, ...] | None = None,
    fallback: Fallback | None = None,
    camera_info_tolerance_ns: int = 50_000_000,
    progress: Callable[[int, int], None] | None = None,
    triangulate: bool = True,
    foreign: bool = False,
    stream: StreamSettings | None = None,
) -> VisionResult:
    """PnP observations (label centre in the base frame, "" = ``log.base_frame``, at each image stamp, with
    covariance from ``sigma_px`` pixel noise) of every sized label sighting of ``log``, the views to
    triangulate (labels without a size when ``triangulate``; foreign codes when ``foreign`` too), and a
    ``VisionReport``. ``progress(done, total)`` follows the image decoding and ``stream`` sets how frames are
    skipped (see :func:`sightings_from_log`)."""
    from holoslam.frames import TransformTree

    base_frame = base_frame or log.base_frame
    sightings, c = sightings_from_log(log, source, decoders, fallback, progress, foreign and triangulate, stream,
                                      base_frame)
    problems: list[str] = list(c.pop("problems"))
    foreign_payloads = c.pop("foreign_payloads")
    tree = TransformTree(log.transforms)
    infos = log.camera_infos
    info_stamps = np.array([i.stamp_ns for i in infos], dtype=np.int64)
    miss: dict[str, Any] = {"missing_camera_info": 0, "missing_transform": 0, "missing_size": 0, "pnp_failures": 0}
    obs: list[ObjectObservation] = []
    views: list[View] = []
    used: list[Sighting] = []
    n_sizeless = n_foreign = 0
    for s in sightings:
        where = f"{s.source} sighting of {s.object_id} at {s.stamp_ns} ns"
        side = s.label.size_m if s.label is not None else None
        sized = side is not None and side > 0
        if not sized and not triangulate:
            miss["missing_size"] += 1
            problems.append(
                f"{where}: label has no printed size (attribute s=<mm>) and triangulation is off; cannot "
                "locate it from one view"
            )
            continue
        info = _camera_info_at(infos, info_stamps, s.frame_id, s.stamp_ns, camera_info_tolerance_ns)
        if info is None:
            miss["missing_camera_info"] += 1
            problems.append(
                f"{where}: no CameraInfo for frame {s.frame_id!r} within "
                f"{camera_info_tolerance_ns / 1e6:.0f} ms"
            )
            continue
        try:
            bTc = tree.lookup(base_frame, s.frame_id or info.frame_id, s.stamp_ns)
        except HoloslamError as e:
            miss["missing_transform"] += 1
            problems.append(f"{where}: {e}")
            continue
        try:
            cam = PinholeCamera.from_camera_info(info)
            if side is not None and sized:
                ob = observation_from_pnp(s.stamp_ns, s.object_id, s.payload, s.corners, side, cam, bTc, sigma_px)
                obs.append(replace(ob, source=s.source))
            else:
                sides = np.linalg.norm(s.corners - np.roll(s.corners, -1, axis=0), axis=1)
                b_normal, sigma_n = _view_normal(s.corners, cam, bTc, sigma_px)
                views.append(View(s.stamp_ns, s.object_id, s.payload, _centre(s.corners), cam, bTc, s.source,
                                  s.foreign, float(sides.mean()), b_normal, sigma_n))
                n_foreign += s.foreign
                n_sizeless += not s.foreign
        except VisionError as e:
            miss["pnp_failures"] += 1
            problems.append(f"{where}: {e}")
            continue
        if s.label is not None:
            used.append(s)
    obs.sort(key=lambda o: (o.stamp_ns, o.object_id))
    report = VisionReport(
        **c,
        **miss,
        observations=len(obs),
        object_ids=tuple(sorted({o.object_id for o in obs})),
        foreign_payloads=foreign_payloads,
        problems=tuple(problems),
        views=len(views),
        sizeless=n_sizeless,
        foreign_views=n_foreign,
    )
    return VisionResult(tuple(obs), tuple(views), tuple(used), report)


def observations_from_log(
    log: LogData,
    base_frame: str = "",
    sigma_px: float = DEFAULT_SIGMA_PX,
    source: SightingSource | str = SightingSource.AUTO,
    decoders: tuple[Decoder, ...] | None = None,
    fallback: Fallback | None = None,
    camera_info_tolerance_ns: int = 50_000_000,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[tuple[ObjectObservation, ...], VisionReport]:
    """The PnP observations of :func:`locate_from_log` and its report (labels without a size are reported as
    ``missing_size``: triangulating them needs the trajectory)."""
    r = locate_from_log(log, base_frame, sigma_px, source, decoders, fallback, camera_info_tolerance_ns, progress,
                        triangulate=False)
    return r.observations, r.report


@dataclass(frozen=True, slots=True)
class AcceptedLandmark:
    """An object accepted as a landmark: mean of its consistent sightings, how many agreed, how many in
    all."""

    object_id: str
    position: np.ndarray
    n_consistent: int
    n_sightings: int


def accept_landmarks(
    object_ids: Sequence[str],
    positions: np.ndarray,
    min_decodes: int = DEFAULT_MIN_DECODES,
    radius_m: float = 0.3,
) -> dict[str, AcceptedLandmark]:
    """Accept an object id only after at least ``min_decodes`` sightings whose positions (N, 2 or 3; all in
    one common frame: world or one submap) lie within ``radius_m`` of the component-wise median of that id's
    sightings. Returns the accepted ids with the mean of their consistent positions."""
    if min_decodes < 1:
        raise VisionError(f"min_decodes must be >= 1, got {min_decodes}")
    P = np.asarray(positions, dtype=np.float64)
    ids = np.asarray(list(object_ids), dtype=object)
    if P.ndim != 2 or P.shape[0] != ids.shape[0]:
        raise VisionError(f"accept_landmarks: {ids.shape[0]} ids but positions of shape {P.shape}")
    out: dict[str, AcceptedLandmark] = {}
    for oid in sorted(set(ids.tolist())):
        Q = P[ids == oid]
        Q = Q[np.all(np.isfinite(Q), axis=1)]
        if len(Q) < min_decodes:
            continue
        med = np.median(Q, axis=0)
        inl = np.linalg.norm(Q - med, axis=1) <= radius_m
        if inl.sum() >= min_decodes:
            out[oid] = AcceptedLandmark(oid, Q[inl].mean(axis=0), int(inl.sum()), int(len(Q)))
    return out
