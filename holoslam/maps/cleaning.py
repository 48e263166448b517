"""Map cleaning before thinning: the free space the topology and the holographic graph are built on.

A real occupancy map is full of sensor noise: free specks inside walls and in unexplored space, one-pixel
obstacles and table legs in the rooms, unknown pixels between laser beams. Thinned as they are, every speck
becomes a component, a cycle or a node of the topology (thousands on an office floor). Cleaning keeps the
significant part of the map, with documented minimum sizes (:class:`MapCleaning`):

1. **Free regions** (8-connected components of free cells, free = occupancy at or below ``free_thresh`` as
   :attr:`OccupancyGrid.free` counts it) smaller than ``min_free_area_m2`` (default 0.25 m^2, about a robot
   footprint) are dropped (become non-free).
2. **Obstacle islands**: the 4-connected components of non-free cells (occupied or unknown) that do not touch
   the map's edge, counted after step 1 (a dropped free speck inside an island is part of it). An island
   smaller than ``min_obstacle_area_m2`` (default 0.05 m^2: a table leg, a speck of noise) becomes free, so it
   makes no cycle of the skeleton; an island that encloses a free region (it touches more than one free
   region) is never filled, whatever its size, so no free region merges with another.
3. **Unknown cells** are not free (the robot has not seen them; map_server's convention): unknown inside free
   space is an obstacle island like an occupied one (rule 2, by its size). With
   ``unknown_islands="free"`` an island made only of unknown cells (no occupied cell: unexplored pixels the
   beams passed around) becomes free whatever its size; islands with an occupied cell follow rule 2.
4. **Spurs** are pruned after thinning (``topology.prune_spurs``: a spur shorter than ``prune_spur_m`` or
   ``spur_clearance_factor`` x the clearance at its junction leaves no node), which changes neither
   components nor cycles.

Hence, with the defaults and no further pre-processing (``erode_cells = close_cells = 0``), the topology of
any map has exactly one component per free region of at least ``min_free_area_m2`` and one independent cycle
per obstacle island of at least ``min_obstacle_area_m2`` (both counted on the map after step 1; with
``unknown_islands="free"``, per such island holding an occupied cell). Everything is two labellings of the map
(``cv2.connectedComponentsWithStats``) and gathers over the small islands' cells.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from holoslam.errors import MapError

__all__ = ["MapCleaning", "CleaningReport", "clean_free", "significant_counts"]

_UNKNOWN_RULES = ("obstacle", "free")


@dataclass(frozen=True, slots=True)
class MapCleaning:
    """Minimum sizes of map cleaning (module docstring). ``min_free_area_m2``: free regions below it are
    dropped (default 0.25 m^2, about a robot footprint); ``min_obstacle_area_m2``: obstacle islands inside free
    space below it are filled (default 0.05 m^2, e.g. 20 cells at 5 cm); ``unknown_islands``: ``"obstacle"``
    (default: unknown counts as an obstacle) or ``"free"`` (islands of unknown cells only are filled). Zero
    areas turn the corresponding step off."""

    min_free_area_m2: float = 0.25  # m^2: a free region smaller than a robot's footprint (0.5 x 0.5 m) is dropped
    min_obstacle_area_m2: float = 0.05  # m^2: an obstacle island smaller (a table leg, sensor noise) is filled
    unknown_islands: str = "obstacle"  # obstacle: unknown cells are not free (map_server); free: unknown-only islands filled

    def __post_init__(self) -> None:
        for name in ("min_free_area_m2", "min_obstacle_area_m2"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise MapError(f"map cleaning: {name} must be a non-negative area in m^2, got {v}")
        if self.unknown_islands not in _UNKNOWN_RULES:
            raise MapError(
                f"map cleaning: unknown_islands must be one of {', '.join(_UNKNOWN_RULES)}, "
                f"got {self.unknown_islands!r}"
            )

    def as_graph_attrs(self) -> dict:
        """Scalar graph attributes (``cleaning_<name>``) that record the cleaning a topology was built with."""
        return {f"cleaning_{k}": v for k, v in asdict(self).items()}

    @classmethod
    def from_graph_attrs(cls, attrs) -> MapCleaning | None:
        """The cleaning recorded by :meth:`as_graph_attrs` (None when the graph records none)."""
        keys = ("min_free_area_m2", "min_obstacle_area_m2", "unknown_islands")
        if not all(f"cleaning_{k}" in attrs for k in keys):
            return None
        return cls(*(attrs[f"cleaning_{k}"] for k in keys))


@dataclass(frozen=True, slots=True)
class CleaningReport:
    """What cleaning changed: free regions dropped and their cells, obstacle islands filled (of them, islands
    of unknown cells only) and their cells, and what is left: free regions and obstacle islands."""

    free_regions_dropped: int = 0
    free_cells_dropped: int = 0
    islands_filled: int = 0
    unknown_islands_filled: int = 0
    island_cells_filled: int = 0
    free_regions: int = 0
    islands: int = 0

    def as_graph_attrs(self) -> dict:
        return {f"cleaned_{k}": int(v) for k, v in asdict(self).items()}


def _islands(free: np.ndarray):
    """(labels (H, W) of the 4-connected non-free components (a view into cv2's padded label image; free cells
    have label 0), their areas in cells (index = label; 0 for label 0 and for the component that touches the
    map's edge, which is no island); number of labels)."""
    import cv2

    pad = cv2.copyMakeBorder((~free).view(np.uint8), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=1)
    n, lab, st, _ = cv2.connectedComponentsWithStats(pad, connectivity=4)
    outer = int(lab[0, 0])  # the frame's component: every non-free cell connected to the map's edge
    area = st[:, cv2.CC_STAT_AREA].astype(np.int64)
    area[0] = area[outer] = 0
    return lab[1:-1, 1:-1], area, n


def _regions_touched(
    cells: np.ndarray, owner: np.ndarray, region_lab: np.ndarray, n_owner: int
) -> np.ndarray:
    """(n_owner,) number of distinct free regions (labels > 0 of ``region_lab``) 8-adjacent to the cells
    (flat indices) of each owner (the island each cell belongs to). The cells are islands' cells, which never
    lie on the map's edge (a non-free cell there belongs to the edge's component), so every neighbour is
    inside the map."""
    h, w = region_lab.shape
    r, c = cells // w, cells % w
    reg = np.concatenate(
        [region_lab[r + dr, c + dc] for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc]
    ).astype(np.int64)
    own = np.tile(owner.astype(np.int64), 8)
    sel = reg > 0
    stride = int(region_lab.max()) + 1
    pairs = np.unique(own[sel] * stride + reg[sel])
    return np.bincount(pairs // stride, minlength=n_owner)


def clean_free(grid, cleaning: MapCleaning | None = None, free: np.ndarray | None = None):
    """(H, W) bool free space of ``grid`` after the cleaning of the module docstring, and what changed
    (:class:`CleaningReport`). ``free`` replaces the grid's free cells (e.g. pre-processed ones); unknown
    cells are the grid's."""
    import cv2

    c = cleaning or MapCleaning()
    free = np.ascontiguousarray(grid.free if free is None else np.asarray(free, dtype=bool))
    if free.shape != grid.shape:
        raise MapError(f"free mask shape {free.shape} differs from the grid's {grid.shape}")
    cell = grid.resolution * grid.resolution
    rep = {}
    # 1. free regions below the minimum area
    n, lab, st, _ = cv2.connectedComponentsWithStats(free.view(np.uint8), connectivity=8)
    area = st[:, cv2.CC_STAT_AREA].astype(np.int64)
    small = area * cell < c.min_free_area_m2
    small[0] = False
    if small.any():
        free = free & ~small[lab]
        rep["free_regions_dropped"] = int(small.sum())
        rep["free_cells_dropped"] = int(area[small].sum())
        n, lab, st, _ = cv2.connectedComponentsWithStats(free.view(np.uint8), connectivity=8)
    rep["free_regions"] = int(n - 1)
    # 2. and 3. obstacle islands below the minimum area (or of unknown cells only) that touch one free region
    ilab, iarea, n_i = _islands(free)
    fill = (iarea * cell < c.min_obstacle_area_m2) & (iarea > 0)
    unknown_only = np.zeros(n_i, dtype=bool)
    if c.unknown_islands == "free":
        occupied = np.zeros(n_i, dtype=bool)
        occupied[ilab[~grid.free & ~grid.unknown]] = True  # (a free speck dropped in step 1 is no obstacle)
        unknown_only = ~occupied & (iarea > 0)
        fill |= unknown_only
    if fill.any():
        cells = np.flatnonzero(fill[ilab])
        owner = ilab[cells // ilab.shape[1], cells % ilab.shape[1]]  # (ilab is a view: no flat copy)
        fill &= _regions_touched(cells, owner, lab, n_i) <= 1
        cells = cells[fill[owner]]
        free = free.copy()
        free.ravel()[cells] = True
        rep["islands_filled"] = int(fill.sum())
        rep["unknown_islands_filled"] = int((fill & unknown_only).sum())
        rep["island_cells_filled"] = int(cells.shape[0])
    rep["islands"] = int((iarea > 0).sum()) - rep.get("islands_filled", 0)
    return free, CleaningReport(**rep)


def significant_counts(grid, cleaning: MapCleaning | None = None) -> tuple[int, int]:
    """(free regions of at least ``min_free_area_m2``, obstacle islands of at least ``min_obstacle_area_m2``)
    counted on the map as the module docstring defines them: the components and independent cycles the
    topology of the cleaned map has."""
    _free, rep = clean_free(grid, cleaning)
    return rep.free_regions, rep.islands
