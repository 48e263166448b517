"""benchmarks/lifelong_truth.py: the simulated days' changes as the day's camera could have observed them (issue 27:
an object moved where nothing of the day could photograph it is "not seen although its place was in view", gone,
and found again moved against its last known place; a gone waits for its place to be photographable; an added
object is new on the first day it can be photographed), decided from the truth alone."""

from __future__ import annotations

import math

import numpy as np
import pytest
from repo_paths import benchmark_module

from holoslam.sim.world import World, WorldObject


@pytest.fixture(scope="module")
def lt():
    return benchmark_module("lifelong_truth")


def _obj(oid: str, x: float, y: float, yaw: float, z: float = 0.5) -> WorldObject:
    return WorldObject(oid, "cup", "room", f"holo:{oid};k=cup;s=60", (x, y, z), yaw, 0.06)


def _home(*objects: WorldObject, walls=()) -> World:
    return World(20.0, 20.0, (), tuple(walls), (), (), tuple(objects))


def _cam_at(o: WorldObject, r: float, off_deg: float = 0.0, z: float | None = None) -> np.ndarray:
    a = o.label_yaw + math.radians(off_deg)
    return np.array([[o.position[0] + r * math.cos(a), o.position[1] + r * math.sin(a),
                      o.position[2] if z is None else z]])


def test_the_cameras_reading_limits(lt):
    o = _obj("O05", 5.0, 5.0, 0.0)
    w = _home(o)
    assert lt.readable_mask(w, o, _cam_at(o, 1.0, 59.0))[0]  # the camera reads to 60 deg from the normal
    assert not lt.readable_mask(w, o, _cam_at(o, 1.0, 61.0))[0]
    assert not lt.readable_mask(w, o, _cam_at(o, 1.0, 180.0))[0]  # its back
    assert not lt.readable_mask(w, o, _cam_at(o, 0.5, 0.0, z=1.10))[0]  # 50 deg below the camera: tilt 45 at most
    far = lt.max_read_m(o)
    assert 3.0 < far < 6.0  # a 6 cm code with 3 px modules at 10x
    assert lt.readable_mask(w, o, _cam_at(o, 0.95 * far))[0]
    assert not lt.readable_mask(w, o, _cam_at(o, 1.05 * far))[0]
    walled = _home(o, walls=[(6.0, 3.0, 6.0, 7.0)])  # a wall 1 m in front of it
    assert not lt.readable_mask(walled, o, _cam_at(o, 2.0))[0]
    assert lt.readable_mask(walled, o, _cam_at(o, 0.8))[0]
    assert lt.photographable_s(w, o, np.vstack([_cam_at(o, 1.0), _cam_at(o, 1.0, 90.0)]), 0.25) == pytest.approx(0.25)


def test_a_move_out_of_sight_is_gone_then_moved_and_gone_waits_for_its_place(lt):
    cup_a, remote = _obj("O05", 2.0, 2.0, 0.0), _obj("O06", 2.0, 8.0, 0.0)
    cup_b = _obj("O05", 12.0, 2.0, math.pi)  # facing away from the camera in front of its old place
    added = _obj("O36", 12.0, 12.0, 0.0)
    cam_a, cam_r, cam_b, cam_n = (_cam_at(cup_a, 1.5), _cam_at(remote, 1.5), _cam_at(cup_b, 1.5),
                                  _cam_at(added, 1.5))
    assert not lt.readable_mask(_home(cup_b), cup_b, cam_a)[0]
    worlds = [_home(cup_a, remote), _home(cup_b, added), _home(cup_b, added), _home(cup_b, added)]
    cams = [np.vstack([cam_a, cam_r]), cam_a, np.vstack([cam_a, cam_n]), np.vstack([cam_b, cam_r])]
    # the images read what the poses could photograph (the simulator's record): both rules agree
    read = [["O05", "O06"], [], ["O36"], ["O05"]]
    truth = {"days": [{"objects": {"O05": [], "O06": []}, "photographed": read[0]}]
             + [{"objects": {}, "photographed": r} for r in read[1:]]}
    for rule in ("read", "photographable"):
        obs = lt.observable_truth(truth, worlds, cams, rule)
        # day 2: the cup moved where nothing photographed it, its old place photographed: gone; the remote's place
        # not photographable: its gone waits; the added object not photographable: not new yet
        assert obs.days[1] == {"O05": "gone"}
        assert obs.days[2] == {"O36": "new"}  # photographed; the cup's empty place again: already gone
        assert obs.days[3] == {"O05": "moved", "O06": "gone"}  # the cup found, moved against its last known place


def test_an_object_at_its_place_out_of_sight_and_a_visible_move_on_its_day(lt):
    cup_a, cup_b = _obj("O05", 2.0, 2.0, 0.0), _obj("O05", 2.0, 4.0, 0.0)
    worlds = [_home(cup_a), _home(cup_a), _home(cup_b)]
    cams = [_cam_at(cup_a, 1.0), _cam_at(cup_a, 1.0, 180.0), _cam_at(cup_b, 1.0)]
    truth = {"days": [{"objects": {"O05": []}}, {"objects": {}}, {"objects": {}}]}
    obs = lt.observable_truth(truth, worlds, cams, "photographable")
    assert obs.days[1] == {}  # at its place, not photographable: no change
    assert obs.days[2] == {"O05": "moved"}  # 2 m, photographable on its day
    assert lt.observable_truth(truth, worlds, cams).days[2] == {}  # the goal's rule: read in no image, not seen
    # read in the day's images (the simulator's record) counts as observable whatever the geometry says
    truth["days"][0]["photographed"] = truth["days"][2]["photographed"] = ["O05"]
    for rule in ("read", "photographable"):
        obs = lt.observable_truth(truth, worlds, [cams[0], cams[1], cams[1]], rule)
        assert obs.days[2] == {"O05": "moved"}


def _image_at(lt, o: WorldObject, r: float, off_deg: float = 0.0, aim_off_deg: float = 0.0, zoom: float = 8.0):
    """An image taken from a base ``r`` m in front of ``o``'s label (``off_deg`` around its normal), the head
    aimed at the label (``aim_off_deg`` of pan away from it) at ``zoom``."""
    from holoslam.sim.camera import camera_pose_world, intrinsics

    a = o.label_yaw + math.radians(off_deg)
    base = np.array([o.position[0] + r * math.cos(a), o.position[1] + r * math.sin(a), a + math.pi])
    _, c = camera_pose_world(base, 0.0, 0.0)
    rel = np.asarray(o.position) - c
    pan = math.atan2(rel[1], rel[0]) - base[2] + math.radians(aim_off_deg)
    tilt = math.atan2(rel[2], math.hypot(rel[0], rel[1]))
    wRc, wtc = camera_pose_world(base, pan, tilt)
    return lt.ImageCamera(0, intrinsics(zoom), wRc, wtc, (640, 480))


def test_an_image_reads_a_label_only_aimed_at_it_facing_it_and_with_nothing_between(lt):
    o = _obj("O05", 5.0, 5.0, 0.0)
    w = _home(o)
    assert lt.image_reads(w, o, [_image_at(lt, o, 1.5)]) == 1
    assert lt.image_reads(w, o, [_image_at(lt, o, 1.5), _image_at(lt, o, 2.0, 30.0)]) == 2
    assert lt.image_reads(w, o, [_image_at(lt, o, 1.5, aim_off_deg=20.0)]) == 0  # aimed elsewhere: off the picture
    assert lt.image_reads(w, o, [_image_at(lt, o, 1.5, 70.0)]) == 0  # 70 deg off its normal
    assert lt.image_reads(w, o, [_image_at(lt, o, 3.0, zoom=1.0)]) == 0  # 6 cm at 3 m, zoom 1: modules under 3 px
    walled = _home(o, walls=[(6.0, 3.0, 6.0, 7.0)])
    assert lt.image_reads(walled, o, [_image_at(lt, o, 1.5)]) == 0


def test_the_goals_rule_counts_a_label_seen_only_when_an_image_read_it(lt):
    """The goal's rule ("read"): an object moved where the day's poses could photograph it but no image read it is
    gone that day when its old place was in view, and moved on the day an image reads it; the photographable rule
    calls it moved on the first day. An added object is new on the day an image reads it."""
    cup_a, cup_b = _obj("O05", 2.0, 2.0, 0.0), _obj("O05", 12.0, 2.0, 0.0)
    added = _obj("O36", 12.0, 12.0, 0.0)
    worlds = [_home(cup_a), _home(cup_b, added), _home(cup_b, added), _home(cup_b, added)]
    poses = [_cam_at(cup_a, 1.5), np.vstack([_cam_at(cup_a, 1.5), _cam_at(cup_b, 1.5), _cam_at(added, 1.5)]),
             _cam_at(cup_b, 1.5), _cam_at(cup_b, 1.5)]
    truth = {"days": [{"objects": {"O05": []}, "photographed": ["O05"]}, {"objects": {}}, {"objects": {}},
                      {"objects": {}, "photographed": ["O05", "O36"]}]}
    assert lt.observable_truth(truth, worlds, poses, "photographable").days[1:] == [
        {"O05": "moved", "O36": "new"}, {}, {}]
    # day 2: read in no image, its old place in view: gone; day 3 nothing read; day 4 both read
    assert lt.observable_truth(truth, worlds, poses).days[1:] == [{"O05": "gone"}, {}, {"O05": "moved", "O36": "new"}]
    # an old place not in view: the gone waits (and the move is reported on the day it is read)
    poses[1] = _cam_at(cup_b, 1.5)
    assert lt.observable_truth(truth, worlds, poses).days[1:] == [{}, {}, {"O05": "moved", "O36": "new"}]
    with pytest.raises(ValueError):
        lt.observable_truth(truth, worlds, poses, "images")
