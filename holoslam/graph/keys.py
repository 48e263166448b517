"""GTSAM keys of holoslam's variables (``gtsam.symbol_shorthand`` style, computed without importing gtsam).

- ``x<i>``: the pose ``wTa`` of anchor i (index into ``SlamProblem.initial_wTa``),
- ``l<k>``: the position of landmark k (index into the problem's sorted landmark variable list),
- ``n<k>``: the base pose of keyframe k (``holoslam.graph.nodes``),
- ``m0``:   the compass's magnetic frame (a Pose2 whose rotation is minus the compass's constant bias).

Landmark variables are named by object id; a moved object's earlier place is a second variable named
``before_id(object_id)`` (``"<id>@before"``). ``object_of`` and ``is_before`` read such a name back; nothing
else in holoslam builds or splits these names (an object id may itself hold an ``@``, e.g. a foreign code's
payload).

A gtsam Symbol key is ``(ord(char) << 56) | index``; the same arithmetic is done here so that this module stays
importable without gtsam.
"""

from __future__ import annotations

import numpy as np

__all__ = ["anchor_key", "landmark_key", "MAGNETIC_KEY", "anchor_keys", "node_key", "node_keys", "key_index", "key_char",
           "BEFORE_SUFFIX", "before_id", "is_before", "object_of"]

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


BEFORE_SUFFIX = "@before"  # the name of a moved object's earlier place: object id + this suffix


def before_id(object_id: str) -> str:
    """The landmark name of ``object_id``'s earlier place (the object was moved)."""
    return f"{object_id}{BEFORE_SUFFIX}"


def is_before(landmark_id: str) -> bool:
    """Is ``landmark_id`` a moved object's earlier place (``before_id``)?"""
    return str(landmark_id).endswith(BEFORE_SUFFIX)


def object_of(landmark_id: str) -> str:
    """The object id a landmark name belongs to (itself, or the object whose earlier place it is)."""
    name = str(landmark_id)
    return name[: -len(BEFORE_SUFFIX)] if name.endswith(BEFORE_SUFFIX) else name
