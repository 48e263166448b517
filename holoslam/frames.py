"""A transform tree built from a log's ``/tf_static`` and ``/tf`` records (like tf2's buffer, without ROS).

Each frame has one parent. Static transforms hold for all time; dynamic ones are kept per edge sorted by
stamp and looked up by linear interpolation of the translation and slerp of the rotation between the two
samples that bracket the query, or by the nearest sample when the query lies outside an edge's samples by at
most ``tolerance_ns``. ``lookup(parent, child, t)`` chains edges through the common ancestor and returns the
4x4 matrix ``parentTchild``; ``planar`` projects it to (x, y, theta) (theta = yaw of the child's x axis).

Depends on numpy alone.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from holoslam.errors import IngestError
from holoslam.types import Transform

__all__ = ["TransformTree", "TransformLookupError", "quat_to_matrix", "yaw_from_quaternion", "quaternion_from_yaw",
           "quaternion_from_matrix"]


class TransformLookupError(IngestError):
    """No transform connects two frames at the requested time."""


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a quaternion (x, y, z, w) (normalised first)."""
    x, y, z, w = np.asarray(q, dtype=np.float64) / (np.linalg.norm(q) or 1.0)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def yaw_from_quaternion(x: float, y: float, z: float, w: float) -> float:
    """Yaw (rotation about z of the rotated x axis, ZYX convention) of a quaternion, in [-pi, pi)."""
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return (yaw + math.pi) % (2.0 * math.pi) - math.pi


def quaternion_from_yaw(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw`` about z."""
    return 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)


def quaternion_from_matrix(R: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation matrix (3, 3), w >= 0."""
    R = np.asarray(R, dtype=np.float64)
    tr = np.trace(R)
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        w, x, y, z = 0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
        w, x, y, z = (R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s
    elif R[1, 1] > R[2, 2]:
        s = math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
        w, x, y, z = (R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s
    else:
        s = math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
        w, x, y, z = (R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s
    if w < 0:
        w, x, y, z = -w, -x, -y, -z
    return float(x), float(y), float(z), float(w)


def _slerp(q0: np.ndarray, q1: np.ndarray, u: float) -> np.ndarray:
    q0 = q0 / np.linalg.norm(q0)
    q1 = q1 / np.linalg.norm(q1)
    d = float(np.dot(q0, q1))
    if d < 0.0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + u * (q1 - q0)
        return q / np.linalg.norm(q)
    th = math.acos(min(1.0, d))
    s = math.sin(th)
    return (math.sin((1 - u) * th) * q0 + math.sin(u * th) * q1) / s


class _Edge:
    __slots__ = ("parent", "static_T", "stamps", "t", "q")

    def __init__(self, parent: str) -> None:
        self.parent = parent
        self.static_T: np.ndarray | None = None
        self.stamps: np.ndarray = np.empty(0, dtype=np.int64)
        self.t: np.ndarray = np.empty((0, 3))
        self.q: np.ndarray = np.empty((0, 4))


class TransformTree:
    """Static and dynamic transforms of one log. Build with ``TransformTree(records)`` (the order of the
    records does not matter; a dynamic edge's samples are sorted by stamp)."""

    def __init__(self, transforms: Iterable[Transform] = (), tolerance_ns: int = 100_000_000) -> None:
        self.tolerance_ns = int(tolerance_ns)
        self._edges: dict[str, _Edge] = {}
        self._conflicts: list[str] = []
        dyn: dict[str, list[Transform]] = {}
        for tr in transforms:
            edge = self._edges.get(tr.child)
            if edge is None:
                edge = self._edges[tr.child] = _Edge(tr.parent)
            elif edge.parent != tr.parent:
                self._conflicts.append(
                    f"frame '{tr.child}' has two parents, '{edge.parent}' and '{tr.parent}' (kept the first)"
                )
                continue
            if tr.static:
                edge.static_T = tr.matrix()
            else:
                dyn.setdefault(tr.child, []).append(tr)
        for child, trs in dyn.items():
            trs.sort(key=lambda r: r.stamp_ns)
            e = self._edges[child]
            e.stamps = np.array([r.stamp_ns for r in trs], dtype=np.int64)
            e.t = np.array([r.translation for r in trs], dtype=np.float64).reshape(-1, 3)
            e.q = np.array([r.rotation_xyzw for r in trs], dtype=np.float64).reshape(-1, 4)

    @property
    def frames(self) -> set[str]:
        out = set(self._edges)
        out.update(e.parent for e in self._edges.values())
        return out

    @property
    def conflicts(self) -> tuple[str, ...]:
        """Messages about frames given two different parents (the later parent was ignored)."""
        return tuple(self._conflicts)

    def _chain(self, frame: str) -> list[str]:
        chain = [frame]
        seen = {frame}
        while chain[-1] in self._edges:
            p = self._edges[chain[-1]].parent
            if p in seen:
                break  # a cycle; stop at the repeated frame
            chain.append(p)
            seen.add(p)
        return chain

    def can_transform(self, parent: str, child: str) -> bool:
        """Whether ``parent`` and ``child`` are connected in the tree (ignoring time)."""
        return bool(set(self._chain(parent)) & set(self._chain(child)))

    def _edge_matrix(self, child: str, stamp_ns: int) -> np.ndarray:
        e = self._edges[child]
        n = e.stamps.shape[0]
        if n == 0:
            assert e.static_T is not None
            return e.static_T
        i = int(np.searchsorted(e.stamps, stamp_ns, side="left"))
        if i < n and e.stamps[i] == stamp_ns:
            t, q = e.t[i], e.q[i]
        elif 0 < i < n:
            t0, t1 = e.stamps[i - 1], e.stamps[i]
            u = float(stamp_ns - t0) / float(t1 - t0)
            t = e.t[i - 1] + u * (e.t[i] - e.t[i - 1])
            q = _slerp(e.q[i - 1], e.q[i], u)
        else:
            j = 0 if i == 0 else n - 1
            if abs(int(e.stamps[j]) - stamp_ns) > self.tolerance_ns:
                if e.static_T is not None:
                    return e.static_T
                raise TransformLookupError(
                    f"transform '{e.parent}' -> '{child}' is not known at stamp {stamp_ns} ns: its samples span "
                    f"[{int(e.stamps[0])}, {int(e.stamps[-1])}] ns and the nearest is "
                    f"{abs(int(e.stamps[j]) - stamp_ns) / 1e9:.3f} s away (tolerance "
                    f"{self.tolerance_ns / 1e9:.3f} s). Query inside the span or raise tolerance_ns."
                )
            t, q = e.t[j], e.q[j]
        T = np.eye(4)
        T[:3, :3] = quat_to_matrix(q)
        T[:3, 3] = t
        return T

    def lookup(self, parent: str, child: str, stamp_ns: int) -> np.ndarray:
        """The 4x4 homogeneous matrix ``parentTchild`` at ``stamp_ns``.

        Raises TransformLookupError when the frames are not connected or a dynamic edge on the path has no
        sample near ``stamp_ns``.
        """
        if parent == child:
            return np.eye(4)
        up_p = self._chain(parent)
        up_c = self._chain(child)
        common = next((f for f in up_c if f in set(up_p)), None)
        if common is None:
            known = ", ".join(sorted(self.frames)) or "none"
            raise TransformLookupError(
                f"no transform connects '{parent}' and '{child}': '{child}' reaches up to '{up_c[-1]}' and "
                f"'{parent}' up to '{up_p[-1]}'. Known frames: {known}. Add the missing transform to /tf_static "
                "or name it in the log mapping."
            )
        # rootTchild = product along the chain from the common ancestor down to child
        cTchild = np.eye(4)
        for f in up_c[: up_c.index(common)]:
            cTchild = self._edge_matrix(f, stamp_ns) @ cTchild
        cTparent = np.eye(4)
        for f in up_p[: up_p.index(common)]:
            cTparent = self._edge_matrix(f, stamp_ns) @ cTparent
        R = cTparent[:3, :3]
        inv = np.eye(4)
        inv[:3, :3] = R.T
        inv[:3, 3] = -R.T @ cTparent[:3, 3]
        return inv @ cTchild

    def planar(self, parent: str, child: str, stamp_ns: int) -> tuple[float, float, float]:
        """``parentTchild`` projected on the parent's xy plane: (x, y, theta) with theta the yaw of the
        child's x axis, wrapped to [-pi, pi)."""
        T = self.lookup(parent, child, stamp_ns)
        th = math.atan2(T[1, 0], T[0, 0])
        th = (th + math.pi) % (2.0 * math.pi) - math.pi
        return float(T[0, 3]), float(T[1, 3]), th
