"""The stitched real test floor (tests/building_floor.py, issue 26): the shared maps joined into one building."""

from __future__ import annotations

import numpy as np
import pytest

from tests.building_floor import SHARED, building_floor, shared_tiles

pytestmark = pytest.mark.skipif(not (SHARED / "rooms").is_dir(), reason="needs ../shared/rooms")


def test_small_floor_is_one_building_of_the_shared_maps():
    import cv2

    tiles = [t for t in shared_tiles() if t.name in ("nav2_smoothers_world", "Freiburg52_scan", "lab_c_scan")]
    grid = building_floor(tiles, width=2000, height=1200, repeat=False)
    assert grid.shape == (1200, 2000) and grid.resolution == 0.05
    tile_free = sum(int((t.occ == 0).sum()) for t in tiles)
    free = grid.free
    # every tile's free cells are there, plus the corridors and passages (2.5 m x the floor's width at most)
    assert tile_free < free.sum() < tile_free + 2 * 2000 * 60
    n, lab, stats, _ = cv2.connectedComponentsWithStats(free.view(np.uint8), connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA]
    assert areas.max() > 0.99 * areas.sum()  # one connected building (the maps' own specks aside)
