"""The camera's images as evidence: a place counts as held by an image only inside its frustum, in range, facing
it, large enough to read, and with free space in between (``holoslam.lifelong.frustum``); ``classify`` calls an
object gone from ``min_images`` such images even without the time in view."""

from __future__ import annotations

import numpy as np

from holoslam.lifelong.changes import ChangeConfig, classify
from holoslam.lifelong.frustum import CameraViews, FrustumConfig, covering_images, module_count, world_cameras
from holoslam.lifelong.merge import merge_submaps, overlay
from holoslam.store.records import ObjectState

PAYLOAD = "HL1;O05;cup;f=1,g=handle,m=0.3,s=60"  # a 60 mm label


def _views(n=1, f=5000.0):
    """n images from a camera 1 m above the base looking along the base's x axis (optical: z forward)."""
    bTc = np.eye(4)
    bTc[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    bTc[2, 3] = 1.0
    K = np.array([[f, 0, 320.0], [0, f, 240.0], [0, 0, 1]])
    return CameraViews(np.arange(n, dtype=np.int64) * 10**9, np.repeat(bTc[None], n, 0), np.repeat(K[None], n, 0),
                       np.repeat([[640.0, 480.0]], n, 0))


def test_an_image_holds_a_place_only_when_it_could_read_it_there():
    v = _views(2)
    wTc = world_cameras(v, np.array([0, 10**9], np.int64), np.zeros((2, 3)))
    cfg = FrustumConfig()
    assert 25 <= module_count(PAYLOAD) <= 33
    facing = np.array([-1.0, 0.0])  # the label was seen from -x: it faces the camera
    assert covering_images(np.array([2.0, 0.0, 1.0]), facing, PAYLOAD, v, wTc, None, cfg) == 2
    assert covering_images(np.array([2.0, 0.5, 1.0]), facing, PAYLOAD, v, wTc, None, cfg) == 0  # off the picture
    assert covering_images(np.array([-2.0, 0.0, 1.0]), None, PAYLOAD, v, wTc, None, cfg) == 0  # behind the camera
    assert covering_images(np.array([2.0, 0.0, 1.0]), -facing, PAYLOAD, v, wTc, None, cfg) == 0  # faces away
    # 60 mm / 29 modules at 3.4 m and f = 5000 px: 3 px a module, below the 4 px it takes to read it
    assert covering_images(np.array([3.4, 0.0, 1.0]), facing, PAYLOAD, v, wTc, None, cfg) == 0
    wide = _views(2, f=500.0)  # zoom 1: the same place is too small to read
    assert covering_images(np.array([2.0, 0.0, 1.0]), facing, PAYLOAD, wide, wTc, None, cfg) == 0
    prob = np.full((40, 80), 0.1, np.float32)
    prob[:, 20:22] = 0.9  # a wall at x = 1
    wall = merge_submaps(np.zeros((1, 3)), [(prob, np.ones_like(prob, bool), (0.0, -1.0), 0.05)], [1])
    assert covering_images(np.array([2.0, 0.0, 1.0]), facing, PAYLOAD, v, wTc, wall, cfg) == 0


def test_a_footprint_the_session_saw_free_no_longer_hides_a_place():
    """The view tests look through the home as the session's laser saw it (``merge.overlay``, used by
    ``session._join``): a chair the store holds between the camera and a place, carried away and its footprint
    seen free by today's laser, does not refuse today's checks of the place; what today's laser did not see keeps
    the store's cells."""
    v = _views(2)
    wTc = world_cameras(v, np.array([0, 10**9], np.int64), np.zeros((2, 3)))
    facing = np.array([-1.0, 0.0])
    prob = np.full((40, 80), 0.1, np.float32)
    prob[18:22, 20:28] = 0.9  # the chair's old footprint at x 1.0-1.4, y -0.1..0.1, on the line of sight
    stored = merge_submaps(np.zeros((1, 3)), [(prob, np.ones_like(prob, bool), (0.0, -1.0), 0.05)], [1])
    place = np.array([2.0, 0.0, 1.0])
    assert covering_images(place, facing, PAYLOAD, v, wTc, stored, FrustumConfig()) == 0
    seen = np.full((10, 14), 0.1, np.float32)  # today's laser: the footprint's cells free (x 0.9-1.6, y -0.2..0.3)
    today = merge_submaps(np.zeros((1, 3)), [(seen, np.ones_like(seen, bool), (0.9, -0.2), 0.05)], [2], margin_m=0.0)
    sight = overlay(stored, today)
    assert covering_images(place, facing, PAYLOAD, v, wTc, sight, FrustumConfig()) == 2
    half = np.full((10, 4), 0.1, np.float32)  # today's laser saw only the footprint's first 0.2 m
    part = merge_submaps(np.zeros((1, 3)), [(half, np.ones_like(half, bool), (1.0, -0.2), 0.05)], [2], margin_m=0.0)
    assert covering_images(place, facing, PAYLOAD, v, wTc, overlay(stored, part), FrustumConfig()) == 0
    far = merge_submaps(np.zeros((1, 3)), [(seen, np.ones_like(seen, bool), (5.0, 5.0), 0.05)], [2], margin_m=0.0)
    grown = overlay(stored, far)  # the union of both extents, the store's cells kept
    assert grown.known.sum() == stored.known.sum() + far.known.sum()
    assert overlay(stored, None) is stored


def test_images_make_an_object_gone_without_time_in_view():
    stored = {"A": ObjectState("A", "cup", PAYLOAD, "seen", np.array([20.0, 20.0]), 1.0, np.eye(2) * 1e-4, 2,
                               "A#1", view=np.array([-1.0, 0.0]))}
    t = np.arange(5, dtype=np.int64) * 10**8
    xy = np.zeros((5, 2))  # the robot far away: no time in view
    view_s: dict[str, float] = {}
    assert classify(stored, {}, t, xy, None, ChangeConfig(), view_s, {"A": 1}) == {}
    assert view_s == {"A": 0.0}
    assert classify(stored, {}, t, xy, None, ChangeConfig(), None, {"A": 2}) == {"A": "gone"}
