"""The simulated large building (holoslam.sim.building, issue 26): the floor's size, corridors, rooms and loops,
the sparse laser of the held-out hospital log, the drive, and its MCAP log read back. A short drive here; the
80-minute one is measured by ``benchmarks/bench_memory.py --log building.mcap``."""

from __future__ import annotations

import numpy as np
import pytest

from holoslam.errors import ConfigError
from holoslam.sim.building import (
    BuildingPlan,
    building_config,
    building_world,
    simulate_building,
    simulate_building_to_file,
)


@pytest.fixture(scope="module")
def short_run():
    return simulate_building(building_config(duration_s=240.0))


def test_the_floor_is_a_350_m_building_of_corridors_and_rooms():
    w = building_world()
    assert (w.width, w.height) == (350.0, 110.0)
    walls = w.wall_segments()
    assert walls[:, [0, 2]].min() >= 0 and walls[:, [0, 2]].max() <= 350.0
    assert walls[:, [0, 2]].max() - walls[:, [0, 2]].min() > 340.0  # about 350 m across
    rooms = [r for r in w.rooms if r.name.startswith("room_")]
    assert 250 <= len(rooms) <= 400 and len(w.doorways) == len(rooms)
    corridors = [r for r in w.rooms if r.name.startswith("corridor_")]
    lengths = sorted(max(r.xmax - r.xmin, r.ymax - r.ymin) for r in corridors)
    assert len(corridors) == 7 and lengths[-1] > 340.0 and lengths[0] > 80.0
    for d in w.doorways:  # doors 0.9-1.2 m, rooms 4-8 m wide and 7 m deep
        assert 0.85 <= d.width <= 1.25
    for r in rooms:
        assert 3.95 <= r.xmax - r.xmin <= 8.05 and r.ymax - r.ymin == pytest.approx(7.0, abs=0.06)
    # the corridor graph's smallest loop: around one block between two east-west and two north-south corridors
    p = BuildingPlan()
    loop = 2 * (p.corridor_x_m[1] - p.corridor_x_m[0]) + 2 * (p.corridor_y_m[1] - p.corridor_y_m[0])
    assert loop > 300.0


def test_the_laser_is_the_hospital_logs(short_run):
    sc = short_run.scans
    dt = np.diff(sc.stamps_ns) * 1e-9
    assert np.allclose(dt, 1 / 1.4, atol=1e-6)
    assert sc.ranges.shape[1] == 180
    assert np.degrees(sc.angle_increment * 179) == pytest.approx(180.0)
    none = float(np.mean(~np.isfinite(sc.ranges)))
    assert 0.09 <= none <= 0.15  # about 12 % of beams return nothing (beyond 20 m, or dropped)
    finite = sc.ranges[np.isfinite(sc.ranges)]
    assert finite.max() <= 20.0


def test_the_drive_stays_in_the_corridors_and_rooms(short_run):
    from holoslam.sim.world import free_space

    w = short_run.world
    xy = short_run.wTb[:, :2]
    steps = np.hypot(*np.diff(xy, axis=0).T)
    assert steps.max() * 20.0 <= 0.81  # 20 Hz, at most 0.8 m/s
    assert 80.0 <= steps.sum() <= 240.0 * 0.8
    fs = free_space(w, resolution=0.1, seed_xy=(4.0, 12.0))
    assert np.all(fs.clearance_at(xy) >= 0.3)  # the robot (0.25 m radius) never touches a wall


def test_the_log_reads_back(tmp_path):
    from holoslam.io.mcap import read_log

    path = tmp_path / "building.mcap"
    s = simulate_building_to_file(path, duration_s=60.0)
    assert s["scans"] == 84 and s["messages"]["/scan"] == 84 and 0.05 < s["no_return"] < 0.2
    log, _report = read_log(path, require=["odometry", "scan"])
    assert len(log.scans) == 84 and len(log.odometry) == 1201 and log.ground_truth
    assert simulate_building_to_file(tmp_path / "again.mcap", duration_s=60.0)["bytes"] == s["bytes"]
    assert (tmp_path / "again.mcap").read_bytes() == path.read_bytes()  # deterministic


def test_a_drive_needs_a_duration():
    from holoslam.sim.core import SimConfig

    with pytest.raises(ConfigError, match="duration_s"):
        simulate_building(SimConfig(duration_s=None))
    with pytest.raises(ConfigError, match="laser_dropout"):
        SimConfig(laser_dropout=1.0)


def test_the_cli_writes_a_building_log(tmp_path, capsys):
    from holoslam.cli import main

    out = tmp_path / "b.mcap"
    assert main(["simulate", "--building", "--seed", "26", "--duration", "20", "-o", str(out)]) == 0
    assert out.is_file() and "scans: 28" in capsys.readouterr().out
    assert main(["simulate", "--building", "--duration", "0", "-o", str(out)]) == 2
    assert "--duration" in capsys.readouterr().err
