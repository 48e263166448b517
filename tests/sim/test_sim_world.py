"""The reference household: layout, labels, reachability, JSON round trip, ray casting."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from holoslam.sim.world import (
    ARM_REACH,
    ROBOT_RADIUS,
    free_space,
    raycast,
    reference_household,
    segments_block,
    world_from_json,
    world_to_json,
)
from holoslam.vision.label import parse_label


@pytest.fixture(scope="module")
def world():
    return reference_household()


def test_floor_plan_has_the_papers_rooms_and_size(world):
    assert (world.width, world.height) == (9.5, 10.5)
    names = {r.name for r in world.rooms}
    assert names == {"living_room", "dining_room", "kitchen", "study", "bedroom_1", "bedroom_2", "balcony"}
    area = sum((r.xmax - r.xmin) * (r.ymax - r.ymin) for r in world.rooms)
    assert area == pytest.approx(9.5 * 10.5)


def test_doorways_are_gaps_wide_enough_for_the_robot(world):
    walls = world.wall_segments()
    for d in world.doorways:
        assert d.width >= 0.8, d.name
        # the doorway centre line is crossable: a short segment through the gap hits no wall
        c = np.array(d.centre)
        along = np.subtract(d.p1, d.p0) / d.width
        normal = np.array([-along[1], along[0]])
        assert not segments_block(walls, (c - 0.3 * normal)[None], (c + 0.3 * normal)[None])[0], d.name
        # but the wall next to the gap blocks
        side = np.asarray(d.p0) - 0.2 * along
        assert segments_block(walls, (side - 0.3 * normal)[None], (side + 0.3 * normal)[None])[0], d.name


def test_35_labelled_objects_with_valid_payloads(world):
    assert len(world.objects) == 35
    ids = [o.object_id for o in world.objects]
    assert ids == [f"O{i:02d}" for i in range(1, 36)]
    kinds = {o.kind for o in world.objects}
    assert {"sofa", "air_conditioner", "cup", "chair", "tv", "fridge"} <= kinds
    for o in world.objects:
        lab = parse_label(o.payload)
        assert lab.object_id == o.object_id and lab.kind == o.kind
        assert lab.size_m == pytest.approx(o.label_size)
        assert 0.04 <= o.label_size <= 0.15
        assert 0.3 <= o.position[2] <= 2.1
        r = world.room_of(np.array([o.position[:2]]))[0]
        assert r == o.room, o.object_id


def test_exactly_the_dining_corner_chair_is_out_of_reach(world):
    unreachable = [o for o in world.objects if not o.reachable]
    assert [(o.kind, o.room) for o in unreachable] == [("chair", "dining_room")]
    fs = free_space(world)
    rr, cc = np.nonzero(fs.standable)
    pts = fs.xy_of(rr, cc)
    o = unreachable[0]
    d = np.hypot(*(pts - np.array(o.position[:2])).T)
    # no standable point within reach on the same side of the walls
    near = pts[d <= ARM_REACH]
    if len(near):
        assert segments_block(world.wall_segments(), near, np.broadcast_to(o.position[:2], near.shape)).all()
    assert (fs.clearance[fs.standable] >= ROBOT_RADIUS).all()


def test_world_json_round_trip(world):
    text = world_to_json(world)
    back = world_from_json(text)
    assert back == world
    assert world_to_json(back) == text


def test_raycast_hits_the_outer_wall_from_the_living_room(world):
    # from (3.0, 2.0) looking -y through the balcony door gap: wall y=0 at 2.0 m (balcony table is x 2.2-3.0)
    r = raycast(world.obstacle_segments(), np.array([[2.1, 2.0]]), np.array([[-math.pi / 2]]), 8.0)
    assert r[0, 0] == pytest.approx(2.0)
    # looking +x from (1.0, 0.7) on the balcony, above the table (y <= 0.55): washing machine face at x = 4.7
    r = raycast(world.obstacle_segments(), np.array([[1.0, 0.7]]), np.array([[0.0]]), 8.0)
    assert r[0, 0] == pytest.approx(3.7)
    # nothing within range -> inf
    r = raycast(np.array([[10.0, -1, 10.0, 1]]), np.array([[0.0, 0.0]]), np.array([[0.0]]), 8.0)
    assert np.isinf(r[0, 0])


@settings(max_examples=40, deadline=None)
@given(st.floats(-5, 5), st.floats(-5, 5), st.floats(-math.pi, math.pi), st.floats(0.5, 4.0))
def test_raycast_against_a_single_wall_matches_geometry(x, y, th, dist):
    # a long wall perpendicular to the ray at distance `dist`
    c, s = math.cos(th), math.sin(th)
    px, py = x + dist * c, y + dist * s
    seg = np.array([[px - 50 * s, py + 50 * c, px + 50 * s, py - 50 * c]])
    r = raycast(seg, np.array([[x, y]]), np.array([[th, th + math.pi]]), 8.0)
    assert r[0, 0] == pytest.approx(dist, abs=1e-9)
    assert np.isinf(r[0, 1])
