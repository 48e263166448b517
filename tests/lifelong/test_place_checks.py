"""A robot checks on the objects of its map: the simulated camera aims at a remembered object's place
(``sim.sensors.camera_snapshots``' ``remembered``) and, where the object was removed, keeps an image that holds
the place empty; the image's camera pose and intrinsics reach holoslam through the log, and
``frustum.covering_images`` counts it as evidence of absence, so ``classify`` calls the object gone without
any time in view. A present label that faces away from the camera is never counted, whatever is at its place."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from holoslam.lifelong.changes import ChangeConfig, classify
from holoslam.lifelong.frustum import FrustumConfig, camera_views, covering_images, world_cameras
from holoslam.store.records import ObjectState

GONE = "O05"  # the cup on the coffee table, label at (1.8, 3.56, 0.5) facing -y
TURNED = "O90"  # a box put at the cup's place the day after, its label facing away (+y)


def _two_days():
    """Day 1's world (the robot's map) and day 2's: the cup removed, a box at its place with its label turned
    away; a 32 s drive past the place, 1 m in front of it, along +x."""
    from holoslam.sim.world import reference_household

    day1 = reference_household()
    cup = day1.object(GONE)
    box = dataclasses.replace(cup, object_id=TURNED, kind="box", label_yaw=math.pi / 2,
                              payload=cup.payload.replace(GONE, TURNED).replace("cup", "box"))
    day2 = dataclasses.replace(day1, objects=tuple(o for o in day1.objects if o.object_id != GONE) + (box,))
    stamps = 1_700_000_000_000_000_000 + np.arange(0, 32 * 20 + 1, dtype=np.int64) * 50_000_000
    s = np.linspace(0.0, 1.0, len(stamps))
    wTb = np.stack([cup.position[0] - 0.6 + 1.2 * s, np.full_like(s, cup.position[1] - 1.0), np.zeros_like(s)], 1)
    return day1, day2, box, stamps, wTb


def _run(world, stamps, wTb, remembered):
    from holoslam.sim import SimConfig
    from holoslam.sim.core import SimulatedRun
    from holoslam.sim.sensors import camera_snapshots, compass, laser_scans, odometry

    def rng(k):
        return np.random.default_rng(np.random.SeedSequence([7, k]))

    snaps = camera_snapshots(world, stamps, wTb, rng(4), remembered=remembered)
    return SimulatedRun(SimConfig(seed=7, duration_s=32.0), world, stamps, wTb, odometry(stamps, wTb, rng(1)),
                        compass(world, stamps, wTb, rng(2)), laser_scans(world, stamps, wTb, rng(3)), tuple(snaps))


def test_without_a_map_the_camera_aims_only_at_labels():
    day1, day2, _box, stamps, wTb = _two_days()
    run = _run(day2, stamps, wTb, ())
    assert run.snapshots and all(s.target_id in s.visible_ids and not s.checked_id for s in run.snapshots)


@pytest.fixture(scope="module")
def day2_log(tmp_path_factory):
    from holoslam.io.mcap import read_log
    from holoslam.sim.writer import write_household_log

    day1, day2, box, stamps, wTb = _two_days()
    run = _run(day2, stamps, wTb, day1.objects)
    path = tmp_path_factory.mktemp("days") / "day_02.mcap"
    write_household_log(run, path)
    log, _ = read_log(path, require=["odometry"])
    return day1, box, stamps, wTb, run, log


def test_the_camera_checks_the_remembered_place_and_keeps_it_empty(day2_log):
    _day1, _box, _stamps, _wTb, run, _log = day2_log
    checks = [s for s in run.snapshots if s.checked_id == GONE]
    assert len(checks) >= 2  # a first view and a second from 0.5 m away, as for a label
    assert all(GONE not in s.visible_ids and TURNED not in s.visible_ids and not s.target_id for s in checks)
    assert all(s.jpeg for s in checks)  # real rendered images
    # present objects of the map are read as labels, never "checked" empty
    assert {s.checked_id for s in run.snapshots} <= {GONE, ""}


def test_images_of_the_empty_place_reach_holoslam_and_make_it_gone(day2_log):
    day1, box, stamps, wTb, run, log = day2_log
    views = camera_views(log)
    assert len(views) == len(run.snapshots)  # every image with its camera transform and intrinsics
    wTc = world_cameras(views, stamps, wTb)
    cup = day1.object(GONE)
    facing = np.array([math.cos(cup.label_yaw), math.sin(cup.label_yaw)])  # the side it was seen from
    n = covering_images(np.array(cup.position), facing, cup.payload, views, wTc, None, FrustumConfig())
    assert n >= 2
    # the box at the same place, its label seen before from the other side: its side never faces the camera
    away = np.array([math.cos(box.label_yaw), math.sin(box.label_yaw)])
    assert covering_images(np.array(box.position), away, box.payload, views, wTc, None, FrustumConfig()) == 0
    stored = {o: ObjectState(o, k, p, "seen", np.array(xyz[:2]), xyz[2], np.eye(2) * 1e-4, 2, f"{o}#1", view=v)
              for o, k, p, xyz, v in ((GONE, "cup", cup.payload, cup.position, facing),
                                      (TURNED, "box", box.payload, box.position, away))}
    images = {GONE: n, TURNED: 0}
    far = np.full((len(stamps), 2), 50.0)  # no time in view: the images alone decide
    assert classify(stored, {}, stamps, far, None, ChangeConfig(), None, images) == {GONE: "gone"}
    assert classify(stored, {}, stamps, far, None, ChangeConfig(), None, {GONE: 0, TURNED: 0}) == {}


def _standing(seconds=14.0):
    """The robot stands 1 m in front of the cup's place, facing it (a station near it), then the log ends."""
    from holoslam.sim.world import reference_household

    cup = reference_household().object(GONE)
    stamps = 1_700_000_000_000_000_000 + np.arange(0, int(seconds * 20) + 1, dtype=np.int64) * 50_000_000
    wTb = np.tile([cup.position[0], cup.position[1] - 1.0, math.pi / 2], (len(stamps), 1))
    return stamps, wTb


def _views_of(snaps):
    """The snapshots as holoslam reads them from a log: stamps, base -> camera transforms, intrinsics, sizes."""
    from holoslam.lifelong.frustum import CameraViews
    from holoslam.sim.camera import camera_pose_world

    bTc = np.repeat(np.eye(4)[None], len(snaps), 0)
    for k, s in enumerate(snaps):
        bTc[k, :3, :3], bTc[k, :3, 3] = camera_pose_world(np.zeros(3), s.pan, s.tilt)
    return CameraViews(np.array([s.stamp_ns for s in snaps], np.int64), bTc, np.array([s.K for s in snaps]),
                       np.repeat([[640.0, 480.0]], len(snaps), 0))


def test_a_place_found_empty_is_looked_at_again_before_the_robot_leaves():
    """The removed objects' places of the simulated days got one check where the robot stood at a station near
    them and left before a point 0.5 m away (a label's second-view baseline): a place's second look needs no
    baseline and comes before the labels never photographed, so two images hold it and it is gone."""
    from holoslam.sim.sensors import camera_snapshots

    day1, day2, _box, _s, _w = _two_days()
    stamps, wTb = _standing()
    snaps = camera_snapshots(day2, stamps, wTb, np.random.default_rng(3), render=False, remembered=day1.objects)
    checks = [k for k, s in enumerate(snaps) if s.checked_id == GONE]
    assert checks[:2] == [0, 1]  # the first image and, next, its second look (not the nearby labels first)
    assert len(checks) == 2  # later ones only after resnap_s
    targets = [s.target_id for s in snaps if s.target_id]
    assert targets and len(targets) == len(set(targets))  # a label's second view still waits for 0.5 m
    views = _views_of(snaps)
    wTc = world_cameras(views, stamps, wTb)
    cup = day1.object(GONE)
    facing = np.array([math.cos(cup.label_yaw), math.sin(cup.label_yaw)])
    n = covering_images(np.array(cup.position), facing, cup.payload, views, wTc, None, FrustumConfig())
    assert n == 2
    stored = {GONE: ObjectState(GONE, "cup", cup.payload, "seen", np.array(cup.position[:2]), cup.position[2],
                                np.eye(2) * 1e-4, 2, f"{GONE}#1", view=facing)}
    far = np.full((len(stamps), 2), 50.0)  # no time in view: the images alone decide
    assert classify(stored, {}, stamps, far, None, ChangeConfig(), None, {GONE: n}) == {GONE: "gone"}


def test_the_route_stops_in_front_of_the_places_of_its_map():
    """A robot that checks on the objects of its map stops in front of a remembered place no object stands at
    (the removed cup's) as in front of an object; an object still at its place keeps its one station, and a first
    day (no map) has the stations of its objects only."""
    from holoslam.sim.route import plan_stations

    day1, day2, _box, _s, _w = _two_days()
    ids = [s.object_id for s in plan_stations(day2, remembered=day1.objects) if s.object_id]
    assert ids.count(GONE) == 1 and len(ids) == len(set(ids))
    alone = [s.object_id for s in plan_stations(day2) if s.object_id]
    assert GONE not in alone and sorted(alone + [GONE]) == sorted(ids)


def test_the_robot_checks_a_removed_objects_place_until_a_check_finds_it_empty():
    """The simulated days plan the checks from the robot's own map (``sim.days.robot_map``: each object where an
    image last read it), not from the day before's truth: the cup read on day 1 and taken away before day 2, on a
    day the robot never looked at its place, is still in the map on day 3, whose route stops in front of its place
    and whose camera checks it; one image of the place held empty is not enough to forget it, two are, and day 4
    neither stops nor aims there. The box at the cup's place, its label read from behind on day 2, joins the map."""
    from holoslam.sim.days import FORGET_EMPTY_IMAGES, robot_map
    from holoslam.sim.route import plan_stations
    from holoslam.sim.sensors import camera_snapshots

    day1, day2, _box, stamps, wTb = _two_days()
    cup = day1.object(GONE)
    memory = robot_map({}, day1, camera_snapshots(day1, stamps, wTb, np.random.default_rng(1), render=False))
    assert memory[GONE] == cup and TURNED not in memory
    # day 2: the cup is gone; the robot drives behind the label's place (its side facing away): no check of it
    behind = wTb + np.array([0.0, 2.0, 0.0])
    snaps2 = camera_snapshots(day2, stamps, behind, np.random.default_rng(2), render=False,
                              remembered=tuple(memory.values()))
    assert not any(s.checked_id == GONE for s in snaps2)
    memory = robot_map(memory, day2, snaps2)
    assert memory[GONE] == cup  # the day before's truth would have dropped it
    assert memory[TURNED] == day2.object(TURNED)  # read on day 2: where it stands
    # day 3 (the home as on day 2): the route stops in front of the place, the camera checks it and finds it empty
    assert GONE in [s.object_id for s in plan_stations(day2, remembered=tuple(memory.values()))]
    snaps3 = camera_snapshots(day2, stamps, wTb, np.random.default_rng(3), render=False,
                              remembered=tuple(memory.values()))
    checks = [s for s in snaps3 if s.checked_id == GONE]
    assert len(checks) >= FORGET_EMPTY_IMAGES and all(GONE not in s.visible_ids for s in checks)
    first = [s for s in snaps3 if s is not checks[1]]  # a day whose second look never came
    assert GONE in robot_map(memory, day2, first)
    memory = robot_map(memory, day2, snaps3)
    assert GONE not in memory and TURNED in memory
    # day 4: nothing left to check there
    assert GONE not in [s.object_id for s in plan_stations(day2, remembered=tuple(memory.values()))]
    snaps4 = camera_snapshots(day2, stamps, wTb, np.random.default_rng(4), render=False,
                              remembered=tuple(memory.values()))
    assert not any(s.checked_id == GONE for s in snaps4)
