"""One robot description (``RunConfig.robot``) feeds planning, reach and the configuration space (issue 13)."""

from __future__ import annotations

import numpy as np
import pytest
from planning_maps import apartment_free

from holoslam.config import RobotConfig, RunConfig, from_mapping, to_mapping
from holoslam.errors import ConfigError
from holoslam.mapping import configuration_space, reach_model
from holoslam.maps.grid import OccupancyGrid
from holoslam.maps.holographic import ObjectInfo, ReachModel, build_holographic
from holoslam.maps.topology import clearance_map, topology_from_grid

RES = 0.05


def _keys(tree, prefix=""):
    for k, v in tree.items():
        if isinstance(v, dict):
            yield from _keys(v, f"{prefix}{k}.")
        else:
            yield f"{prefix}{k}"


def test_the_run_configuration_has_one_robot_radius_and_every_reach_setting():
    keys = list(_keys(to_mapping(RunConfig())))
    assert [k for k in keys if "radius" in k] == ["robot.radius_m"]
    assert [k for k in keys if "reach" in k] == [
        "robot.arm_reach_m", "robot.reach_through_m", "robot.reach_z_min_m", "robot.reach_z_max_m"
    ]
    # the reach model of a run is the robot description, field for field
    robot = RobotConfig(radius_m=0.3, arm_reach_m=0.7, reach_through_m=0.5, reach_z_min_m=0.1, reach_z_max_m=1.8)
    assert reach_model(robot) == ReachModel(robot_radius_m=0.3, arm_reach_m=0.7, z_min_m=0.1, z_max_m=1.8,
                                            reach_through_m=0.5)
    # ReachModel's own defaults are the robot description's (a caller without a config gets the same robot)
    assert reach_model(RobotConfig()) == ReachModel()


def test_a_robot_setting_in_its_old_place_says_where_it_went():
    with pytest.raises(ConfigError, match="'robot_radius_m' is now 'robot.radius_m'"):
        from_mapping(RunConfig, {"planning": {"robot_radius_m": 0.2}})
    with pytest.raises(ConfigError, match="'arm_reach_m' is now 'robot.arm_reach_m'"):
        from_mapping(RunConfig, {"holographic": {"arm_reach_m": 0.9}})
    with pytest.raises(ConfigError, match="robot: radius_m must be a finite number of metres"):
        from_mapping(RunConfig, {"robot": {"radius_m": -0.1}})
    assert from_mapping(RunConfig, {"robot": {"radius_m": 0.18}}).robot == RobotConfig(radius_m=0.18)


@pytest.fixture(scope="module")
def flat():
    grid = OccupancyGrid.from_free_mask(apartment_free(RES), RES)
    return grid, topology_from_grid(grid)


def test_reach_through_decides_the_box_in_the_middle_of_the_table(flat):
    """The synthetic flat's 1.2 x 0.8 m table holds a box in its middle, 0.4 m from the nearest edge: out of reach
    when the arm reaches 0.35 m over furniture (the default), within reach at 0.5 m."""
    grid, topo = flat
    box = [ObjectInfo("BOX-1", "box", np.array([1.6, 3.4, 0.5]))]
    default = build_holographic(grid, topo, objects=box, reach_model=reach_model(RobotConfig()))
    longer = build_holographic(grid, topo, objects=box, reach_model=reach_model(RobotConfig(reach_through_m=0.5)))
    assert default.degree("BOX-1") == 0 and longer.degree("BOX-1") >= 1


@pytest.mark.parametrize("radius", [0.2, 0.26, 0.4])
def test_the_configuration_space_keeps_the_cells_the_robot_centre_fits(flat, radius):
    grid, _ = flat
    cspace = configuration_space(grid, radius)
    clr = clearance_map(grid.free, RES)
    # every cell left free has the robot's radius of free space around it, and almost every such cell is kept
    assert np.all(clr[cspace.free] >= radius - RES)
    assert np.count_nonzero(cspace.free) >= 0.9 * np.count_nonzero(clr >= radius + RES)
