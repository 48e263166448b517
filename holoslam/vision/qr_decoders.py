"""Adapters to the QR decoders holoslam wraps: each turns one decoder's results into ``RawCode`` records
(the decoder's own text, the payload bytes, four corners and what the decoder knows of the code).

- zxing-cpp (``zxingcpp``): text as zxing-cpp transcodes it (``TextMode.Plain``: ECI designators applied,
  Shift-JIS / Kanji and the other character sets guessed the way zxing does), the payload bytes, the version
  (so the module count) and the corners in the code's order TL, TR, BR, BL.
- zbar (through ``pyzbar``'s ctypes bindings; needs the libzbar shared library): read twice when needed. In
  binary mode (``ZBAR_CFG_BINARY``, zbar >= 0.23.1) zbar hands over the payload bytes; its text mode is
  asked only when those bytes are not ASCII. zbar's text is exact for ASCII and UTF-8 (and under an ECI),
  but for other bytes it guesses among legacy character sets (Debian's zbar tries Big5 before Shift-JIS: a
  Japanese payload comes out as Chinese). Such a text is marked ``text_guessed``; ``holoslam.vision.qr``
  then asks zxing-cpp to read the code again from a rectified crop and uses its text when it can. zbar's
  four points are the code's TL, BL, BR, TR; they are returned in the code's order.
- OpenCV (``QRCodeDetector``, ``QRCodeDetectorAruco``): UTF-8 text only (OpenCV raises on other payloads).

Only full-size QR codes are read (Micro QR, rMQR and other symbologies are disabled, so clutter cannot decode
as a tiny code).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["RawCode", "decoder_status", "read_zxing", "read_zbar", "read_opencv", "zxing_on_quad"]

_ZBAR_CFG_BINARY = 4  # zbar.h: ZBAR_CFG_ENABLE 0, ADD_CHECK, EMIT_CHECK, ASCII, BINARY (since 0.23.1), NUM


@dataclass(frozen=True, slots=True)
class RawCode:
    """One code as a decoder returned it. ``corners`` (4, 2) pixels (OpenCV convention: pixel centres at
    integers), in the code's order TL, TR, BR, BL when ``ordered``; ``n_modules`` the side in modules (0:
    unknown); ``content`` what the decoder says the payload is (text, binary, mixed, gs1, iso15434,
    unknown_eci); ``text_guessed`` whether the decoder guessed the character set of bytes that are neither
    ASCII nor UTF-8 without an ECI telling it (the text may then be wrong; ``raw`` holds the bytes)."""

    text: str
    raw: bytes
    corners: np.ndarray
    n_modules: int = 0
    ordered: bool = False
    content: str = "text"
    text_guessed: bool = False
    extra: dict = field(default_factory=dict, compare=False)


def decoder_status() -> dict[str, str | None]:
    """For each decoder (zxing, zbar, opencv, opencv_aruco), None if it can run here, else a one-line reason
    (e.g. libzbar missing)."""
    out: dict[str, str | None] = {}
    try:
        import zxingcpp  # noqa: F401

        out["zxing"] = None
    except ImportError as e:  # pragma: no cover - installed in the project env
        out["zxing"] = f"zxing-cpp not importable ({e}); pip install zxing-cpp"
    try:
        from pyzbar import pyzbar  # noqa: F401

        out["zbar"] = None
    except (ImportError, OSError) as e:  # libzbar0 missing raises ImportError from ctypes
        out["zbar"] = f"pyzbar/libzbar not available ({e}); apt install libzbar0"
    import cv2

    out["opencv"] = None if hasattr(cv2, "QRCodeDetector") else "cv2.QRCodeDetector missing"
    out["opencv_aruco"] = None if hasattr(cv2, "QRCodeDetectorAruco") else "cv2.QRCodeDetectorAruco missing"
    return out


# ----------------------------------------------------------------------------------------------- zxing-cpp

_CONTENT = {
    "Text": "text",
    "Binary": "binary",
    "Mixed": "mixed",
    "GS1": "gs1",
    "ISO15434": "iso15434",
    "UnknownECI": "unknown_eci",
}


def read_zxing(gray: np.ndarray, pure: bool = False) -> list[RawCode]:
    """zxing-cpp on a grey image (QR codes only, any rotation, downscaled pyramids and inverted codes tried).
    ``pure``: the image holds nothing but one upright code (a rectified crop)."""
    import zxingcpp

    F = zxingcpp.BarcodeFormat
    small = {getattr(F, name) for name in ("MicroQRCode", "RMQRCode") if hasattr(F, name)}
    res = zxingcpp.read_barcodes(
        gray,
        # zxing-cpp 3: the QR family, Micro QR and rMQR included (dropped below); one BarcodeFormat converts
        # to the BarcodeFormats the stub names (zxing-cpp 2 has no such class to build it with)
        formats=F.QRCode,  # type: ignore[arg-type]
        try_rotate=True,
        try_downscale=True,
        try_invert=True,
        text_mode=zxingcpp.TextMode.Plain,
        is_pure=pure,
    )
    out = []
    for b in res:
        if b.format in small:  # only full-size codes: clutter cannot decode as a tiny code
            continue
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
            extra: Any = b.extra  # a dict in zxing-cpp 3; absent or without .get before
            version = int(extra.get("Version", 0))
        except (TypeError, ValueError, AttributeError):
            version = 0
        n = 17 + 4 * version if 1 <= version <= 40 else 0
        content = _CONTENT.get(getattr(b.content_type, "name", str(b.content_type)), "text")
        out.append(RawCode(b.text, bytes(b.bytes), c, n, True, content, False))
    return out


def zxing_on_quad(gray: np.ndarray, quad: np.ndarray, margin: float = 0.35) -> RawCode | None:
    """zxing-cpp on the code another decoder found at ``quad`` (4, 2; TL, TR, BR, BL), warped upright into a
    square crop with a margin (a fraction of the side) and at least 4 px per module of a version-10 code;
    its corners mapped back into the image. None when zxing-cpp cannot read it there either."""
    import cv2

    q = np.asarray(quad, np.float64).reshape(4, 2)
    side = float(np.mean(np.linalg.norm(q - np.roll(q, -1, axis=0), axis=1)))
    if not (math.isfinite(side) and side >= 8):
        return None
    s = int(np.clip(round(side), 240, 1200))
    m = margin * s
    dst = np.array([[m, m], [m + s, m], [m + s, m + s], [m, m + s]], np.float32)
    H = cv2.getPerspectiveTransform(q.astype(np.float32), dst)
    size = int(round(s + 2 * m))
    crop = cv2.warpPerspective(gray, H, (size, size), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
    found = read_zxing(crop)
    if not found:
        return None
    centre = np.array([m + s / 2, m + s / 2])
    best = min(found, key=lambda r: float(np.linalg.norm(r.corners.mean(axis=0) - centre)))
    if np.linalg.norm(best.corners.mean(axis=0) - centre) > 0.25 * s:
        return None
    back = cv2.perspectiveTransform(best.corners.reshape(1, 4, 2).astype(np.float64), np.linalg.inv(H))
    return RawCode(best.text, best.raw, back.reshape(4, 2), best.n_modules, True, best.content, False)


# ----------------------------------------------------------------------------------------------------- zbar


def _zbar_scan(gray: np.ndarray, binary: bool) -> list[tuple[bytes, np.ndarray]]:
    from ctypes import c_void_p, cast, string_at

    from pyzbar import wrapper as zw
    from pyzbar.pyzbar import _FOURCC, ZBarSymbol, _image, _image_scanner, _symbols_for_image

    g = np.ascontiguousarray(gray, dtype=np.uint8)
    h, w = g.shape
    buf = g.tobytes()
    out = []
    with _image_scanner() as scanner:
        zw.zbar_image_scanner_set_config(scanner, 0, zw.ZBarConfig.CFG_ENABLE, 0)
        zw.zbar_image_scanner_set_config(scanner, ZBarSymbol.QRCODE, zw.ZBarConfig.CFG_ENABLE, 1)
        if binary:
            zw.zbar_image_scanner_set_config(scanner, ZBarSymbol.QRCODE, _ZBAR_CFG_BINARY, 1)
        with _image() as img:
            zw.zbar_image_set_format(img, _FOURCC["L800"])
            zw.zbar_image_set_size(img, w, h)
            zw.zbar_image_set_data(img, cast(buf, c_void_p), len(buf), None)  # type: ignore[arg-type]  # ctypes casts a bytes object's buffer
            if zw.zbar_scan_image(scanner, img) < 0:  # pragma: no cover - Y800 is always supported
                return []
            for sym in _symbols_for_image(img):
                data = string_at(zw.zbar_symbol_get_data(sym), zw.zbar_symbol_get_data_length(sym))
                pts = [
                    (zw.zbar_symbol_get_loc_x(sym, i), zw.zbar_symbol_get_loc_y(sym, i))
                    for i in range(zw.zbar_symbol_get_loc_size(sym))
                ]
                out.append((bytes(data), np.array(pts, float).reshape(-1, 2)))
    return out


def _utf8(b: bytes) -> str | None:
    try:
        return b.decode("utf-8")
    except UnicodeDecodeError:
        return None


def read_zbar(gray: np.ndarray) -> list[RawCode]:
    """zbar on a grey image: payload bytes (binary mode), zbar's text where the bytes are not ASCII."""
    found = _zbar_scan(gray, binary=True)
    texts: list[tuple[bytes, np.ndarray]] = []
    if any(not raw.isascii() for raw, _ in found):
        texts = _zbar_scan(gray, binary=False)
    out = []
    for raw, pts in found:
        if pts.shape[0] != 4:
            continue
        c = pts[[0, 3, 2, 1]]  # zbar: TL, BL, BR, TR of the code
        if raw.isascii():
            out.append(RawCode(raw.decode("ascii"), raw, c, 0, True, "text", False))
            continue
        text = None
        for t, tp in texts:  # the text-mode read of the same code: same place
            if tp.shape == pts.shape and np.abs(tp - pts).max() < 1.0:
                text = t.decode("utf-8", errors="replace")
                break
        as_utf8 = _utf8(raw)
        if text is None:
            text = as_utf8 if as_utf8 is not None else raw.decode("latin-1")
        guessed = as_utf8 is None or text != as_utf8
        out.append(RawCode(text, raw, c, 0, True, "text", guessed))
    return out


# --------------------------------------------------------------------------------------------------- OpenCV


def read_opencv(gray: np.ndarray, aruco: bool = False) -> list[RawCode]:
    """OpenCV's QR detector (or its ArUco-based twin). Its points are taken as unordered."""
    import cv2

    det = cv2.QRCodeDetectorAruco() if aruco else cv2.QRCodeDetector()
    try:
        ok, texts, points, straight = det.detectAndDecodeMulti(gray)
    except (cv2.error, UnicodeDecodeError):  # OpenCV raises on payloads that are not UTF-8
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
        out.append(RawCode(t, t.encode("utf-8"), np.asarray(points[i], float).reshape(4, 2), n, False))
    return out
