"""The run's map stages, from the optimised trajectory: the occupancy grid of the scans, its thinning topology,
the rooms and the holographic graph (places, objects and how each is reached), and the two-layer planning graph
of the robot's configuration space (``build_maps`` -> ``RunMaps``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from holoslam import geometry as g

if TYPE_CHECKING:
    from holoslam.config import RobotConfig, RunConfig
    from holoslam.maps.grid import OccupancyGrid
    from holoslam.maps.holographic import ReachModel
    from holoslam.timing import StageClock
    from holoslam.trajectory import RunTrajectory

__all__ = ["RunMaps", "build_maps", "occupancy_grid", "holographic_graph", "reach_model", "configuration_space"]


@dataclass(frozen=True, eq=False)
class RunMaps:
    grid: Any  # OccupancyGrid
    topology: Any  # nx.MultiGraph
    holographic: Any  # nx.Graph
    rooms: Any  # holoslam.maps.rooms.RoomSegmentation: ids = the holographic graph's room nodes
    planning: Any  # holoslam.planning.twolayer.TwoLayerGraph


def build_maps(log: Any, fe: Any, sol: Any, traj: RunTrajectory, objects: tuple, cfg: RunConfig,
               clock: StageClock) -> RunMaps:
    """The stages ``occupancy grid``, ``topology (thinning)``, ``holographic graph`` and ``planning graph``."""
    from holoslam.maps.topology import topology_from_settings
    from holoslam.planning.twolayer import build_two_layer

    with clock.stage("occupancy grid"):
        grid = occupancy_grid(log, fe.bTs, traj, cfg)
    with clock.stage("topology (thinning)"):
        topology = topology_from_settings(grid, cfg.topology, anchors_wTa=sol.wTa, robot_radius_m=cfg.robot.radius_m)
    with clock.stage("holographic graph"):
        holo, rooms = holographic_graph(grid, topology, fe.submaps, sol.wTa, objects, cfg)
    with clock.stage("planning graph"):
        planning = build_two_layer(configuration_space(grid, cfg.robot.radius_m), cfg.planning.min_block_cells)
    return RunMaps(grid, topology, holo, rooms, planning)


def occupancy_grid(log: Any, bTs: np.ndarray, traj: RunTrajectory, cfg: RunConfig) -> OccupancyGrid:
    """The log's scans cast from the optimised sensor poses wTs = wTb ∘ bTs (``holoslam.maps.occupancy``)."""
    from holoslam.maps.occupancy import build_grid

    wTb_scan = traj.at_scans(log)
    wTs = g.compose(wTb_scan, np.broadcast_to(bTs, wTb_scan.shape))
    return build_grid(wTs, log.scans, cfg.grid.resolution, margin_m=cfg.grid.margin_m,
                      no_return_clear_m=cfg.grid.no_return_clear_m)


def _submap_features(submaps: Any) -> dict[int, dict[str, int]]:
    """Per submap, the sizes of its scan content (the holographic graph's submap node attributes)."""
    return {
        sm.index: {
            "n_scans": int(len(sm.scan_stamps_ns)),
            "n_points": int(len(sm.points)),
            "n_lines": int(len(sm.features.lines)),
            "n_corners": int(len(sm.features.corners)),
            "n_crossings": int(len(sm.features.crossings)),
        }
        for sm in submaps
    }


def holographic_graph(grid: Any, topology: Any, submaps: Any, wTa: np.ndarray, objects: tuple,
                      cfg: RunConfig) -> tuple[Any, Any]:
    """The rooms (``holoslam.maps.rooms``) and the holographic graph (``holoslam.maps.holographic``) of a run."""
    from holoslam.maps.holographic import build_holographic
    from holoslam.maps.passages import EdgePaths
    from holoslam.maps.rooms import rooms_of_grid

    edge_paths = EdgePaths(topology)
    rooms = rooms_of_grid(grid, topology, cfg.holographic.rooms, edge_paths)
    holo = build_holographic(
        grid,
        topology,
        anchors_wTa=wTa,
        submap_ids=[sm.index for sm in submaps],
        objects=objects,
        reach_model=reach_model(cfg.robot),
        params=cfg.holographic.places,
        submap_features=_submap_features(submaps),
        rooms=rooms,
        edge_paths=edge_paths,
    )
    return holo, rooms


def reach_model(robot: RobotConfig) -> ReachModel:
    """The holographic graph's reach model (``holoslam.maps.holographic.ReachModel``) of a robot description."""
    from holoslam.maps.holographic import ReachModel

    return ReachModel(robot_radius_m=robot.radius_m, arm_reach_m=robot.arm_reach_m, z_min_m=robot.reach_z_min_m,
                      z_max_m=robot.reach_z_max_m, reach_through_m=robot.reach_through_m)


def configuration_space(grid: Any, robot_radius_m: float) -> OccupancyGrid:
    """The grid with free space eroded by the robot radius: a free cell of the result is a place the robot's
    centre can be. Unknown and occupied cells both block."""
    import cv2

    from holoslam.maps.grid import OccupancyGrid

    r = int(np.ceil(robot_radius_m / grid.resolution))
    free = grid.free.astype(np.uint8)
    if r > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
        free = cv2.erode(free, k, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return OccupancyGrid.from_free_mask(free.astype(bool), grid.resolution, grid.origin_x, grid.origin_y)
