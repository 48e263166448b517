"""Find and decode every QR code in an image: the decoder's text, the payload bytes and the four corners in
the code's own order (TL, TR, BR, BL of the printed code: the finder patterns sit at TL, TR and BL) with
sub-pixel accuracy where the code allows it.

Decoders (``Decoder``; adapters in ``holoslam.vision.qr_decoders``): zxing-cpp (``zxingcpp``), zbar
(``pyzbar``'s bindings, needs the libzbar shared library), OpenCV's ``QRCodeDetector`` and
``QRCodeDetectorAruco``. The default, chosen by measurement (``benchmarks/bench_vision.py``: rendered VGA
views, the simulator's household log and real phone photos): zxing-cpp and zbar on every image, their codes
merged (``Fallback.ALWAYS``). On rendered labels zxing-cpp alone missed 3 % at 4 px per module and 4 % of
the codes in images holding three, which zbar reads; on real photos zbar reads a few codes zxing-cpp does not.

Every code a decoder reads is kept: an error-corrected payload is evidence on its own. Codes found by two
decoders at the same place are one code; the earlier decoder's reading is kept (zxing-cpp first: it applies
ECI designators and guesses Shift-JIS the way the QR standard's readers do, where zbar may not). A code only
zbar read whose bytes are neither ASCII nor UTF-8 (zbar guessed their character set) is read again by
zxing-cpp from an upright crop of the place zbar found, and zxing-cpp's text is used when it can read it;
otherwise zbar's text is kept with ``text_guessed`` set. The text is the decoder's own (``payload``), the
payload bytes are kept (``raw``), and ``content`` says whether the payload is text or binary.

Corners (``orient_and_refine``), whatever decoder found the code:

1. the rotation and module count N that best match the fixed pattern (three finder patterns with their
   separators, the two timing lines) sampled through the corner homography are chosen (zxing-cpp and zbar
   report the code's order and zxing-cpp the version, so only what is unknown is searched; OpenCV's corners
   are tried in every rotation and winding). When the pattern matches (``verified``),
2. along the code's four borders, at every dark module next to the quiet zone (finder patterns and dark data
   modules), the 50 % crossing of the intensity profile across the border is found; a total least-squares line
   is fitted per border and the corners are the line intersections (exact under perspective, unbiased under
   symmetric blur). Two passes; if refinement fails or runs away the decoder's corners are kept.

A code whose pattern does not verify at the decoder's corners (large codes at about one pixel per module, a
damaged finder) is kept with the decoder's corners, ``verified`` and ``refined`` false.

Payloads are untrusted text. A payload that is not a holoslam label (``holoslam.vision.label``) is returned
with ``is_label=False`` and the reason in ``error``, never guessed at.
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from holoslam.errors import PayloadError, VisionError
from holoslam.vision.label import ObjectLabel, parse_label
from holoslam.vision.qr_decoders import (
    RawCode,
    read_opencv,
    read_zbar,
    read_zxing,
    zxing_on_quad,
)
from holoslam.vision.qr_decoders import decoder_status as decoder_status

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
    """One decoded QR code. ``payload`` is the decoder's text, ``raw`` the payload bytes, ``content`` what
    they are ("text", "binary", "mixed", "gs1", ...: zxing-cpp's content type; "text" for other decoders);
    ``corners`` (4, 2) float64 pixels in the code's order TL, TR, BR, BL; ``label`` is the parsed holoslam
    label or None; ``error`` says why the payload is not a label (foreign text), else None. ``n_modules`` is
    the code's side in modules (0 if unknown); ``verified`` whether the fixed pattern matched at the corners
    (orientation and module count checked), ``refined`` whether the corners were then refined on the code's
    borders; ``text_guessed`` whether the decoder had to guess the character set of bytes that are neither
    ASCII nor UTF-8 (the text may be wrong; ``raw`` is exact)."""

    payload: str
    corners: np.ndarray
    decoder: str
    is_label: bool
    label: ObjectLabel | None = None
    error: str | None = None
    n_modules: int = 0
    refined: bool = False
    raw: bytes = field(default=b"", repr=False, compare=False)
    content: str = "text"
    verified: bool = False
    text_guessed: bool = False

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


_BACKENDS = {
    Decoder.ZXING: read_zxing,
    Decoder.ZBAR: read_zbar,
    Decoder.OPENCV: lambda g: read_opencv(g, False),
    Decoder.OPENCV_ARUCO: lambda g: read_opencv(g, True),
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


MODULE_COUNTS = tuple(range(21, 178, 4))  # versions 1-40


@functools.cache
def _fixed_pattern(n: int) -> tuple[np.ndarray, np.ndarray]:
    return _pattern(n)


def _finder_corners(n: int) -> np.ndarray:
    """The 12 outer corners of the three finder patterns in module coordinates (col, row)."""
    q = []
    for c0, r0 in ((0, 0), (n - 7, 0), (0, n - 7)):
        q += [(c0, r0), (c0 + 7, r0), (c0 + 7, r0 + 7), (c0, r0 + 7)]
    return np.array(q, np.float64)


def _sample(gray_f: np.ndarray, pts: np.ndarray) -> np.ndarray:
    import cv2

    n = len(pts)
    if n == 0:
        return np.zeros(0, np.float32)
    width = 1024  # the map as rows of this many points: OpenCV's remap takes fewer than 32767 columns
    m = np.zeros((-(-n // width) * width, 2), np.float32)
    m[:n] = pts
    # map2 None: one float map of (x, y) pairs, as OpenCV documents (the stub requires an array)
    out = cv2.remap(gray_f, m.reshape(-1, width, 2), None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)  # type: ignore[call-overload, unused-ignore]
    return out.ravel()[:n]


def _homography(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.getPerspectiveTransform(src.astype(np.float32), dst.astype(np.float32)).astype(np.float64)


def _apply_h(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    p = np.column_stack([pts, np.ones(len(pts))]) @ H.T
    return p[:, :2] / p[:, 2:3]


def orient_and_refine(
    gray: np.ndarray,
    corners: np.ndarray,
    n_modules: int = 0,
    refine: bool = True,
    min_agreement: float = 0.8,
    ordered: bool = False,
) -> tuple[np.ndarray, int, bool] | None:
    """Put rough corners in the code's order TL, TR, BR, BL by matching the finder/timing pattern, find the
    module count, and refine the corners on the code's borders. ``ordered``: the corners are already in the
    code's order (zxing-cpp, zbar), so only the module count is searched (when ``n_modules`` is 0); else any
    start and either winding is tried.

    Returns ``(corners (4, 2), n_modules, refined)`` or None when no rotation/module count matches at least
    ``min_agreement`` of the fixed pattern (not verifiable at these corners)."""

    c = np.asarray(corners, np.float64).reshape(4, 2)
    if not ordered:
        x, y = c[:, 0], c[:, 1]
        if np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) < 0:  # counter-clockwise on screen: reverse
            c = c[[0, 3, 2, 1]]
    if not np.all(np.isfinite(c)):
        return None
    # work on the code's neighbourhood only (the profiles reach 1.6 modules outside the code)
    side = float(np.max(np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1)))
    pad = 0.3 * side + 4.0
    h, w = gray.shape[:2]
    x0, y0 = (max(0, int(np.floor(v))) for v in c.min(axis=0) - pad)
    x1, y1 = int(min(w, np.ceil(c[:, 0].max() + pad) + 1)), int(min(h, np.ceil(c[:, 1].max() + pad) + 1))
    if x1 - x0 < 4 or y1 - y0 < 4:
        return None
    off = np.array([x0, y0], np.float64)
    res = _orient_and_refine(gray[y0:y1, x0:x1].astype(np.float32), c - off, n_modules, refine,
                             min_agreement, ordered)
    if res is None:
        return None
    return res[0] + off, res[1], res[2]


def _orient_and_refine(gray_f: np.ndarray, c: np.ndarray, n_modules: int, refine: bool, min_agreement: float,
                       ordered: bool) -> tuple[np.ndarray, int, bool] | None:
    ns = [n_modules] if n_modules in MODULE_COUNTS else list(MODULE_COUNTS)
    best: tuple[float, int, int, np.ndarray | None] = (-1.0, 0, 0, None)
    for rot in range(1 if ordered else 4):
        cr = np.roll(c, -rot, axis=0)
        for n in ns:
            pts, dark = _fixed_pattern(n)
            Hn = _homography(np.array([[0, 0], [n, 0], [n, n], [0, n]], float), cr)
            v = _sample(gray_f, _apply_h(Hn, pts))
            srt = np.sort(v)  # 5th and 95th percentiles (np.percentile costs 20x more per call)
            lo, hi = srt[int(0.05 * (len(srt) - 1))], srt[int(0.95 * (len(srt) - 1))]
            if hi - lo < 1e-6:
                continue
            agree = float(np.mean((v < 0.5 * (lo + hi)) == dark))
            if agree > best[0]:
                best = (agree, rot, n, Hn)
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
    # base points on the border and outward normals, the four borders at once: top, right, bottom, left
    base = np.stack([np.column_stack([along, zero]), np.column_stack([full, along]),
                     np.column_stack([along, full]), np.column_stack([zero, along])])  # (4, P, 2)
    nrm = np.array([[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])
    fpts, fdark = _fixed_pattern(n)
    fv = _sample(gray_f, _apply_h(H, fpts))
    g_dark, g_light = np.median(fv[fdark]), np.median(fv[~fdark])
    g_mid = 0.5 * (g_dark + g_light)
    if g_light - g_dark < 8.0:
        return None
    P, S = base.shape[1], len(_ACROSS)
    prof_m = base[:, :, None, :] + _ACROSS[None, None, :, None] * nrm[:, None, None, :]  # (4, P, S, 2)
    prof = _sample(gray_f, _apply_h(H, prof_m.reshape(-1, 2))).reshape(4 * P, S)
    dark = np.median(prof[:, _ACROSS < -0.3], axis=1)
    light = np.median(prof[:, _ACROSS > 0.9], axis=1)
    thr = 0.5 * (dark + light)
    good = (dark < g_mid) & (light > g_mid) & (light - dark > 0.4 * (g_light - g_dark))
    above = prof > thr[:, None]
    j = np.argmax(above, axis=1)  # first crossing dark -> light going outwards
    rows = np.arange(len(j))
    good &= (j > 0) & above[rows, j]
    j = np.clip(j, 1, S - 1)
    v0, v1 = prof[rows, j - 1], prof[rows, j]
    frac = np.where(np.abs(v1 - v0) > 1e-9, (thr - v0) / (v1 - v0 + 1e-12), 0.5)
    t = _ACROSS[j - 1] + np.clip(frac, 0, 1) * (_ACROSS[1] - _ACROSS[0])
    good = (good & (np.abs(t) < 0.6)).reshape(4, P)
    if np.any(good.sum(axis=1) < 6):
        return None
    t = t.reshape(4, P)
    pts_by_line = [_apply_h(H, base[k][good[k]] + t[k, good[k], None] * nrm[k][None, :]) for k in range(4)]
    lines = []
    for p in pts_by_line:
        m = p.mean(axis=0)
        _, _, vt = np.linalg.svd(p - m)
        u = vt[1]
        lines.append((float(u[0]), float(u[1]), float(-u @ m)))  # a x + b y + c = 0
    top, right, bottom, left = lines

    def meet(l1: tuple[float, float, float], l2: tuple[float, float, float]) -> list[float]:
        # the cross product (np.cross's arithmetic, on floats)
        x0, x1, x2 = l1[1] * l2[2] - l1[2] * l2[1], l1[2] * l2[0] - l1[0] * l2[2], l1[0] * l2[1] - l1[1] * l2[0]
        return [x0 / x2, x1 / x2]

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


def _make_detection(code: RawCode, corners: np.ndarray, decoder: str, n: int, refined: bool,
                    verified: bool) -> QrDetection:
    common: dict[str, Any] = dict(n_modules=n, refined=refined, raw=code.raw, content=code.content, verified=verified,
                  text_guessed=code.text_guessed)
    try:
        label = parse_label(code.text)
    except PayloadError as e:
        return QrDetection(code.text, corners, decoder, False, None, str(e), **common)
    return QrDetection(code.text, corners, decoder, True, label, None, **common)


def _clockwise(c: np.ndarray) -> np.ndarray:
    x, y = c[:, 0], c[:, 1]
    return c[[0, 3, 2, 1]] if np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) < 0 else c


def _same_place(a: np.ndarray, b: np.ndarray) -> bool:
    """Two decoders' quadrilaterals of one code: either centre lies inside the other quadrilateral."""
    import cv2

    for p, q in ((a, b), (b, a)):
        ctr = _diagonal_intersection(q)
        if np.all(np.isfinite(ctr)) and cv2.pointPolygonTest(p.astype(np.float32).reshape(-1, 1, 2),
                                                              (float(ctr[0]), float(ctr[1])), False) >= 0:
            return True
    return False


def detect_qr(
    image: np.ndarray,
    decoders: tuple[Decoder, ...] | None = None,
    fallback: Fallback | None = None,
    refine: bool = True,
) -> list[QrDetection]:
    """Every QR code in ``image`` (grey or BGR uint8) that a decoder reads, as ``QrDetection`` records.

    ``decoders`` run in order (default ``DEFAULT_DECODERS``); the ones after the first run according to
    ``fallback`` (default ``DEFAULT_FALLBACK``) and their codes are merged (the same place = one code; the
    earlier decoder's reading is kept). A decoder that cannot run here (e.g. libzbar missing) is skipped with
    one ``RuntimeWarning`` naming it; the others go on. A code found by a decoder other than zxing-cpp whose
    text was guessed is read again by zxing-cpp (when it is among ``decoders``) from an upright crop."""
    gray = to_gray(image)
    decoders = DEFAULT_DECODERS if decoders is None else tuple(Decoder(d) for d in decoders)
    fallback = DEFAULT_FALLBACK if fallback is None else Fallback(fallback)
    status = decoder_status()
    zxing_here = Decoder.ZXING in decoders and status.get(Decoder.ZXING.value) is None
    out: list[QrDetection] = []
    for i, dec in enumerate(decoders):
        if i > 0 and (fallback is Fallback.NEVER or (fallback is Fallback.IF_EMPTY and out)):
            break
        why = status.get(dec.value)
        if why is not None:
            warnings.warn(f"QR decoder {dec.value} skipped: {why}", RuntimeWarning, stacklevel=2)
            continue
        for code in _BACKENDS[dec](gray):
            if not np.all(np.isfinite(code.corners)):
                continue
            if any(_same_place(d.corners, code.corners) for d in out):
                continue
            name = dec.value
            if dec is not Decoder.ZXING and zxing_here and (code.text_guessed or not code.n_modules):
                # zxing-cpp missed it in the whole image; on an upright crop it may read it (its text, the
                # version, the code's order)
                again = zxing_on_quad(gray, code.corners if code.ordered else _clockwise(code.corners))
                if again is not None and (again.raw == code.raw or code.text_guessed):
                    code, name = again, f"{dec.value}+{Decoder.ZXING.value}"
            res = orient_and_refine(gray, code.corners, code.n_modules, refine=refine, ordered=code.ordered)
            if res is None:  # not verifiable here (about 1 px per module, damaged finder): the decode stands
                c = code.corners if code.ordered else _clockwise(code.corners)
                out.append(_make_detection(code, c, name, code.n_modules, False, False))
            else:
                c, n, refined = res
                out.append(_make_detection(code, c, name, n, refined, True))
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
    """The JSON form the CLI prints: ``{"image", "payload", "corners", "decoder", "label", "foreign", "error",
    "content", "raw_hex", "text_guessed", "n_modules", "verified", "refined"}``; ``raw_hex`` holds the payload
    bytes when they are not plain text (``content`` other than "text", or a guessed character set), else
    None."""
    label = None
    if det.label is not None:
        label = {"id": det.label.object_id, "type": det.label.kind, "attributes": dict(det.label.attributes)}
    exact_text = det.content == "text" and not det.text_guessed
    return {
        "image": image,
        "payload": det.payload,
        "corners": [[round(float(x), 3), round(float(y), 3)] for x, y in det.corners],
        "decoder": det.decoder,
        "label": label,
        "foreign": not det.is_label,
        "error": det.error,
        "content": det.content,
        "raw_hex": None if exact_text else det.raw.hex(),
        "text_guessed": det.text_guessed,
        "n_modules": det.n_modules,
        "verified": det.verified,
        "refined": det.refined,
    }
