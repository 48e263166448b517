"""Find and decode every QR code in an image: payload text and the four corners in the code's own order
(TL, TR, BR, BL of the printed code: the finder patterns sit at TL, TR and BL) with sub-pixel accuracy.

Decoders (``Decoder``): zxing-cpp (``zxingcpp``), zbar (``pyzbar``, needs the libzbar shared library),
OpenCV's ``QRCodeDetector`` and ``QRCodeDetectorAruco``. Only full-size QR codes are read (Micro QR, rMQR and
other symbologies are disabled, so clutter cannot decode as a tiny code). The default, chosen by measurement
(``benchmarks/bench_vision.py``, 320 rendered VGA views): zxing-cpp and zbar on every image, their codes
merged (``Fallback.ALWAYS``). zxing-cpp alone reads labels with modules >= 3 px under blur, noise, dim light,
gradients, JPEG, tilt up to 60 deg and any rotation, but missed 3 % at 4 px per module and 4 % of the codes
in images holding three; zbar only where zxing-cpp found nothing (``Fallback.IF_EMPTY``, 2.3 ms per image)
cannot recover those, since the image already had a decode. Both always: every label with modules >= 3 px
decoded, three codes per image included, no false decode, corner error 0.04 px median after refinement, ~10 ms
per VGA image (~100 images/s on one core, the goal is 30). On the simulator's household log zxing-cpp alone
read 102 of 104 labels, both 104 of 104.
OpenCV's detectors decoded fewer labels and were slower. Pass ``decoders=`` / ``fallback=`` to change it.

Whatever decoder found a code, its corners are put in the code's order and refined the same way
(``orient_and_refine``):

1. the four corners are made clockwise on screen, then the rotation and the module count N (versions 1-10)
   that best match the fixed pattern (three finder patterns with their separators, the two timing lines)
   sampled through the corner homography are chosen; a code whose pattern does not match is dropped;
2. along the code's four borders, at every dark module next to the quiet zone (finder patterns and dark data
   modules), the 50 % crossing of the intensity profile across the border is found; a total least-squares line
   is fitted per border and the corners are the line intersections (exact under perspective, unbiased under
   symmetric blur). Two passes; if refinement fails or runs away the decoder's oriented corners are kept.

Payloads are untrusted text. A payload that is not UTF-8 or not a holoslam label (``holoslam.vision.label``)
is returned with ``is_label=False`` and the reason in ``error``, never guessed at.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

import numpy as np

from holoslam.errors import PayloadError, VisionError
from holoslam.vision.label import ObjectLabel, parse_label

__all__ = [
    "Decoder",
    "Fallback",
    "QrDetection",
    "DEFAULT_DECODERS",
    "DEFAULT_FALLBACK",
    "decoder_status",
    "detect_qr",
    "decode_image_file",
    "detection_to_json",
    "orient_and_refine",
    "to_gray",
]


class Decoder(StrEnum):
    ZXING = "zxing"
    ZBAR = "zbar"
    OPENCV = "opencv"
    OPENCV_ARUCO = "opencv_aruco"


class Fallback(StrEnum):
    """When the decoders after the first run: never, only when the first found nothing, or always (merged)."""

    NEVER = "never"
    IF_EMPTY = "if_empty"
    ALWAYS = "always"


DEFAULT_DECODERS: tuple[Decoder, ...] = (Decoder.ZXING, Decoder.ZBAR)
DEFAULT_FALLBACK = Fallback.ALWAYS


@dataclass(frozen=True, slots=True)
class QrDetection:
    """One decoded QR code. ``corners`` (4, 2) float64 pixels in the code's order TL, TR, BR, BL;
    ``label`` is the parsed holoslam label or None; ``error`` says why the payload is not a label (foreign
    text, not UTF-8), else None. ``n_modules`` is the code's side in modules (0 if unknown) and ``refined``
    whether the corners were refined on the finder patterns."""

    payload: str
    corners: np.ndarray
    decoder: str
    is_label: bool
    label: ObjectLabel | None = None
    error: str | None = None
    n_modules: int = 0
    refined: bool = False
    raw: bytes = field(default=b"", repr=False, compare=False)

    def __post_init__(self) -> None:
        c = np.ascontiguousarray(np.asarray(self.corners, dtype=np.float64).reshape(4, 2))
        c.setflags(write=False)
        object.__setattr__(self, "corners", c)

    @property
    def foreign(self) -> bool:
        return not self.is_label

    @property
    def centre(self) -> np.ndarray:
        """The code centre in pixels: the intersection of the diagonals (exact under perspective)."""
        return _diagonal_intersection(self.corners)

    @property
    def module_px(self) -> float:
        """Mean module side in pixels (NaN if the module count is unknown)."""
        if not self.n_modules:
            return math.nan
        sides = np.linalg.norm(self.corners - np.roll(self.corners, -1, axis=0), axis=1)
        return float(sides.mean() / self.n_modules)


# ----------------------------------------------------------------------------------------------- backends


def decoder_status() -> dict[str, str | None]:
    """For each decoder, None if it can run here, else a one-line reason (e.g. libzbar missing)."""
    out: dict[str, str | None] = {}
    try:
        import zxingcpp  # noqa: F401

        out[Decoder.ZXING.value] = None
    except ImportError as e:  # pragma: no cover - installed in the project env
        out[Decoder.ZXING.value] = f"zxing-cpp not importable ({e}); pip install zxing-cpp"
    try:
        from pyzbar import pyzbar  # noqa: F401

        out[Decoder.ZBAR.value] = None
    except (ImportError, OSError) as e:  # libzbar0 missing raises ImportError from ctypes
        out[Decoder.ZBAR.value] = f"pyzbar/libzbar not available ({e}); apt install libzbar0"
    import cv2

    out[Decoder.OPENCV.value] = None if hasattr(cv2, "QRCodeDetector") else "cv2.QRCodeDetector missing"
    out[Decoder.OPENCV_ARUCO.value] = (
        None if hasattr(cv2, "QRCodeDetectorAruco") else "cv2.QRCodeDetectorAruco missing"
    )
    return out


def _raw_zxing(gray: np.ndarray) -> list[tuple[bytes, np.ndarray, int]]:
    import zxingcpp

    res = zxingcpp.read_barcodes(
        gray, formats=zxingcpp.BarcodeFormat.QRCode, try_rotate=True, try_downscale=True, try_invert=False
    )
    out = []
    for b in res:
        p = b.position
        c = np.array(
            [
                [p.top_left.x, p.top_left.y],
                [p.top_right.x, p.top_right.y],
                [p.bottom_right.x, p.bottom_right.y],
                [p.bottom_left.x, p.bottom_left.y],
            ],
            float,
        )
        # zxing puts corners on pixel boundaries (pixel centre at +0.5); holoslam uses OpenCV's centres
        c -= 0.5
        try:
            n = 17 + 4 * int(b.extra.get("Version", 0))
        except (TypeError, ValueError, AttributeError):
            n = 0
        out.append((bytes(b.bytes), c, n if n > 17 else 0))
    return out


def _raw_zbar(gray: np.ndarray) -> list[tuple[bytes, np.ndarray, int]]:
    from pyzbar import pyzbar

    res = pyzbar.decode(gray, symbols=[pyzbar.ZBarSymbol.QRCODE])
    out = []
    for r in res:
        poly = np.array([(p.x, p.y) for p in r.polygon], float)
        if poly.shape[0] != 4:
            if poly.shape[0] < 4:
                continue
            import cv2

            hull = cv2.approxPolyDP(poly.astype(np.float32), 2.0, True).reshape(-1, 2)
            if hull.shape[0] != 4:
                continue
            poly = hull.astype(float)
        out.append((bytes(r.data), poly, 0))
    return out


def _raw_opencv(gray: np.ndarray, aruco: bool) -> list[tuple[bytes, np.ndarray, int]]:
    import cv2

    det = cv2.QRCodeDetectorAruco() if aruco else cv2.QRCodeDetector()
    try:
        ok, texts, points, straight = det.detectAndDecodeMulti(gray)
    except cv2.error:  # OpenCV raises on payloads that are not UTF-8: nothing usable from this image
        return []
    if not ok or points is None:
        return []
    out = []
    for i, t in enumerate(texts):
        if not t:
            continue
        n = 0
        if straight is not None and i < len(straight) and straight[i] is not None:
            n = int(np.asarray(straight[i]).shape[0])
        out.append((t.encode("utf-8"), np.asarray(points[i], float).reshape(4, 2), n))
    return out


_BACKENDS = {
    Decoder.ZXING: _raw_zxing,
    Decoder.ZBAR: _raw_zbar,
    Decoder.OPENCV: lambda g: _raw_opencv(g, False),
    Decoder.OPENCV_ARUCO: lambda g: _raw_opencv(g, True),
}


# ------------------------------------------------------------------------------------- corners and refine


def _diagonal_intersection(c: np.ndarray) -> np.ndarray:
    p0, p1, p2, p3 = c
    d1, d2 = p2 - p0, p3 - p1
    A = np.column_stack([d1, -d2])
    if abs(np.linalg.det(A)) < 1e-12:
        return c.mean(axis=0)
    s = np.linalg.solve(A, p1 - p0)[0]
    return p0 + s * d1


def _pattern(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Module centres (M, 2) as (col, row)+0.5 and their expected darkness (M,) for the fixed pattern."""
    pts, dark = [], []
    finder = np.ones((7, 7), bool)
    finder[1:6, 1:6] = False
    finder[2:5, 2:5] = True
    for r0, c0 in ((0, 0), (0, n - 7), (n - 7, 0)):
        rr, cc = np.mgrid[0:7, 0:7]
        pts.append(np.column_stack([cc.ravel() + c0, rr.ravel() + r0]))
        dark.append(finder.ravel())
    # separators (light ring inside the code next to each finder)
    sep = [(7, c) for c in range(8)] + [(r, 7) for r in range(7)]
    sep += [(7, n - 1 - c) for c in range(8)] + [(r, n - 8) for r in range(7)]
    sep += [(n - 8, c) for c in range(8)] + [(n - 1 - r, 7) for r in range(7)]
    sep_a = np.array(sep)
    pts.append(sep_a[:, ::-1])
    dark.append(np.zeros(len(sep), bool))
    k = np.arange(8, n - 8)
    pts.append(np.column_stack([k, np.full_like(k, 6)]))  # timing row 6
    dark.append(k % 2 == 0)
    pts.append(np.column_stack([np.full_like(k, 6), k]))  # timing column 6
    dark.append(k % 2 == 0)
    return np.concatenate(pts).astype(np.float64) + 0.5, np.concatenate(dark)


_PATTERNS = {n: _pattern(n) for n in range(21, 21 + 4 * 10, 4)}


def _finder_corners(n: int) -> np.ndarray:
    """The 12 outer corners of the three finder patterns in module coordinates (col, row)."""
    q = []
    for c0, r0 in ((0, 0), (n - 7, 0), (0, n - 7)):
        q += [(c0, r0), (c0 + 7, r0), (c0 + 7, r0 + 7), (c0, r0 + 7)]
    return np.array(q, np.float64)


def _sample(gray_f: np.ndarray, pts: np.ndarray) -> np.ndarray:
    import cv2

    m = pts.astype(np.float32).reshape(1, -1, 2)
    return cv2.remap(gray_f, m, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).ravel()


def _homography(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.getPerspectiveTransform(src.astype(np.float32), dst.astype(np.float32)).astype(np.float64)


def _apply_h(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    p = np.column_stack([pts, np.ones(len(pts))]) @ H.T
    return p[:, :2] / p[:, 2:3]


def orient_and_refine(
    gray: np.ndarray, corners: np.ndarray, n_modules: int = 0, refine: bool = True, min_agreement: float = 0.8
) -> tuple[np.ndarray, int, bool] | None:
    """Put rough corners (any start, either winding) in the code's order TL, TR, BR, BL by matching the
    finder/timing pattern, find the module count, and refine the corners on the finder patterns.

    Returns ``(corners (4, 2), n_modules, refined)`` or None when no rotation/module count matches at least
    ``min_agreement`` of the fixed pattern (not a QR code where the decoder said)."""

    c = np.asarray(corners, np.float64).reshape(4, 2)
    x, y = c[:, 0], c[:, 1]
    if np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) < 0:  # counter-clockwise on screen: reverse
        c = c[[0, 3, 2, 1]]
    gray_f = gray.astype(np.float32)
    ns = [n_modules] if n_modules in _PATTERNS else list(_PATTERNS)
    best = (-1.0, 0, 0, None)
    for rot in range(4):
        cr = np.roll(c, -rot, axis=0)
        for n in ns:
            pts, dark = _PATTERNS[n]
            H = _homography(np.array([[0, 0], [n, 0], [n, n], [0, n]], float), cr)
            v = _sample(gray_f, _apply_h(H, pts))
            lo, hi = np.percentile(v, (5, 95))
            if hi - lo < 1e-6:
                continue
            agree = float(np.mean((v < 0.5 * (lo + hi)) == dark))
            if agree > best[0]:
                best = (agree, rot, n, H)
    agree, rot, n, H = best
    if H is None or agree < min_agreement:
        return None
    c = np.roll(c, -rot, axis=0)
    if not refine:
        return c, n, False
    mod_px = float(np.mean(np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1)) / n)
    if mod_px < 1.0:
        return c, n, False
    out = c
    for _ in range(2):  # the second pass profiles along the refined homography
        res = _refine_edges(gray_f, H, n)
        if res is None:
            return c, n, False
        out = res
        H = _homography(np.array([[0, 0], [n, 0], [n, n], [0, n]], float), out)
    if (
        np.max(np.linalg.norm(out - c, axis=1)) > 1.5 * mod_px + 2.0
    ):  # refinement ran away: keep the decoder's
        return c, n, False
    return out, n, True


_ACROSS = np.linspace(-0.8, 1.6, 25)  # module units; negative = inside the code


def _refine_edges(gray_f: np.ndarray, H: np.ndarray, n: int) -> np.ndarray | None:
    """Sub-pixel code corners from the code's four border lines: at every dark module along a border (the
    finder patterns and the dark data modules), the 50 % crossing of the intensity profile across the border
    into the quiet zone (unbiased under symmetric blur, insensitive to lighting gradients), a total
    least-squares line per border, corners as line intersections (exact under perspective)."""
    along = (np.arange(n)[:, None] + np.array([0.3, 0.5, 0.7])[None, :]).ravel()
    zero, full = np.zeros_like(along), np.full_like(along, float(n))
    borders = [  # base points on the border, outward normal: top, right, bottom, left
        (np.column_stack([along, zero]), np.array([0.0, -1.0])),
        (np.column_stack([full, along]), np.array([1.0, 0.0])),
        (np.column_stack([along, full]), np.array([0.0, 1.0])),
        (np.column_stack([zero, along]), np.array([-1.0, 0.0])),
    ]
    fpts, fdark = _PATTERNS[n]
    fv = _sample(gray_f, _apply_h(H, fpts))
    g_dark, g_light = np.median(fv[fdark]), np.median(fv[~fdark])
    g_mid = 0.5 * (g_dark + g_light)
    if g_light - g_dark < 8.0:
        return None
    pts_by_line: list[np.ndarray] = []
    for base, nrm in borders:
        prof_m = base[:, None, :] + _ACROSS[None, :, None] * nrm[None, None, :]  # (P, S, 2)
        prof = _sample(gray_f, _apply_h(H, prof_m.reshape(-1, 2))).reshape(len(base), len(_ACROSS))
        dark = np.median(prof[:, _ACROSS < -0.3], axis=1)
        light = np.median(prof[:, _ACROSS > 0.9], axis=1)
        thr = 0.5 * (dark + light)
        good = (dark < g_mid) & (light > g_mid) & (light - dark > 0.4 * (g_light - g_dark))
        above = prof > thr[:, None]
        j = np.argmax(above, axis=1)  # first crossing dark -> light going outwards
        good &= (j > 0) & above[np.arange(len(j)), j]
        j = np.clip(j, 1, len(_ACROSS) - 1)
        rows = np.arange(len(j))
        v0, v1 = prof[rows, j - 1], prof[rows, j]
        frac = np.where(np.abs(v1 - v0) > 1e-9, (thr - v0) / (v1 - v0 + 1e-12), 0.5)
        t = _ACROSS[j - 1] + np.clip(frac, 0, 1) * (_ACROSS[1] - _ACROSS[0])
        good &= np.abs(t) < 0.6
        if good.sum() < 6:
            return None
        pts_by_line.append(_apply_h(H, base[good] + t[good, None] * nrm[None, :]))
    lines = []
    for p in pts_by_line:
        m = p.mean(axis=0)
        _, _, vt = np.linalg.svd(p - m)
        nrm = vt[1]
        lines.append(np.array([nrm[0], nrm[1], -nrm @ m]))  # a x + b y + c = 0
    top, right, bottom, left = lines

    def meet(l1: np.ndarray, l2: np.ndarray) -> np.ndarray:
        x = np.cross(l1, l2)
        return x[:2] / x[2]

    return np.array([meet(top, left), meet(top, right), meet(bottom, right), meet(bottom, left)])


# ------------------------------------------------------------------------------------------- public API


def to_gray(image: np.ndarray) -> np.ndarray:
    """A (H, W) uint8 grey view of a grey, BGR or BGRA uint8 image; raises ``VisionError`` otherwise."""
    import cv2

    a = np.asarray(image)
    if a.dtype != np.uint8:
        raise VisionError(
            f"image dtype is {a.dtype}; QR detection needs uint8 pixels (convert or rescale it)"
        )
    if a.ndim in (2, 3) and (a.shape[0] == 0 or a.shape[1] == 0):
        raise VisionError(f"image shape {a.shape} has no pixels; pass a decoded, non-empty image")
    if a.ndim == 2:
        return a
    if a.ndim == 3 and a.shape[2] == 3:
        return cv2.cvtColor(a, cv2.COLOR_BGR2GRAY)
    if a.ndim == 3 and a.shape[2] == 4:
        return cv2.cvtColor(a, cv2.COLOR_BGRA2GRAY)
    if a.ndim == 3 and a.shape[2] == 1:
        return a[:, :, 0]
    raise VisionError(f"image shape {a.shape} is not (H, W), (H, W, 3) or (H, W, 4)")


def _make_detection(raw: bytes, corners: np.ndarray, decoder: Decoder, n: int, refined: bool) -> QrDetection:
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        return QrDetection(
            raw.decode("utf-8", errors="replace"),
            corners,
            decoder.value,
            False,
            None,
            "payload is not UTF-8 text: not a holoslam label",
            n,
            refined,
            raw,
        )
    try:
        label = parse_label(text)
    except PayloadError as e:
        return QrDetection(text, corners, decoder.value, False, None, str(e), n, refined, raw)
    return QrDetection(text, corners, decoder.value, True, label, None, n, refined, raw)


def _same_code(a: QrDetection, raw: bytes, corners: np.ndarray) -> bool:
    if a.raw != raw:
        return False
    size = float(np.mean(np.linalg.norm(a.corners - np.roll(a.corners, -1, axis=0), axis=1)))
    return float(np.linalg.norm(a.centre - _diagonal_intersection(corners))) < 0.5 * size


def detect_qr(
    image: np.ndarray,
    decoders: tuple[Decoder, ...] | None = None,
    fallback: Fallback | None = None,
    refine: bool = True,
) -> list[QrDetection]:
    """Every QR code in ``image`` (grey or BGR uint8), as ``QrDetection`` records.

    ``decoders`` run in order (default ``DEFAULT_DECODERS``); the ones after the first run according to
    ``fallback`` (default ``DEFAULT_FALLBACK``) and their codes are merged (same payload, same place = one
    code). A decoder that cannot run here (e.g. libzbar missing) is skipped with one ``RuntimeWarning`` naming
    it; the others go on. Codes whose finder pattern does not verify at the decoder's corners are dropped.
    """
    gray = to_gray(image)
    decoders = DEFAULT_DECODERS if decoders is None else tuple(Decoder(d) for d in decoders)
    fallback = DEFAULT_FALLBACK if fallback is None else Fallback(fallback)
    status = decoder_status()
    out: list[QrDetection] = []
    for i, dec in enumerate(decoders):
        if i > 0 and (fallback is Fallback.NEVER or (fallback is Fallback.IF_EMPTY and out)):
            break
        why = status.get(dec.value)
        if why is not None:
            warnings.warn(f"QR decoder {dec.value} skipped: {why}", RuntimeWarning, stacklevel=2)
            continue
        for raw, corners, n in _BACKENDS[dec](gray):
            if any(_same_code(d, raw, corners) for d in out):
                continue
            res = orient_and_refine(gray, corners, n, refine=refine)
            if res is None:
                continue
            c, n2, refined = res
            if any(_same_code(d, raw, c) for d in out):
                continue
            out.append(_make_detection(raw, c, dec, n2, refined))
    return out


def decode_image_file(
    path: str | Path, decoders: tuple[Decoder, ...] | None = None, fallback: Fallback | None = None
) -> list[QrDetection]:
    """Decode the QR codes of one image file (PNG, JPEG, ... anything OpenCV reads); the one call the CLI's
    ``holoslam tags`` makes per file. The file is read by ``holoslam.io.images.read_image_file``.

    Raises ``ImageDecodeError`` naming the file when it cannot be read or is not a decodable image."""
    from holoslam.io.images import read_image_file

    return detect_qr(read_image_file(path, grayscale=True), decoders, fallback)


def detection_to_json(det: QrDetection, image: str | None = None) -> dict:
    """The JSON form the CLI prints: ``{"image", "payload", "corners", "decoder", "label", "foreign",
    "error"}``."""
    label = None
    if det.label is not None:
        label = {"id": det.label.object_id, "type": det.label.kind, "attributes": dict(det.label.attributes)}
    return {
        "image": image,
        "payload": det.payload,
        "corners": [[round(float(x), 3), round(float(y), 3)] for x, y in det.corners],
        "decoder": det.decoder,
        "label": label,
        "foreign": not det.is_label,
        "error": det.error,
    }
