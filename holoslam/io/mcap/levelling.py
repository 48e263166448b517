"""Lasers not mounted upright: an upside-down laser's scans mirrored into a level frame."""

from __future__ import annotations

import math

from holoslam.errors import IngestError
from holoslam.types import (
    Scan,
    Transform,
)

LEVEL_SUFFIX = "_level"
TILT_WARN_DEG = 5.0  # a laser plane further than this from the base's xy plane is reported (used as if level)


def mirrored_scan(scan: Scan, frame_id: str) -> Scan:
    """The same beams as an upright laser sees them: an upside-down laser's beam at angle a points at -a in
    the level frame, so the ranges run backwards from ``-(angle_min + (n - 1) * angle_increment)``."""
    n = scan.ranges.shape[0]
    a_last = scan.angle_min + scan.angle_increment * (n - 1) if n else scan.angle_min
    return Scan(
        scan.stamp_ns,
        frame_id,
        -a_last,
        scan.angle_increment,
        scan.range_min,
        scan.range_max,
        scan.ranges[::-1].copy(),
        scan.valid[::-1].copy(),
    )


def level_scans(
    scans: tuple[Scan, ...], transforms: tuple[Transform, ...], base_frame: str
) -> tuple[tuple[Scan, ...], tuple[Transform, ...], list[str], list[str]]:
    """Scans of a laser whose z axis points down in ``base_frame`` (mounted upside down: a roll or pitch of
    pi in its static transform) put into a level frame ``<laser>_level``.

    A planar laser's beam at angle a in its own frame points along R (cos a, sin a, 0) in the base frame, R the
    full 3D rotation base -> laser. When R's z axis points down, R restricted to the xy plane is a reflection:
    the beam points at yaw(R x) - a, so the planar pose (x, y, yaw) alone (what a 2D front end uses) mirrors
    the scan. The mirrored scan (``mirrored_scan``) in a level frame at (x, y, z, yaw(R x)) gives every beam
    its true direction. Returns (scans, the level frames' static transforms, what was levelled, warnings about
    tilted lasers). A laser not connected to the base is left alone (the report names the missing transform)."""
    from holoslam.frames import TransformTree

    first: dict[str, int] = {}
    for sc in scans:
        first.setdefault(sc.frame_id, sc.stamp_ns)
    frames = [f for f in first if f and f != base_frame]
    if not frames:
        return scans, (), [], []
    tree = TransformTree(transforms)
    level: dict[str, str] = {}
    tfs: list[Transform] = []
    done: list[str] = []
    tilted: list[str] = []
    for frame in frames:
        if not tree.can_transform(base_frame, frame):
            continue
        try:
            T = tree.lookup(base_frame, frame, first[frame])
        except IngestError:
            continue
        zz = float(T[2, 2])
        tilt = math.degrees(math.acos(min(1.0, abs(zz))))
        if tilt > TILT_WARN_DEG:
            tilted.append(
                f"laser frame '{frame}' is tilted {tilt:.1f} deg from the base's plane; its scans are used as if level"
            )
        if zz >= 0.0:
            continue
        yaw = math.atan2(T[1, 0], T[0, 0])
        name = frame + LEVEL_SUFFIX
        t = (float(T[0, 3]), float(T[1, 3]), float(T[2, 3]))
        tfs.append(
            Transform(
                first[frame], base_frame, name, t, (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)), True
            )
        )
        level[frame] = name
        done.append(
            f"laser frame '{frame}' is mounted upside down (its z axis points down in '{base_frame}'): its scans "
            f"are mirrored into the level frame '{name}' (beam angle a -> -a, yaw {math.degrees(yaw):.1f} deg)"
        )
    if not level:
        return scans, (), [], tilted
    out = tuple(mirrored_scan(sc, level[sc.frame_id]) if sc.frame_id in level else sc for sc in scans)
    return out, tuple(tfs), done, tilted
