"""GTSAM keys of holoslam's variables (``gtsam.symbol_shorthand`` style, computed without importing gtsam).

- ``x<i>``: the pose ``wTa`` of anchor i (index into ``SlamProblem.initial_wTa``),
- ``l<k>``: the position of landmark k (index into the problem's sorted landmark variable list),
- ``n<k>``: the base pose of keyframe k (``holoslam.graph.nodes``),
- ``m0``:   the compass's magnetic frame (a Pose2 whose rotation is minus the compass's constant bias).

A gtsam Symbol key is ``(ord(char) << 56) | index``; the same arithmetic is done here so that this module stays
importable without gtsam.
"""

from __future__ import annotations

import numpy as np

__all__ = ["anchor_key", "landmark_key", "MAGNETIC_KEY", "anchor_keys", "node_key", "node_keys", "key_index", "key_char"]

_CHAR_SHIFT = 56
_INDEX_MASK = (1 << _CHAR_SHIFT) - 1


def _symbol(char: str, index: int) -> int:
    return (ord(char) << _CHAR_SHIFT) | int(index)


def anchor_key(i: int) -> int:
    """Key of anchor pose i (``X(i)``)."""
    return _symbol("x", i)


def landmark_key(k: int) -> int:
    """Key of landmark variable k (``L(k)``)."""
    return _symbol("l", k)


def anchor_keys(indices: np.ndarray) -> np.ndarray:
    """Keys of many anchors at once, as uint64."""
    return (np.uint64(ord("x")) << np.uint64(_CHAR_SHIFT)) | np.asarray(indices, dtype=np.uint64)


MAGNETIC_KEY: int = _symbol("m", 0)


def key_char(key: int) -> str:
    return chr(int(key) >> _CHAR_SHIFT)


def key_index(key: int) -> int:
    return int(key) & _INDEX_MASK


def node_key(n: int) -> int:
    """Key of keyframe (node) pose n (``n<n>``, ``holoslam.graph.nodes``)."""
    return _symbol("n", n)


def node_keys(indices: np.ndarray) -> np.ndarray:
    """Keys of many nodes at once, as uint64."""
    return (np.uint64(ord("n")) << np.uint64(_CHAR_SHIFT)) | np.asarray(indices, dtype=np.uint64)
