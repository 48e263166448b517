"""A large real test floor: the shared public maps stitched into one connected building (issue 26).

``building_floor()`` reads the maps of ``../shared/maps`` (map_server PGM + YAML) and ``../shared/rooms`` (the
room segmentation benchmark's PNG + YAML, plain and furnished), brings each to 5 cm (nav2_warehouse is 3 cm:
nearest-neighbour resampling), and places them side by side in rows (shelf packing, tallest first) on an
unknown background of ``width`` x ``height`` cells. Every row has a corridor below it (``corridor_m`` wide,
walled on both sides) and the rows' corridors are joined by a vertical corridor at the floor's west side, so
the corridors are one connected space. Each tile's largest free region is joined to the corridor below it by a
straight walled passage (``door_m`` wide) from the region's free cell nearest the corridor: the whole floor is
one building, its tiles the wings. When the maps do not fill the floor once, they are used again (the second
pass turned by 180 degrees), until the next tile no longer fits. The floor is built at test / benchmark time
from the shared data, never committed (``../shared`` is read in place).

``tile_runs(folders)`` adds the maps of run folders (``holoslam run`` on the shared Freiburg logs) as tiles.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from holoslam.maps.grid import OccupancyGrid

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
RESOLUTION = 0.05


@dataclass(frozen=True)
class Tile:
    name: str
    occ: np.ndarray  # (h, w) int8 trinary: 0 free, 100 occupied, -1 unknown; row 0 the lowest y


def _trinary(grid: OccupancyGrid, name: str) -> np.ndarray:
    import cv2

    free, occ = grid.free, grid.occupied
    if name == "nav2_depot":  # its README: grey 205 is unknown although the YAML's free_thresh makes it free
        free = grid.occupancy == 0
    out = np.full(grid.shape, -1, dtype=np.int8)
    out[occ] = 100
    out[free] = 0
    if abs(grid.resolution - RESOLUTION) > 1e-9:
        s = grid.resolution / RESOLUTION
        h, w = grid.shape
        out = cv2.resize(out.view(np.uint8), (round(w * s), round(h * s)), interpolation=cv2.INTER_NEAREST)
        out = out.view(np.int8)
    return out


def shared_tiles(shared: Path = SHARED) -> list[Tile]:
    """Every shared public map as a 5 cm trinary tile (maps/*.yaml, then rooms/*.yaml), in name order."""
    from holoslam.io.grid import read_grid

    tiles = []
    for folder in ("maps", "rooms"):
        for y in sorted((shared / folder).glob("*.yaml")):
            tiles.append(Tile(y.stem, _trinary(read_grid(y), y.stem)))
    return tiles


def tile_runs(folders: list[Path]) -> list[Tile]:
    """The ``map.yaml`` of run folders as tiles (e.g. the shared Freiburg logs mapped by ``holoslam run``)."""
    from holoslam.io.grid import read_grid

    return [Tile(Path(f).name, _trinary(read_grid(Path(f) / "map.yaml"), "")) for f in folders]


def _main_region_exit(occ: np.ndarray) -> tuple[int, int] | None:
    """(row, col) of the largest free region's cell with the lowest row (nearest the corridor below the tile,
    row 0 side), the most central such column; None when the tile has no free cell."""
    import cv2

    free = (occ == 0).astype(np.uint8)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(free, connectivity=8)
    if n < 2:
        return None
    main = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    rows, cols = np.nonzero(lab == main)
    low = rows.min()
    at = cols[rows == low]
    c = at[np.argmin(np.abs(at - occ.shape[1] / 2))]
    return int(low), int(c)


def building_floor(
    tiles: list[Tile] | None = None,
    *,
    width: int = 7000,
    height: int = 5000,
    corridor_m: float = 2.5,
    door_m: float = 1.2,
    wall_cells: int = 3,
    repeat: bool = True,
) -> OccupancyGrid:
    """The stitched floor (module docstring): an OccupancyGrid of (height, width) cells at 5 cm."""
    tiles = list(shared_tiles() if tiles is None else tiles)
    if repeat:  # a second pass of the same maps, turned by 180 degrees, used only as far as they fit
        tiles = tiles + [Tile(t.name + "_r180", t.occ[::-1, ::-1]) for t in tiles]
    first, second = tiles[: len(tiles) // 2 if repeat else len(tiles)], tiles[len(tiles) // 2 :] if repeat else []
    order = sorted(first, key=lambda t: -t.occ.shape[0]) + sorted(second, key=lambda t: -t.occ.shape[0])
    cor = int(round(corridor_m / RESOLUTION))
    door = int(round(door_m / RESOLUTION))
    band = cor + 2 * wall_cells  # a corridor with its two walls
    west = band  # the vertical corridor at the west side
    floor = np.full((height, width), -1, dtype=np.int8)
    placed: list[tuple[Tile, int, int]] = []
    row0, col, row_h = 0, west + 1, 0
    for t in order:
        h, w = t.occ.shape
        if col + w > width:  # next shelf
            row0, col, row_h = row0 + band + row_h + 1, west + 1, 0
        if row0 + band + h > height or col + w > width:
            continue  # does not fit: the floor is full for this tile
        placed.append((t, row0 + band, col))
        col += w + 1
        row_h = max(row_h, h)
    last_row = max((r for _, r, _ in placed), default=band) - band
    # corridors: a walled band below every shelf, and the west corridor joining them
    for r in sorted({r - band for _, r, _ in placed}):
        floor[r : r + band, :] = 100
        floor[r + wall_cells : r + wall_cells + cor, wall_cells : width - wall_cells] = 0
    floor[: last_row + band, :band] = np.where(floor[: last_row + band, :band] == 0, 0, 100)
    floor[wall_cells : last_row + band - wall_cells, wall_cells : wall_cells + cor] = 0
    for t, r, c in placed:
        h, w = t.occ.shape
        floor[r : r + h, c : c + w] = np.where(t.occ >= 0, t.occ, floor[r : r + h, c : c + w])
        ex = _main_region_exit(t.occ)
        if ex is None:
            continue
        er, ec = ex
        c0 = min(max(c + ec - door // 2, c), c + w - door)
        # the passage: free from the corridor (row r - wall_cells) up to the region's exit cell, walled
        top = r + er
        seg = floor[r - wall_cells : top + 1, c0 - wall_cells : c0 + door + wall_cells]
        seg[seg != 0] = 100
        floor[r - wall_cells : top + 1, c0 : c0 + door] = 0
    return OccupancyGrid(floor, RESOLUTION)
