"""The adaptive voxel filter of the points a scan is matched with (holoslam.submaps.scan_filter)."""

from __future__ import annotations

import numpy as np
import pytest
from test_scanmatch import ROOM, points, ray_scan

from holoslam.errors import ConfigError
from holoslam.submaps.scan_filter import ScanFilterConfig, adaptive_voxel_filter

DENSE = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 1081)  # a 270 deg, 1081-beam laser


def _codes(pts: np.ndarray, edge: float) -> np.ndarray:
    k = np.floor(pts / edge).astype(np.int64)
    return k[:, 0] * (1 << 32) + k[:, 1]


def test_a_scan_of_few_points_is_kept_whole():
    pts = points(ray_scan(ROOM, np.array([2.0, 2.0, 0.3]), np.radians(np.arange(-90.0, 91.0))), np.radians(np.arange(-90.0, 91.0)))
    assert len(pts) <= 200
    np.testing.assert_array_equal(adaptive_voxel_filter(pts), pts)


def test_a_dense_scan_keeps_one_point_per_grid_cell_and_at_least_200():
    pts = points(ray_scan(ROOM, np.array([2.0, 2.0, 0.3]), DENSE), DENSE)
    out = adaptive_voxel_filter(pts)
    assert 200 <= len(out) < 0.75 * len(pts)  # measured: 1,081 points -> 699
    assert len(np.unique(_codes(out, 0.02))) == len(out)  # one per 2 cm voxel
    assert len(np.unique(_codes(out, 0.02))) == len(np.unique(_codes(pts, 0.02)))  # and every voxel kept
    assert np.isin(out.view([("x", float), ("y", float)]), pts.view([("x", float), ("y", float)])).all()


def test_when_cells_leave_too_few_points_smaller_voxels_keep_200():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.12, 0.12, (1000, 2))  # 1,000 points in 12 x 12 voxels of 2 cm
    out = adaptive_voxel_filter(pts)
    assert 200 <= len(out) <= 260  # measured 205


def test_bad_settings_are_a_config_error():
    with pytest.raises(ConfigError, match="max_length_m"):
        ScanFilterConfig(max_length_m=0.0)
    assert len(adaptive_voxel_filter(np.zeros((500, 2)), ScanFilterConfig(min_num_points=0))) == 500
