"""Occupancy grids as ROS map_server maps: an image (PGM P5 or PNG) plus a YAML file.

YAML keys: ``image`` (path, relative to the YAML's folder unless absolute), ``resolution`` (m/cell),
``origin`` [x, y, yaw] (world pose of the lower-left pixel), ``negate`` (0/1), ``occupied_thresh``,
``free_thresh`` and ``mode`` (trinary | scale | raw; default trinary). The image's first row is the top of
the map (largest y); OccupancyGrid's row 0 is the lowest y, so rows are flipped here and nowhere else.

Pixel values (negate 0): p = (255 - v) / 255 is the occupancy probability.
- trinary: p > occupied_thresh -> 100, p < free_thresh -> 0, else -1 (unknown). Written as 0 (occupied),
  254 (free) and 205 (unknown), as map_saver does; grids with only 0 / 100 / -1 round-trip exactly, cells with
  values in between are written by their class (free below free_thresh, occupied at or above occupied_thresh,
  unknown between).
- scale: as trinary outside the thresholds, 99 * (p - free) / (occupied - free) in between.
- raw: the pixel value is the occupancy (0..100), anything above 100 is unknown; written with 255 for unknown.
  Every grid round-trips exactly in raw mode.

holoslam grids are axis-aligned: a map whose origin yaw is not 0 is refused with a message.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from holoslam.errors import MapError
from holoslam.maps.grid import OccupancyGrid

__all__ = [
    "MapMetadata",
    "read_map_yaml",
    "read_grid",
    "write_grid",
    "write_grid_png",
    "grid_to_image",
    "image_to_grid",
    "encode_pgm",
    "decode_pgm",
    "grid_picture",
    "write_label_png",
    "read_label_png",
]

MODES = ("trinary", "scale", "raw")
_FREE, _OCC, _UNKNOWN = 254, 0, 205


@dataclass(frozen=True, slots=True)
class MapMetadata:
    """The YAML half of a map_server map, checked. ``notes`` says what was unusual but accepted."""

    image: Path  # resolved path of the image
    resolution: float
    origin: tuple[float, float, float]
    negate: bool
    occupied_thresh: float
    free_thresh: float
    mode: str
    notes: tuple[str, ...] = ()


def _num(data: dict, key: str, path: Path) -> float:
    v = data[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise MapError(f"{path}: '{key}' must be a finite number, got {v!r}")
    return float(v)


def read_map_yaml(path: str | Path) -> MapMetadata:
    """Read and check a map_server YAML file (does not load the image)."""
    import yaml

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise MapError(f"cannot read map YAML {path}: {exc.strerror or exc}") from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise MapError(f"{path} is not valid YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise MapError(f"{path}: a map YAML must be a mapping with image, resolution and origin keys")
    missing = [k for k in ("image", "resolution", "origin") if k not in data]
    if missing:
        raise MapError(
            f"{path}: missing key(s) {', '.join(missing)} (map_server needs image, resolution, origin)"
        )
    notes: list[str] = []
    if not isinstance(data["image"], str) or not data["image"]:
        raise MapError(f"{path}: 'image' must be a file name, got {data['image']!r}")
    res = _num(data, "resolution", path)
    if res <= 0:
        raise MapError(f"{path}: resolution must be positive metres per cell, got {res}")
    origin = data["origin"]
    if not isinstance(origin, (list, tuple)) or len(origin) != 3:
        raise MapError(f"{path}: origin must be [x, y, yaw], got {origin!r}")
    try:
        ox, oy, yaw = (float(v) for v in origin)
    except (TypeError, ValueError) as exc:
        raise MapError(f"{path}: origin must be three numbers [x, y, yaw], got {origin!r}") from exc
    if not all(math.isfinite(v) for v in (ox, oy, yaw)):
        raise MapError(f"{path}: origin must be finite, got {origin!r}")
    if abs(math.remainder(yaw, 2 * math.pi)) > 1e-9:
        raise MapError(
            f"{path}: origin yaw {yaw} is not 0; holoslam grids are axis-aligned, "
            "rotate the image and set yaw 0"
        )
    negate = data.get("negate", 0)
    if negate not in (0, 1, True, False):
        raise MapError(f"{path}: negate must be 0 or 1, got {negate!r}")
    occ = _num(data, "occupied_thresh", path) if "occupied_thresh" in data else 0.65
    free = _num(data, "free_thresh", path) if "free_thresh" in data else 0.196
    if not 0.0 <= free < occ <= 1.0:
        raise MapError(f"{path}: need 0 <= free_thresh < occupied_thresh <= 1, got {free} and {occ}")
    mode = data.get("mode", "trinary")
    if mode not in MODES:
        raise MapError(f"{path}: mode must be one of {', '.join(MODES)}, got {mode!r}")
    img = Path(data["image"])
    resolved = (img if img.is_absolute() else path.parent / img).resolve()
    folder = path.parent.resolve()
    if not resolved.is_relative_to(folder):
        notes.append(
            f"image {data['image']!r} lies outside the YAML's folder {folder} (read from {resolved})"
        )
    return MapMetadata(resolved, res, (ox, oy, 0.0), bool(negate), occ, free, str(mode), tuple(notes))


def decode_pgm(data: bytes, where: str = "PGM") -> np.ndarray:
    """Binary (P5) or ASCII (P2) 8-bit PGM -> (H, W) uint8, first row = top of the image."""
    tokens: list[bytes] = []
    pos = 0
    token_re = re.compile(rb"\s*(?:#[^\n]*\n\s*)*([^\s#]+)")
    for _ in range(4):
        m = token_re.match(data, pos)
        if not m:
            raise MapError(f"{where}: truncated PGM header")
        tokens.append(m.group(1))
        pos = m.end()
    magic = tokens[0]
    if magic not in (b"P5", b"P2"):
        raise MapError(f"{where}: not a PGM file (magic {magic[:2]!r}, expected P5 or P2)")
    try:
        w, h, maxval = (int(t) for t in tokens[1:])
    except ValueError as exc:
        raise MapError(f"{where}: PGM header width/height/maxval are not integers: {tokens[1:]}") from exc
    if w <= 0 or h <= 0 or not 0 < maxval < 256:
        raise MapError(f"{where}: PGM of {w}x{h} with maxval {maxval} (need positive size, 8-bit maxval)")
    if magic == b"P5":
        body = data[pos + 1 : pos + 1 + w * h]
        if len(body) != w * h:
            raise MapError(f"{where}: PGM body has {len(body)} bytes, header says {w}x{h} = {w * h}")
        img: np.ndarray = np.frombuffer(body, dtype=np.uint8).reshape(h, w)
    else:
        vals = data[pos:].split()
        if len(vals) < w * h:
            raise MapError(f"{where}: ASCII PGM has {len(vals)} values, header says {w * h}")
        img = np.array([int(v) for v in vals[: w * h]], dtype=np.int64).reshape(h, w)
    if maxval != 255:
        img = np.rint(np.asarray(img, dtype=np.float64) * 255.0 / maxval)
    return np.asarray(img, dtype=np.uint8).copy()


def encode_pgm(img: np.ndarray, comment: str = "") -> bytes:
    """(H, W) uint8 -> binary PGM (P5) bytes."""
    img = np.ascontiguousarray(img, dtype=np.uint8)
    h, w = img.shape
    head = b"P5\n" + (f"# {comment}\n".encode() if comment else b"") + f"{w} {h}\n255\n".encode()
    return head + img.tobytes()


def grid_to_image(grid: OccupancyGrid, mode: str = "trinary", negate: bool = False) -> np.ndarray:
    """OccupancyGrid -> (H, W) uint8 map_server image (first row = largest y)."""
    if mode not in ("trinary", "raw"):
        raise MapError(f"writing supports mode trinary or raw, got {mode!r}")
    o = grid.occupancy
    if mode == "raw":
        img = np.where(o < 0, 255, o.astype(np.int16)).astype(np.uint8)  # 255 does not fit int8 (numpy >= 2.5 raises)
    else:
        unknown = _UNKNOWN
        if not grid.free_thresh <= (255 - _UNKNOWN) / 255 <= grid.occupied_thresh:
            unknown = round(255 * (1 - (grid.free_thresh + grid.occupied_thresh) / 2))
        img = np.full(o.shape, unknown, dtype=np.uint8)
        img[grid.free] = _FREE
        img[grid.occupied] = _OCC
        if negate:
            img = 255 - img
    return np.ascontiguousarray(img[::-1])


def image_to_grid(img: np.ndarray, meta: MapMetadata) -> OccupancyGrid:
    """map_server image (first row = top) + metadata -> OccupancyGrid."""
    img = np.asarray(img)
    if img.ndim == 2 and img.dtype == np.uint8:  # each of the 256 grey values converted once, then looked up
        lut = image_to_grid(np.arange(256, dtype=np.float64)[None, :], meta).occupancy[0]
        return OccupancyGrid(
            lut[img[::-1]],
            meta.resolution,
            meta.origin[0],
            meta.origin[1],
            occupied_thresh=meta.occupied_thresh,
            free_thresh=meta.free_thresh,
        )
    if img.ndim == 3:
        img = img[..., :3].astype(np.float64).mean(axis=2)  # map_server averages the colour channels
    v = np.asarray(img, dtype=np.float64)[::-1]
    if meta.mode == "raw":
        occ = np.where(v > 100, -1, v)
    else:
        p = v / 255.0 if meta.negate else (255.0 - v) / 255.0
        occ = np.full(v.shape, -1.0)
        occ[p > meta.occupied_thresh] = 100
        occ[p < meta.free_thresh] = 0
        if meta.mode == "scale":
            mid = (p >= meta.free_thresh) & (p <= meta.occupied_thresh)
            occ[mid] = np.rint(99.0 * (p[mid] - meta.free_thresh) / (meta.occupied_thresh - meta.free_thresh))
    return OccupancyGrid(
        np.rint(occ).astype(np.int8),
        meta.resolution,
        meta.origin[0],
        meta.origin[1],
        occupied_thresh=meta.occupied_thresh,
        free_thresh=meta.free_thresh,
    )


def _read_image(path: Path) -> np.ndarray:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise MapError(f"cannot read map image {path}: {exc.strerror or exc}") from exc
    if data[:2] in (b"P5", b"P2"):
        return decode_pgm(data, str(path))
    import cv2

    img = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise MapError(f"{path}: not a readable image (expected PGM or PNG)")
    if img.dtype != np.uint8:
        raise MapError(f"{path}: {img.dtype} pixels; map images must be 8-bit")
    if img.ndim == 3:
        img = img[..., 2::-1] if img.shape[2] >= 3 else img[..., 0]  # BGR(A) -> RGB
    return img


def read_grid(yaml_path: str | Path) -> OccupancyGrid:
    """Read a map_server map (YAML + PGM / PNG) into an OccupancyGrid."""
    meta = read_map_yaml(yaml_path)
    return image_to_grid(_read_image(meta.image), meta)


def write_grid(
    grid: OccupancyGrid,
    yaml_path: str | Path,
    *,
    image_format: str = "pgm",
    mode: str = "trinary",
    negate: bool = False,
) -> Path:
    """Write ``grid`` as ``<name>.yaml`` + ``<name>.pgm`` (or ``.png``) beside it; returns the image path."""
    import yaml

    yaml_path = Path(yaml_path)
    if image_format not in ("pgm", "png"):
        raise MapError(f"image_format must be 'pgm' or 'png', got {image_format!r}")
    if mode == "raw" and negate:
        raise MapError("negate has no meaning in raw mode; write raw with negate=False")
    img = grid_to_image(grid, mode, negate)
    image_path = yaml_path.with_suffix("." + image_format)
    if image_format == "pgm":
        image_path.write_bytes(encode_pgm(img, "holoslam occupancy grid"))
    else:
        import cv2

        ok, buf = cv2.imencode(".png", img)
        if not ok:
            raise MapError(f"PNG encoding of a {img.shape} grid failed")
        image_path.write_bytes(buf.tobytes())
    meta = {
        "image": image_path.name,
        "mode": mode,
        "resolution": float(grid.resolution),
        "origin": [float(grid.origin_x), float(grid.origin_y), 0.0],
        "negate": int(negate),
        "occupied_thresh": float(grid.occupied_thresh),
        "free_thresh": float(grid.free_thresh),
    }
    yaml_path.write_text(yaml.safe_dump(meta, sort_keys=False), encoding="utf-8")
    return image_path


def grid_picture(grid: OccupancyGrid, scale: int = 1) -> np.ndarray:
    """(H*scale, W*scale) uint8 grey picture, top = largest y: white free, black occupied, mid-grey unknown,
    shades of grey for probabilities in between."""
    if scale < 1:
        raise MapError(f"picture scale must be >= 1, got {scale}")
    # the grey of each of the 256 int8 values, looked up (no float copy of the map)
    v = np.arange(256, dtype=np.uint8).view(np.int8).astype(np.float64)
    lut = np.rint(np.where(v < 0, 160.0, 255.0 - v * 2.55)).astype(np.uint8)
    img = lut[grid.occupancy.view(np.uint8)][::-1]
    if scale > 1:
        img = np.repeat(np.repeat(img, scale, axis=0), scale, axis=1)
    return np.ascontiguousarray(img)


def write_grid_png(grid: OccupancyGrid, path: str | Path, scale: int = 1) -> Path:
    """Write ``grid_picture(grid, scale)`` as a PNG."""
    import cv2

    path = Path(path)
    ok, buf = cv2.imencode(".png", grid_picture(grid, scale))
    if not ok:
        raise MapError(f"PNG encoding of the grid picture for {path} failed")
    path.write_bytes(buf.tobytes())
    return path


def write_label_png(labels: np.ndarray, path: str | Path) -> Path:
    """Write a label image of a grid ((H, W) integers in the grid's row order, row 0 = lowest y; 0 = none) as a
    16-bit grey PNG the size of the map, rows as in the map's image (first row = largest y, as ``map.pgm``), so
    pixel (i, j) of the PNG is pixel (i, j) of the map image. Raises ``MapError`` for ids above 65535."""
    import cv2

    path = Path(path)
    lab = np.asarray(labels)
    if lab.ndim != 2 or (lab.size and (lab.min() < 0 or lab.max() > 65535)):
        raise MapError(f"{path}: a label image needs 2-D ids in 0..65535, got shape {lab.shape}")
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(np.flipud(lab)).astype(np.uint16))
    if not ok:
        raise MapError(f"PNG encoding of the label image {path} failed")
    try:
        path.write_bytes(buf.tobytes())
    except OSError as exc:
        raise MapError(f"cannot write {path}: {exc.strerror or exc}") from exc
    return path


def read_label_png(path: str | Path) -> np.ndarray:
    """A label PNG written by :func:`write_label_png` -> (H, W) int32 in the grid's row order."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None or img.ndim != 2:
        raise MapError(f"{path}: not a 1-channel label image")
    return np.ascontiguousarray(np.flipud(img)).astype(np.int32)
