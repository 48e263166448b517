"""Pictures: every drawing function renders, puts its data where it belongs, and no pyplot state is used."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from planning_maps import apartment_free

from holoslam import viz
from holoslam.maps.grid import OccupancyGrid
from holoslam.maps.holographic import ObjectInfo, build_holographic
from holoslam.maps.topology import topology_from_grid
from holoslam.planning.routes import plan_path
from holoslam.planning.twolayer import build_two_layer


@pytest.fixture(scope="module")
def scene():
    grid = OccupancyGrid.from_free_mask(apartment_free(0.05), 0.05, origin_x=-1.0, origin_y=0.5)
    topo = topology_from_grid(grid)
    holo = build_holographic(
        grid,
        topo,
        objects=[
            ObjectInfo("CUP-1", "cup", np.array([2.0, 1.3, 0.8])),
            ObjectInfo("AC-1", "ac", np.array([0.0, 8.0, 3.5])),
        ],
    )
    tl = build_two_layer(grid, 2)
    route = plan_path(tl, np.array([0.0, 1.5]), np.array([8.5, 8.5]))
    return grid, topo, holo, tl, route


def test_import_is_lazy():
    code = "import sys, holoslam.viz; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_map_figure_renders_all_layers(scene, tmp_path):
    grid, topo, holo, tl, route = scene
    fig = viz.map_figure(grid, topology=topo, holographic=holo, planning=tl, route=route, title="flat")
    ax = fig.axes[0]
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    assert (x0, y0) == (-1.0, 0.5) and x1 == pytest.approx(-1.0 + 10.5) and y1 == pytest.approx(0.5 + 9.5)
    # the route line carries the waypoints exactly
    lines = [ln for ln in ax.get_lines() if len(ln.get_xdata()) == route.waypoints.shape[0]]
    assert any(
        np.allclose(np.column_stack([ln.get_xdata(), ln.get_ydata()]), route.waypoints) for ln in lines
    )
    labels = {t.get_text() for t in ax.get_legend().get_texts()}
    assert {"room", "doorway", "object", "object (unreachable)", "junction"} <= labels
    p = tmp_path / "map.png"
    fig.savefig(p, dpi=60)
    assert p.stat().st_size > 10_000


def test_grid_image_orientation(scene):
    from matplotlib.figure import Figure

    grid = OccupancyGrid.from_free_mask(np.array([[True, False], [True, True]]), 1.0)
    ax = Figure().add_subplot()
    (im,) = viz.draw_grid(ax, grid)
    data = im.get_array()
    assert data[0, 1] == 0.0 and data[1, 1] == 1.0  # row 0 is the lowest y, drawn at the bottom
    assert im.origin == "lower"


def test_planning_layers_draw_one_rectangle_per_node(scene):
    from matplotlib.figure import Figure

    _grid, _topo, _holo, tl, _ = scene
    for layer, n in ((1, tl.n_blocks), (2, tl.n_regions)):
        ax = Figure().add_subplot()
        arts = viz.draw_planning(ax, tl, layer=layer, edges=True)
        assert len(arts[0].get_paths()) == n
        assert len(arts[1].get_segments()) == (tl.edges if layer == 1 else tl.region_edges).shape[0]


def test_trajectory_with_covariance_ellipses():
    T = np.column_stack([np.linspace(0, 5, 20), np.zeros(20), np.full(20, np.pi / 2)])
    C = np.tile(np.diag([0.04, 0.01, 0.001]), (20, 1, 1))
    fig = viz.trajectory_figure({"optimised": T, "truth": T + 0.1}, {"optimised": C}, every=5)
    ax = fig.axes[0]
    ell = [c for c in ax.collections if len(c.get_segments()) == 4]
    assert len(ell) == 1
    seg = ell[0].get_segments()[0]
    # heading pi/2: the pose's x sigma (0.2 m, 2-sigma 0.4 m) lies along world y
    assert np.ptp(seg[:, 1]) == pytest.approx(0.8, rel=0.02) and np.ptp(seg[:, 0]) == pytest.approx(
        0.4, rel=0.02
    )


def test_covariance_ellipse_axes():
    e = viz.covariance_ellipse(np.array([1.0, 2.0, 0.0]), np.diag([4.0, 1.0, 0.1]), n_sigma=1.0, n_points=400)
    assert np.allclose(e.mean(axis=0), [1.0, 2.0], atol=0.02)
    assert np.ptp(e[:, 0]) == pytest.approx(4.0, rel=1e-3) and np.ptp(e[:, 1]) == pytest.approx(2.0, rel=1e-3)


def test_a_tall_map_is_drawn_as_large_as_a_wide_one():
    """Issue 26: a 350 m building drawn north-south (7,072 x 2,439 cells) made a 24-inch tall figure whose
    axes showed every cell: each picture resampled the grid at full size (1.5 GB). The longer side is
    ``size_in``, so the grid is pooled to the figure's pixels (the picture's peak: +60 MB)."""
    assert viz.map_figsize((2439, 7072), 8.0) == pytest.approx((8.0, 8.0 * 2439 / 7072 + 0.5))
    w, h = viz.map_figsize((7072, 2439), 8.0)
    assert h == 8.5 and w == pytest.approx(8.0 * 2439 / 7072 + 1.0)
    assert viz.map_figsize((10_000, 10), 8.0) == (3.0, 8.5)  # a corridor: room for the axes
    free = np.ones((3000, 300), dtype=bool)
    free[[0, -1], :] = free[:, [0, -1]] = False
    fig = viz.map_figure(OccupancyGrid.from_free_mask(free, 0.05))
    assert fig.get_size_inches()[1] == 8.5
    (im,) = fig.axes[0].get_images()
    assert im.get_array().shape[0] <= 1500  # pooled: the axes are less than 750 pixels tall
