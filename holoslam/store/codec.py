"""Arrays as the map store's BLOBs: little-endian raw bytes, zlib-compressed, with their dtype and shape in a
short header, so a blob reads back without the schema saying its shape. Probability grids are quantised to uint8
(1/255 steps: finer than the 0.1..0.9 clamp's odds updates, Cartographer's hit/miss 0.55/0.49, move one cell)."""

from __future__ import annotations

import struct
import zlib

import numpy as np

from holoslam.errors import StoreError

__all__ = ["pack", "unpack", "pack_prob", "unpack_prob", "GRID_LEVELS"]

_DTYPES = {"f8": np.float64, "f4": np.float32, "i8": np.int64, "i4": np.int32, "u1": np.uint8, "u2": np.uint16}
_CODES = {np.dtype(v).str[1:]: k for k, v in _DTYPES.items()}
GRID_LEVELS = 255  # a stored probability p is round(p * GRID_LEVELS) as uint8


def pack(a: np.ndarray, level: int = 6) -> bytes:
    """An array as a blob: b'HA' + dtype code (2 bytes) + ndim (1 byte) + shape (uint32 each) + zlib data."""
    arr = np.ascontiguousarray(a)
    code = _CODES.get(arr.dtype.newbyteorder("<").str[1:])
    if code is None:
        raise StoreError(f"the map store cannot hold arrays of dtype {arr.dtype}; use one of {sorted(_DTYPES)}")
    header = b"HA" + code.encode() + struct.pack("<B", arr.ndim) + struct.pack(f"<{arr.ndim}I", *arr.shape)
    return header + zlib.compress(arr.astype(arr.dtype.newbyteorder("<"), copy=False).tobytes(), level)


def unpack(blob: bytes | None, where: str = "") -> np.ndarray:
    """The array of a blob written by ``pack``; raises ``StoreError`` naming ``where`` when it is damaged."""
    if blob is None:
        raise StoreError(f"map store: {where} holds no array (NULL); the store is damaged")
    try:
        if blob[:2] != b"HA":
            raise ValueError("no array header")
        dtype = _DTYPES[blob[2:4].decode()]
        ndim = blob[4]
        shape = struct.unpack(f"<{ndim}I", blob[5 : 5 + 4 * ndim])
        data = zlib.decompress(blob[5 + 4 * ndim :])
        out = np.frombuffer(data, dtype=np.dtype(dtype).newbyteorder("<")).astype(dtype).reshape(shape)
    except (ValueError, KeyError, zlib.error, struct.error, IndexError) as e:
        raise StoreError(f"map store: {where} is not a stored array ({e}); the store is damaged") from None
    out.setflags(write=False)
    return out


def pack_prob(prob: np.ndarray, known: np.ndarray | None = None) -> bytes:
    """A probability grid (values in [0, 1]) quantised to uint8 (1..255) and packed; code 0 marks the cells
    ``known`` says no scan updated (all known when None)."""
    q = np.clip(np.rint(np.clip(np.asarray(prob, np.float64), 0.0, 1.0) * GRID_LEVELS), 1, GRID_LEVELS)
    if known is not None:
        q = np.where(np.asarray(known, bool), q, 0)
    return pack(q.astype(np.uint8), level=9)


def unpack_prob(blob: bytes | None, where: str = "", p_unknown: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """The float32 probability grid of a blob written by ``pack_prob`` (unknown cells at ``p_unknown``, the
    submaps' p_min) and its known mask."""
    q = unpack(blob, where)
    known = q > 0
    out = np.where(known, q.astype(np.float32) / np.float32(GRID_LEVELS), np.float32(p_unknown)).astype(np.float32)
    out.setflags(write=False)
    known.setflags(write=False)
    return out, known
