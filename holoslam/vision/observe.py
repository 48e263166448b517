"""Wiring: a log's images (and the tag sightings the robot decoded itself) become object observations.

``observations_from_log(log)`` decodes every image of the log (``holoslam.vision.qr.detect_qr``), takes the
``CameraInfo`` with the image's stamp (nearest within a tolerance) and the base -> camera transform at that
stamp from the log's TF records (``holoslam.frames.TransformTree``), and locates each holoslam label by PnP
with its printed size (label attribute ``s``). Sightings already decoded on the robot (``log.tags``) are used
as they are (PnP from their corners); an image decode of the same label at the same stamp is then skipped as a
duplicate. Nothing is silently lost: a ``VisionReport`` counts images, decodes, foreign codes, rejected
payloads, corrupt images (with their messages) and every reason a sighting gave no observation.

``accept_landmarks`` is the acceptance rule "a landmark only after consistent decodes": an object id is
accepted once at least ``min_decodes`` (default 3) of its sightings, expressed in one common frame, lie within
``radius_m`` (default 0.3 m) of their component-wise median.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from holoslam.errors import HoloslamError, ImageDecodeError, PayloadError, VisionError
from holoslam.types import CameraInfo, LogData, ObjectObservation
from holoslam.vision.camera import PinholeCamera
from holoslam.vision.label import MAGIC, ObjectLabel, parse_label
from holoslam.vision.locate import DEFAULT_SIGMA_PX, observation_from_pnp
from holoslam.vision.qr import Decoder, Fallback, detect_qr

__all__ = [
    "Sighting",
    "VisionReport",
    "AcceptedLandmark",
    "DEFAULT_MIN_DECODES",
    "sightings_from_log",
    "observations_from_log",
    "accept_landmarks",
]

DEFAULT_MIN_DECODES = 3


@dataclass(frozen=True, slots=True)
class Sighting:
    """A holoslam label seen in one image: where its corners are and where they came from ("image": decoded
    here from the pixels, "tags": decoded on the robot). ``image_index`` indexes ``log.images`` (-1 for
    tags)."""

    stamp_ns: int
    frame_id: str
    payload: str
    label: ObjectLabel
    corners: np.ndarray
    source: str
    image_index: int = -1


@dataclass(frozen=True, slots=True)
class VisionReport:
    """What the vision stage made of a log. ``problems`` holds one line per image or sighting that gave
    nothing (corrupt image, missing calibration or transform, label without a size), ``foreign_payloads``
    the distinct texts of codes that are not holoslam labels."""

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

    def summary(self) -> str:
        return (
            f"{self.images} images ({self.images_decoded} with codes, {self.corrupt_images} corrupt), "
            f"{self.decodes} decodes ({self.labels} labels, {self.foreign} foreign, {self.rejected_payloads} "
            f"rejected), {self.tag_sightings} robot tag sightings, {self.observations} observations of "
            f"{len(self.object_ids)} objects"
        )


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


def sightings_from_log(
    log: LogData,
    use_images: bool = True,
    use_tags: bool = True,
    decoders: tuple[Decoder, ...] | None = None,
    fallback: Fallback | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[list[Sighting], dict]:
    """All holoslam-label sightings of a log (decoded images, then robot tag sightings), and counters for
    the report (as a plain dict; ``observations_from_log`` turns it into a ``VisionReport``).
    ``progress(done, total)`` is called with the images decoded so far, about every 2 % of them."""
    c = {
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
    foreign: dict[str, None] = {}
    out: list[Sighting] = []

    def classify(text: str, where: str) -> ObjectLabel | None:
        try:
            return parse_label(text)
        except PayloadError as e:
            if text.startswith(MAGIC + ";"):
                c["rejected_payloads"] += 1
                problems.append(f"{where}: rejected label payload: {e}")
            else:
                c["foreign"] += 1
                foreign.setdefault(_shown(text), None)
            return None

    tag_keys = set()
    if use_tags:
        for t in log.tags:
            c["tag_sightings"] += 1
            label = classify(t.payload, f"tag sighting at {t.stamp_ns} ns")
            if label is None:
                continue
            c["labels"] += 1
            tag_keys.add((t.stamp_ns, label.object_id))
            out.append(Sighting(t.stamp_ns, t.frame_id, t.payload, label, t.corners, "tags"))
    if use_images:
        every = max(1, -(-len(log.images) // 50))  # at most 50 calls
        for idx, im in enumerate(log.images):
            if progress is not None and idx % every == 0:
                progress(idx, len(log.images))
            c["images"] += 1
            where = f"image {idx} ({im.frame_id} at {im.stamp_ns} ns)"
            try:
                pixels = im.decode()
                dets = detect_qr(pixels, decoders, fallback)
            except (ImageDecodeError, VisionError) as e:
                c["corrupt_images"] += 1
                problems.append(f"{where}: {e}")
                continue
            if dets:
                c["images_decoded"] += 1
            for d in dets:
                c["decodes"] += 1
                if d.label is None:
                    if d.payload.startswith(MAGIC + ";") or (d.error and "UTF-8" in d.error):
                        c["rejected_payloads"] += 1
                        problems.append(f"{where}: rejected payload {_shown(d.payload)!r}: {d.error}")
                    else:
                        c["foreign"] += 1
                        foreign.setdefault(_shown(d.payload), None)
                    continue
                if (im.stamp_ns, d.label.object_id) in tag_keys:
                    c["duplicates_skipped"] += 1
                    continue
                c["labels"] += 1
                out.append(Sighting(im.stamp_ns, im.frame_id, d.payload, d.label, d.corners, "image", idx))
    c["problems"] = problems
    c["foreign_payloads"] = tuple(foreign)
    return out, c


def observations_from_log(
    log: LogData,
    base_frame: str = "base_link",
    sigma_px: float = DEFAULT_SIGMA_PX,
    use_images: bool = True,
    use_tags: bool = True,
    decoders: tuple[Decoder, ...] | None = None,
    fallback: Fallback | None = None,
    camera_info_tolerance_ns: int = 50_000_000,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[tuple[ObjectObservation, ...], VisionReport]:
    """Object observations (label centre in ``base_frame`` at each image stamp, with covariance from
    ``sigma_px`` pixel noise) from every image and robot tag sighting of ``log``, plus a ``VisionReport``.
    ``progress(done, total)`` follows the image decoding (see :func:`sightings_from_log`)."""
    from holoslam.frames import TransformTree

    sightings, c = sightings_from_log(log, use_images, use_tags, decoders, fallback, progress)
    problems: list[str] = list(c.pop("problems"))
    foreign_payloads = c.pop("foreign_payloads")
    tree = TransformTree(log.transforms)
    infos = log.camera_infos
    info_stamps = np.array([i.stamp_ns for i in infos], dtype=np.int64)
    miss = {"missing_camera_info": 0, "missing_transform": 0, "missing_size": 0, "pnp_failures": 0}
    obs: list[ObjectObservation] = []
    for s in sightings:
        where = f"{s.source} sighting of {s.label.object_id} at {s.stamp_ns} ns"
        side = s.label.size_m
        if side is None or not side > 0:
            miss["missing_size"] += 1
            problems.append(
                f"{where}: label has no printed size (attribute s=<mm>); cannot locate it from one view"
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
            obs.append(
                observation_from_pnp(
                    s.stamp_ns, s.label.object_id, s.payload, s.corners, side, cam, bTc, sigma_px
                )
            )
        except VisionError as e:
            miss["pnp_failures"] += 1
            problems.append(f"{where}: {e}")
    obs.sort(key=lambda o: (o.stamp_ns, o.object_id))
    report = VisionReport(
        **c,
        **miss,
        observations=len(obs),
        object_ids=tuple(sorted({o.object_id for o in obs})),
        foreign_payloads=foreign_payloads,
        problems=tuple(problems),
    )
    return tuple(obs), report


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
