"""TransformTree: chaining, interpolation, nearest-within-tolerance, errors; checked against SE(2) geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from holoslam.frames import TransformLookupError, TransformTree, yaw_from_quaternion
from holoslam.geometry import compose
from holoslam.types import Transform


def _yaw_tf(stamp, parent, child, x, y, yaw, static=False, z=0.0):
    return Transform(
        stamp, parent, child, (x, y, z), (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)), static
    )


def test_chain_through_static_and_dynamic_edges_matches_se2_compose():
    tree = TransformTree(
        [
            _yaw_tf(0, "base_link", "ptz_base", 0.1, 0.0, 0.0, static=True, z=1.0),
            _yaw_tf(100, "ptz_base", "camera", 0.0, 0.05, 0.2),
            _yaw_tf(200, "ptz_base", "camera", 0.0, 0.05, 0.6),
            _yaw_tf(0, "base_link", "laser", 0.2, 0.0, math.pi, static=True),
        ]
    )
    # at the midpoint the pan angle interpolates to 0.4
    x, y, th = tree.planar("base_link", "camera", 150)
    want = compose(np.array([[0.1, 0.0, 0.0]]), np.array([[0.0, 0.05, 0.4]]))[0]
    np.testing.assert_allclose([x, y, th], want, atol=1e-12)
    # sibling lookup: laser -> camera goes up to base_link and down again
    T = tree.lookup("laser", "camera", 100)
    T_bl = tree.lookup("base_link", "laser", 100)
    T_bc = tree.lookup("base_link", "camera", 100)
    np.testing.assert_allclose(T, np.linalg.inv(T_bl) @ T_bc, atol=1e-12)
    assert T[2, 3] == pytest.approx(1.0)
    np.testing.assert_allclose(tree.lookup("camera", "base_link", 100), np.linalg.inv(T_bc), atol=1e-12)


def test_nearest_within_tolerance_and_errors():
    tree = TransformTree(
        [_yaw_tf(1_000, "a", "b", 1.0, 0.0, 0.0), _yaw_tf(2_000, "a", "b", 2.0, 0.0, 0.0)], tolerance_ns=500
    )
    assert tree.planar("a", "b", 2_400)[0] == pytest.approx(2.0)
    assert tree.planar("a", "b", 600)[0] == pytest.approx(1.0)
    with pytest.raises(TransformLookupError, match="not known at stamp 3000"):
        tree.lookup("a", "b", 3_000)
    with pytest.raises(TransformLookupError, match="no transform connects 'a' and 'zz'"):
        tree.lookup("a", "zz", 1_000)
    assert tree.can_transform("b", "a") and not tree.can_transform("a", "zz")
    np.testing.assert_array_equal(tree.lookup("q", "q", 0), np.eye(4))


def test_second_parent_is_reported_not_silently_used():
    tree = TransformTree([_yaw_tf(0, "a", "b", 1, 0, 0, True), _yaw_tf(0, "c", "b", 5, 0, 0, True)])
    assert tree.conflicts and "two parents" in tree.conflicts[0]
    assert tree.planar("a", "b", 0)[0] == pytest.approx(1.0)


angles = st.floats(-3.1, 3.1)


@settings(max_examples=50, deadline=None)
@given(a=angles, b=angles, u=st.floats(0.0, 1.0))
def test_interpolated_yaw_lies_on_the_short_arc(a, b, u):
    tree = TransformTree([_yaw_tf(0, "w", "r", 0, 0, a), _yaw_tf(1_000_000, "w", "r", 0, 0, b)])
    stamp = int(round(u * 1_000_000))
    u = stamp / 1_000_000
    th = tree.planar("w", "r", stamp)[2]
    d = (b - a + math.pi) % (2 * math.pi) - math.pi
    want = (a + u * d + math.pi) % (2 * math.pi) - math.pi
    assert abs((th - want + math.pi) % (2 * math.pi) - math.pi) < 1e-6


@settings(max_examples=50, deadline=None)
@given(yaw=angles)
def test_yaw_from_quaternion_round_trip(yaw):
    assert yaw_from_quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)) == pytest.approx(
        yaw, abs=1e-12
    )
