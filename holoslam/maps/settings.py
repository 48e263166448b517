"""The map stages' sections of the run configuration (``holoslam.config.RunConfig``: ``topology`` and
``holographic``), here so that ``holoslam topology`` reads its defaults without loading the rest of a run's
configuration (the front end's). ``holoslam.config`` re-exports them."""

from __future__ import annotations

from dataclasses import dataclass, field

from holoslam.maps.cleaning import MapCleaning
from holoslam.maps.holographic import PlaceParams
from holoslam.maps.rooms import RoomRules

__all__ = ["TopologyConfig", "HolographicConfig"]


@dataclass(frozen=True)
class TopologyConfig:
    """Thinning topology (``holoslam topology`` has the same settings and defaults as options): the free space
    is cleaned (``cleaning``: free regions and obstacle islands below a minimum area), optionally opened
    (``close_cells``) and eroded (``erode_cells``), thinned, and spurs shorter than ``prune_spur_m``, than
    ``spur_clearance_factor`` x the clearance at their junction, or than that clearance plus
    ``spur_robot_diameters`` x the robot's diameter are pruned (the graph's ``spurs_pruned`` says how many)."""

    prune_spur_m: float = 0.3  # m: a spur shorter than this leaves no node (a wall corner's thinning noise)
    spur_clearance_factor: float = 1.5  # a spur inside its junction's free disc (x this) leaves no node
    # robot diameters (2 x robot.radius_m): a dead-end branch that leaves its junction's free disc (its
    # clearance) by less than the robot's own body is a notch in a wall's scan, not a place the robot can drive
    # into (a side alcove or a doorway into a room is at least that deep: the body must fit in it). With the
    # default robot (0.26 m): 0.52 m beyond the junction's clearance
    spur_robot_diameters: float = 1.0
    erode_cells: int = 0  # cells: erode free space by a disc first (0: the topology of the map itself)
    # cells: open free space by a disc first, dropping free lines 1-2 cells wide (rays through gaps in walls).
    # 0, as holoslam topology: the topology then shows the map itself after the documented cleaning, so its
    # components and cycles are the map's significant free regions and obstacle islands; an opening of 1 closes
    # gaps of 1-2 cells between obstacles and merges their islands (aws_small_house 20 -> 15 cycles, office_a
    # furnished 224 -> 200). The rooms do not use it (their space is where a disc of half a door fits)
    close_cells: int = 0
    cleaning: MapCleaning = field(default_factory=MapCleaning)  # minimum sizes (holoslam.maps.cleaning)


@dataclass(frozen=True)
class HolographicConfig:
    """Place detection of the holographic graph: ``rooms``, the room segmentation (door and opening widths, the
    smallest room, wall thickness, furniture size: ``holoslam.maps.rooms``), and ``places``, the corridor places
    (crossings, dead ends). The robot's size and reach: ``robot``."""

    rooms: RoomRules = field(default_factory=RoomRules)
    places: PlaceParams = field(default_factory=PlaceParams)
