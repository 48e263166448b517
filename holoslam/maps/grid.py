"""The occupancy grid record shared by maps and planning.

A grid carries its geometry, so (row, col) never mixes with (x, y): cell (row, col) covers
x in [origin_x + col*res, origin_x + (col+1)*res), y in [origin_y + row*res, ...), i.e. row 0 is the lowest y
(nav_msgs/OccupancyGrid order; the map_server PGM stores rows top-down and is flipped by the io layer).
``occupancy`` holds nav_msgs values: -1 unknown, 0..100 probability of occupancy in percent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from holoslam.errors import MapError

__all__ = ["OccupancyGrid", "UNKNOWN", "world_to_cells", "cells_to_world"]

UNKNOWN = -1


@dataclass(frozen=True, slots=True)
class OccupancyGrid:
    occupancy: np.ndarray  # (H, W) int8: -1 unknown, 0..100
    resolution: float  # metres per cell
    origin_x: float = 0.0  # world position of the lower-left corner of cell (0, 0)
    origin_y: float = 0.0
    occupied_thresh: float = 0.65  # map_server convention, probabilities
    free_thresh: float = 0.196

    def __post_init__(self) -> None:
        occ = np.asarray(self.occupancy)
        if occ.ndim != 2 or occ.size == 0:
            raise MapError(f"an occupancy grid must be a non-empty 2-D array, got shape {occ.shape}")
        if not np.isfinite(self.resolution) or self.resolution <= 0:
            raise MapError(
                f"grid resolution must be a positive number of metres per cell, got {self.resolution}"
            )
        if not 0.0 <= self.free_thresh < self.occupied_thresh <= 1.0:
            raise MapError(
                f"thresholds must satisfy 0 <= free_thresh < occupied_thresh <= 1, got "
                f"{self.free_thresh} and {self.occupied_thresh}"
            )
        occ = np.ascontiguousarray(occ, dtype=np.int8)
        occ.setflags(write=False)
        object.__setattr__(self, "occupancy", occ)

    @property
    def shape(self) -> tuple[int, int]:
        return self.occupancy.shape

    @property
    def free(self) -> np.ndarray:
        """(H, W) bool: known and below the free threshold."""
        o = self.occupancy
        return (o >= 0) & (o <= self.free_thresh * 100.0)

    @property
    def occupied(self) -> np.ndarray:
        """(H, W) bool: at or above the occupied threshold."""
        return self.occupancy >= self.occupied_thresh * 100.0

    @property
    def unknown(self) -> np.ndarray:
        return self.occupancy < 0

    def world_to_cell(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) world points -> (N, 2) int (row, col); cells outside the grid are not clipped."""
        return world_to_cells(xy, self.origin_x, self.origin_y, self.resolution)

    def cell_to_world(self, rc: np.ndarray) -> np.ndarray:
        """(N, 2) (row, col) -> (N, 2) world (x, y) of the cell centres."""
        return cells_to_world(rc, self.origin_x, self.origin_y, self.resolution)

    def contains(self, rc: np.ndarray) -> np.ndarray:
        rc = np.asarray(rc).reshape(-1, 2)
        h, w = self.shape
        return (rc[:, 0] >= 0) & (rc[:, 0] < h) & (rc[:, 1] >= 0) & (rc[:, 1] < w)

    @classmethod
    def from_free_mask(
        cls, free: np.ndarray, resolution: float, origin_x: float = 0.0, origin_y: float = 0.0
    ):
        """A grid whose True cells are free (0) and False cells occupied (100)."""
        occ = np.where(np.asarray(free, dtype=bool), 0, 100).astype(np.int8)
        return cls(occ, resolution, origin_x, origin_y)


def world_to_cells(xy: np.ndarray, origin_x: float, origin_y: float, resolution: float) -> np.ndarray:
    """(N, 2) world points -> (N, 2) int64 (row, col) of the cells holding them, on the lattice whose cell
    (0, 0) has its lower-left corner at (origin_x, origin_y) (ROS map_server convention); not clipped."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    col = np.floor((xy[:, 0] - origin_x) / resolution).astype(np.int64)
    row = np.floor((xy[:, 1] - origin_y) / resolution).astype(np.int64)
    return np.column_stack([row, col])


def cells_to_world(rc: np.ndarray, origin_x: float, origin_y: float, resolution: float) -> np.ndarray:
    """(N, 2) (row, col) -> (N, 2) world (x, y) of the cell centres (``world_to_cells``' lattice)."""
    rc = np.asarray(rc, dtype=np.float64).reshape(-1, 2)
    return np.column_stack([origin_x + (rc[:, 1] + 0.5) * resolution, origin_y + (rc[:, 0] + 0.5) * resolution])
