"""Decode camera images kept encoded by ingestion (``holoslam.types.Image``), and image files, into numpy
pixels."""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import numpy as np

from holoslam.errors import ImageDecodeError

__all__ = ["EncodedImage", "decode_image", "read_image_file", "COMPRESSED_FORMATS", "RAW_ENCODINGS"]


class EncodedImage(Protocol):
    """What decoding reads of an image record (``holoslam.types.Image`` has it): this module does not import
    the record types, so ``Image.decode`` can call it without an import cycle."""

    @property
    def stamp_ns(self) -> int: ...
    @property
    def frame_id(self) -> str: ...
    @property
    def encoding(self) -> str: ...
    @property
    def data(self) -> bytes: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def step(self) -> int: ...

COMPRESSED_FORMATS = ("jpeg", "jpg", "png", "bmp", "tiff", "webp")

# raw sensor_msgs/Image encodings: (channels, numpy dtype)
RAW_ENCODINGS: dict[str, tuple[int, str]] = {
    "mono8": (1, "u1"),
    "8uc1": (1, "u1"),
    "mono16": (1, "u2"),
    "16uc1": (1, "u2"),
    "bgr8": (3, "u1"),
    "rgb8": (3, "u1"),
    "8uc3": (3, "u1"),
    "bgra8": (4, "u1"),
    "rgba8": (4, "u1"),
    "8uc4": (4, "u1"),
    "32fc1": (1, "f4"),
}


def _compressed_kind(encoding: str) -> str | None:
    # CompressedImage.format is 'jpeg', 'png', or e.g. 'rgb8; jpeg compressed bgr8'
    e = encoding.lower()
    for fmt in COMPRESSED_FORMATS:
        if fmt in e:
            return fmt
    return None


def decode_image(image: EncodedImage) -> np.ndarray:
    """The pixels of ``image``: (H, W) for single-channel images (uint8, or uint16/float32 for depth-like
    encodings) and (H, W, 3) uint8 BGR for colour ones (alpha dropped, RGB reordered).

    Raises ImageDecodeError naming the stamp, frame and encoding when the bytes are not a valid image.
    """
    where = f"image at stamp {image.stamp_ns} ns in frame '{image.frame_id}' (encoding '{image.encoding}')"
    enc = image.encoding.strip().lower()
    if enc in RAW_ENCODINGS:
        return _decode_raw(image, enc, where)
    kind = _compressed_kind(enc)
    if kind is None:
        raise ImageDecodeError(
            f"{where}: unknown encoding; holoslam decodes compressed {', '.join(COMPRESSED_FORMATS)} and raw "
            f"{', '.join(sorted(RAW_ENCODINGS))}. Convert the topic (e.g. with image_transport republish)."
        )
    import cv2

    buf = np.frombuffer(image.data, dtype=np.uint8)
    if buf.size == 0:
        raise ImageDecodeError(f"{where}: the message carries no image bytes")
    img = _imdecode(buf, cv2.IMREAD_UNCHANGED, where)
    if img is None:
        raise ImageDecodeError(
            f"{where}: {buf.size} bytes do not decode as {kind} (corrupted or truncated data; "
            f"first bytes {bytes(image.data[:8]).hex()})"
        )
    return _bgr_or_gray(img)


def _imdecode(buf: np.ndarray, flags: int, where: str) -> np.ndarray | None:
    """``cv2.imdecode``, with OpenCV's own refusals (a header declaring more pixels than
    ``CV_IO_MAX_IMAGE_PIXELS``, a malformed header) turned into ImageDecodeError naming ``where``."""
    import cv2

    try:
        return cv2.imdecode(buf, flags)
    except cv2.error as e:
        why = str(e).strip().splitlines()[-1] if str(e).strip() else type(e).__name__
        raise ImageDecodeError(
            f"{where}: OpenCV refuses to decode its {buf.size} bytes ({why}); the header is corrupt or declares "
            "an image too large to decode (OpenCV's limit: the OPENCV_IO_MAX_IMAGE_PIXELS environment variable)"
        ) from None


def _decode_raw(image: EncodedImage, enc: str, where: str) -> np.ndarray:
    channels, dt = RAW_ENCODINGS[enc]
    h, w = int(image.height), int(image.width)
    if h <= 0 or w <= 0:
        raise ImageDecodeError(f"{where}: raw image with size {w}x{h}; width and height must be positive")
    itemsize = np.dtype(dt).itemsize
    row = w * channels * itemsize
    step = int(image.step) or row
    if step < row:
        raise ImageDecodeError(f"{where}: step {step} is smaller than a row of {w} pixels ({row} bytes)")
    if len(image.data) < step * h:
        raise ImageDecodeError(
            f"{where}: {len(image.data)} bytes, but {h} rows of step {step} need {step * h} (truncated image)"
        )
    rows = np.frombuffer(image.data, dtype=np.uint8, count=step * h).reshape(h, step)[:, :row]
    px = np.ascontiguousarray(rows).view(np.dtype(dt).newbyteorder("<")).reshape(h, w, channels)
    px = px.astype(np.dtype(dt).newbyteorder("="), copy=False)
    if channels == 1:
        return px[:, :, 0].copy()
    if enc in ("rgb8",):
        return px[:, :, ::-1].copy()
    if enc in ("rgba8",):
        return px[:, :, 2::-1].copy()
    return px[:, :, :3].copy()


def read_image_file(path: str | Path, grayscale: bool = False) -> np.ndarray:
    """The pixels of one image file (PNG, JPEG, BMP, TIFF, WebP: anything OpenCV decodes): (H, W) uint8 when
    ``grayscale`` or the file is single-channel, else (H, W, 3) uint8 BGR (alpha dropped); 16-bit files keep
    their depth unless ``grayscale``.

    Raises ImageDecodeError naming the file when it is missing, unreadable, empty or not a decodable image.
    """
    import cv2

    p = Path(path)
    if p.is_dir():
        raise ImageDecodeError(f"{path}: is a directory, not an image file; pass the image files inside it")
    try:
        data = np.fromfile(p, dtype=np.uint8)
    except FileNotFoundError:
        raise ImageDecodeError(f"{path}: cannot read the file: no such file; check the path") from None
    except OSError as e:
        raise ImageDecodeError(
            f"{path}: cannot read the file ({e.strerror or e}); check its permissions"
        ) from None
    if data.size == 0:
        raise ImageDecodeError(f"{path}: the file is empty (0 bytes), not an image")
    img = _imdecode(data, cv2.IMREAD_GRAYSCALE if grayscale else cv2.IMREAD_UNCHANGED, str(path))
    if img is None:
        raise ImageDecodeError(
            f"{path}: not a decodable image: its {data.size} bytes are corrupt, truncated or an unsupported "
            f"format (first bytes {data[:8].tobytes().hex()}); save it as PNG or JPEG"
        )
    return _bgr_or_gray(img)


def _bgr_or_gray(img: np.ndarray) -> np.ndarray:
    """A decoded image as BGR (alpha dropped) or single-channel grey (H, W)."""
    import cv2

    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    if img.ndim == 3 and img.shape[2] == 1:
        return img[:, :, 0]
    return img
