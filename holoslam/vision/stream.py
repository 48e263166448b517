"""Vision on a camera stream: fast where there is nothing to find, careful where there is.

A robot's camera topic runs at 10-30 frames a second and most frames show no code; the full decode
(``holoslam.vision.qr.detect_qr``: zxing-cpp and zbar on every image, corners oriented and refined) costs
5-15 ms a frame, most of it zbar's scan, whether or not the frame holds a code. ``FrameDecoder`` puts two
cheap steps in front of it, frame by frame in stream order:

1. **Can this frame hold a code?** (``quick_look``) The frame is decoded to grey only (``decode_gray``; a JPEG's
   luma plane, without colour) and zxing-cpp's fast path runs on it and on a half-size copy (no rotation,
   downscale pyramid or inversion tried; ``return_errors``: a symbol whose three finder patterns were found but
   whose data did not decode counts too, so a blurred or partly read code still passes). Chosen by measurement
   (``benchmarks/bench_vision.py``, stream section; simulated 600 s at 15 fps): the full decode costs 5-15 ms
   a frame, zbar's scan most of it; the quick look takes 0.75 ms (CPU) on a frame without a code (1333 such
   frames a second through the vision stage) and rejected 10 of the 1737 frames the full decode read a label
   in (5.8 per thousand; every object was read in neighbouring frames). The half-size pass is there for
   blurred codes: zxing-cpp's downscale pyramid, which the fast path leaves out, is what read some of the
   frames the full-size pass rejected (a blur of a few pixels is about one pixel at half size). Rendered labels (``holoslam.sim.label_views``, 3-5 px per
   module, motion blur up to 1.5 modules, JPEG): every one the full decode read passed. Real photos (zxing's
   black-box sets in ``../shared/qr``, which flatter zxing-cpp): 95 of the 97 with a code passed (the full
   decode reads the same 95), 25 of 25 without a code rejected. A frame that fails is not decoded
   (``skipped_no_code``).
2. **Is it the view already decoded?** A frame whose camera pose (the odometry interpolated at its stamp times
   the log's base -> camera transform, in the odometry frame) lies within ``same_view_m`` and ``same_view_deg``
   of the last frame decoded in full, with the same intrinsics (zoom), at most ``same_view_max_s`` later, and
   whose quick look read the same payloads (at least one), adds nothing to that frame's sightings and is not
   decoded again (``skipped_same_view``), once the view has been decoded in full ``decodes_per_view`` times.
   Without odometry or a transform the frame is decoded.

Every other frame is decoded in full (``full_decodes``) from the same pixels as without these steps
(``Image.decode``): every decoder, merged, corners oriented and refined; except that when the quick look read
every symbol it found (``first_decoder_when_read``), only the first decoder (zxing-cpp) reads the frame again
(zbar, the second, reads codes zxing-cpp misses: those zxing-cpp's fast path finds but cannot read, and then
zbar runs). A log whose frames all hold codes far apart (operator snapshots: the bundled household log) gives
the same sightings as before. ``StreamSettings`` holds the switches and thresholds (the run configuration's ``vision``
section sets them); ``frames_per_second`` wraps a stage's progress callback so that it reports frames per
second.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from holoslam.errors import ConfigError, HoloslamError, ImageDecodeError
from holoslam.types import Image, LogData

__all__ = [
    "StreamSettings",
    "StreamCounts",
    "FrameDecoder",
    "QuickLook",
    "decode_gray",
    "quick_look",
    "frames_per_second",
]


@dataclass(frozen=True)
class StreamSettings:
    """How the vision stage walks a camera stream (see the module docstring).

    ``same_view_m`` (m) and ``same_view_deg`` (deg): a frame whose camera moved less than this since the last
    frame decoded in full is the same view. 5 cm is one cell of the map grid (``grid.resolution``): the map
    cannot tell the two camera positions apart, and the odometry over such a step is exact to about a
    millimetre (a 1.5 % scale error). 1 deg is twice the pointing repeatability of a PTZ head (0.5 deg) and
    moves a code in the image by at most 1/60 of a 60 deg field of view at zoom 1. ``same_view_max_s`` (s): a
    view is decoded again at least this often while it lasts, so a label the robot keeps looking at gets
    independent decodes (a payload is confirmed by a second sighting, ``maps.holographic.CONFIRMING_SIGHTINGS``)
    and a slow odometry drift cannot chain skips; one second is under the time a person-paced robot spends
    looking at an object (it turns toward it at up to 35 deg/s and stops). ``decodes_per_view``: a view is
    decoded in full this many times before its repeats are skipped; 2 = the sightings that confirm a payload
    (``maps.holographic.CONFIRMING_SIGHTINGS``), so an object seen in one view only is still confirmed.
    ``first_decoder_when_read``: a frame whose quick look read every symbol it found is decoded by the first
    decoder only (saves zbar's scan of the whole frame, about half of a full decode).

    Chosen by measurement (``benchmarks/bench_vision.py`` stream section; simulated 600 s at 15 fps, 34
    objects, object RMSE after the front end and solve): decoding every frame in full 7.2 mm; 5 cm / 1 deg
    6.5 mm with 1090 full decodes; 10 cm / 2 deg 6.8 mm (829); 20 cm / 5 deg / 2 s 7.6 mm (528), worse than
    decoding every frame. No object was lost by any of them."""

    prefilter: bool = True
    skip_same_view: bool = True
    same_view_m: float = 0.05
    same_view_deg: float = 1.0
    same_view_max_s: float = 1.0
    decodes_per_view: int = 2
    first_decoder_when_read: bool = True

    def __post_init__(self) -> None:
        if not (isinstance(self.decodes_per_view, int) and self.decodes_per_view >= 1):
            raise ConfigError(f"vision.decodes_per_view = {self.decodes_per_view!r}: expected an integer >= 1")
        for name in ("same_view_m", "same_view_deg", "same_view_max_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"vision.{name} = {v!r}: expected a finite number >= 0")


@dataclass
class StreamCounts:
    """What ``FrameDecoder`` did: frames seen, frames the quick look found no code in, frames skipped as the
    view already decoded, frames decoded in full, and the seconds (wall) spent."""

    frames: int = 0
    skipped_no_code: int = 0
    skipped_same_view: int = 0
    full_decodes: int = 0
    seconds: float = 0.0

    @property
    def frames_per_s(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else float("nan")

    def for_report(self) -> dict[str, int | float]:
        """The counts ``VisionReport`` carries (frames are its ``images``)."""
        return {"full_decodes": self.full_decodes, "skipped_no_code": self.skipped_no_code,
                "skipped_same_view": self.skipped_same_view, "frames_per_s": round(self.frames_per_s, 1)}


@dataclass(frozen=True)
class QuickLook:
    """The quick look's verdict on one frame: whether it can hold a code and the payloads it already read."""

    candidate: bool
    payloads: frozenset[str] = field(default_factory=frozenset)
    unread: int = 0  # symbols whose finder patterns were found but whose data did not decode

    @property
    def all_read(self) -> bool:
        """Every symbol the quick look found was read (and it found at least one)."""
        return bool(self.payloads) and self.unread == 0


def decode_gray(image: Image) -> np.ndarray:
    """The grey pixels (H, W) uint8 of ``image``: a compressed frame decoded to grey directly (a JPEG's luma
    plane, without colour conversion), any other through ``Image.decode``. Raises ``ImageDecodeError``."""
    import cv2

    from holoslam.io.images import _compressed_kind
    from holoslam.vision.qr import to_gray

    if _compressed_kind(image.encoding.strip().lower()) is not None and image.data:
        try:
            g = cv2.imdecode(np.frombuffer(image.data, np.uint8), cv2.IMREAD_GRAYSCALE)
        except cv2.error:
            g = None
        if g is not None:
            return g
    px = image.decode()
    if px.dtype != np.uint8:
        raise ImageDecodeError(f"image at {image.stamp_ns} ns is {px.dtype}; QR codes need 8-bit pixels")
    return to_gray(px)


def quick_look(gray: np.ndarray) -> QuickLook:
    """zxing-cpp's fast path on ``gray`` and on a half-size copy (module docstring, step 1). Without zxing-cpp
    every frame is a candidate (decoded in full, as without the quick look)."""
    import cv2

    try:
        import zxingcpp
    except ImportError:  # no fast path here: every frame goes to the full decode, which says what is missing
        return QuickLook(True)
    fmt = zxingcpp.BarcodeFormat.QRCode
    small = {getattr(zxingcpp.BarcodeFormat, n) for n in ("MicroQRCode", "RMQRCode")
             if hasattr(zxingcpp.BarcodeFormat, n)}
    found = []
    half = cv2.resize(gray, (gray.shape[1] // 2, gray.shape[0] // 2), interpolation=cv2.INTER_AREA)
    for g in (gray, half):
        # one BarcodeFormat converts to the stub's BarcodeFormats (zxing-cpp 2 has no such class to build it with)
        res = zxingcpp.read_barcodes(g, formats=fmt,  # type: ignore[arg-type]
                                     try_rotate=False, try_downscale=False, try_invert=False,
                                     text_mode=zxingcpp.TextMode.Plain, return_errors=True)
        found += [b for b in res if b.format not in small]
        if any(b.valid for b in found):
            break
    return QuickLook(bool(found), frozenset(b.text for b in found if b.valid), sum(not b.valid for b in found))


def _rotation_deg(R1: np.ndarray, R2: np.ndarray) -> float:
    c = (np.trace(R1.T @ R2) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


class FrameDecoder:
    """Decodes a log's frames in stream order with the quick look and the same-view skip in front of the full
    decode (module docstring). ``decode(index, image)`` returns the frame's detections, or an empty list for a
    skipped frame; ``counts`` says what was done."""

    def __init__(self, log: LogData, settings: StreamSettings, base_frame: str,
                 full_decode: Callable[[np.ndarray, bool], list]) -> None:
        self.settings = settings
        self.counts = StreamCounts()
        self._full = full_decode
        self._base = base_frame or log.base_frame
        self._tree = None
        self._stamps: np.ndarray = np.zeros(0, np.int64)
        self._odom: np.ndarray | None = None
        if log.odometry:
            self._stamps, self._odom = log.odometry_arrays()
        self._infos = log.camera_infos
        self._info_stamps = np.array([i.stamp_ns for i in self._infos], np.int64)
        self._key: tuple[int, np.ndarray, float, frozenset[str]] | None = None
        self._key_decodes = 0  # full decodes of the key view so far
        self._t0 = time.perf_counter()
        if settings.skip_same_view and self._odom is not None and len(self._stamps) >= 2:
            from holoslam.frames import TransformTree

            self._tree = TransformTree(log.transforms)
            self._theta = np.unwrap(self._odom[:, 2])

    def _camera_pose(self, image: Image) -> tuple[np.ndarray, float] | None:
        """(odomTc 4x4, focal length px) at the frame's stamp, or None when the odometry does not cover it or
        the transform is missing."""
        t, odom = image.stamp_ns, self._odom
        if self._tree is None or odom is None or not (self._stamps[0] <= t <= self._stamps[-1]):
            return None
        x, y = (float(np.interp(t, self._stamps, odom[:, k])) for k in (0, 1))
        th = float(np.interp(t, self._stamps, self._theta))
        try:
            bTc = self._tree.lookup(self._base, image.frame_id, t)
        except HoloslamError:
            return None
        c, s = math.cos(th), math.sin(th)
        oTb = np.array([[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, 0], [0, 0, 0, 1.0]])
        fx = float("nan")
        if len(self._infos):
            j = int(np.clip(np.searchsorted(self._info_stamps, t), 0, len(self._infos) - 1))
            if j > 0 and abs(self._info_stamps[j - 1] - t) < abs(self._info_stamps[j] - t):
                j -= 1
            fx = float(self._infos[j].K[0, 0])
        return oTb @ bTc, fx

    def _same_view(self, image: Image, pose: tuple[np.ndarray, float] | None, payloads: frozenset[str]) -> bool:
        if self._key is None or pose is None or not payloads:
            return False
        st = self.settings
        k_stamp, k_pose, k_fx, k_payloads = self._key
        T, fx = pose
        return (
            payloads == k_payloads
            and 0 <= image.stamp_ns - k_stamp <= st.same_view_max_s * 1e9
            and (math.isnan(fx) and math.isnan(k_fx) or abs(fx - k_fx) <= 0.01 * k_fx)
            and float(np.linalg.norm(T[:3, 3] - k_pose[:3, 3])) <= st.same_view_m
            and _rotation_deg(T[:3, :3], k_pose[:3, :3]) <= st.same_view_deg
        )

    def decode(self, index: int, image: Image) -> list:
        """The detections of frame ``index`` (raises ``ImageDecodeError`` / ``VisionError`` as the full decode
        does)."""
        c = self.counts
        c.frames += 1
        try:
            if not self.settings.prefilter:
                c.full_decodes += 1
                return self._full(image.decode(), True)
            look = quick_look(decode_gray(image))
            if not look.candidate:
                c.skipped_no_code += 1
                return []
            pose = self._camera_pose(image) if self._tree is not None else None
            same = self.settings.skip_same_view and self._same_view(image, pose, look.payloads)
            if same and self._key_decodes >= self.settings.decodes_per_view:
                c.skipped_same_view += 1
                return []
            c.full_decodes += 1
            dets = self._full(image.decode(), not (self.settings.first_decoder_when_read and look.all_read))
            if dets and look.payloads and pose is not None:
                if same:
                    self._key_decodes += 1
                else:
                    self._key, self._key_decodes = (image.stamp_ns, pose[0], pose[1], look.payloads), 1
            return dets
        finally:
            c.seconds = time.perf_counter() - self._t0


def frames_per_second(progress: Callable[..., None], stage: str) -> Callable[[int, int], None]:
    """A ``(done, total)`` progress callback for a stage that goes through frames: it calls
    ``progress("<stage> (<n> frames/s)", done, total)`` with the frames per second (wall) so far."""
    t0 = time.perf_counter()

    def report(done: int, total: int) -> None:
        dt = time.perf_counter() - t0
        name = f"{stage} ({done / dt:.0f} frames/s)" if done and dt > 0 else stage
        progress(name, done, total)

    return report
