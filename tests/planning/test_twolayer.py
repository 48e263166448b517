"""The two-layer planning graph (seed 003): decomposition, layer-1 adjacency, layer-2 regions, guarantees."""

from __future__ import annotations

import cv2
import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from planning_maps import random_map

from holoslam.errors import MapError
from holoslam.maps.grid import OccupancyGrid
from holoslam.planning.twolayer import (
    block_label_image,
    build_two_layer,
    decompose,
    grow_regions,
    grow_regions_batched,
    integral_image,
    layer1_edges,
    layer1_edges_join,
    rect_free,
)

maps = st.builds(
    random_map,
    seed=st.integers(0, 2**31 - 1),
    h=st.integers(1, 40),
    w=st.integers(1, 40),
    n_rect=st.integers(0, 12),
    n_dots=st.integers(0, 30),
)


def brute_adjacency(blocks: np.ndarray) -> set[tuple[int, int]]:
    """Reference of the 1-cell dilation rule: block i dilated by one cell overlaps block j."""
    out = set()
    for i, (a0, b0, a1, b1) in enumerate(blocks.tolist()):
        for j, (c0, d0, c1, d1) in enumerate(blocks.tolist()):
            if i < j and a0 - 1 < c1 and c0 < a1 + 1 and b0 - 1 < d1 and d0 < b1 + 1:
                out.add((i, j))
    return out


def components_of(n: int, edges: np.ndarray) -> list[set[int]]:
    g = nx.Graph()
    g.add_nodes_from(range(n))
    g.add_edges_from(edges.tolist())
    return [set(c) for c in nx.connected_components(g)]


def test_nine_square_split_of_one_obstacle_cell():
    free = np.ones((9, 9), dtype=bool)
    free[4, 4] = False  # the centre cell
    blocks = decompose(free)
    # the 8 outer 3x3 blocks stay whole, the centre 3x3 block splits into 8 free cells
    sizes = sorted(((b[2] - b[0]) * (b[3] - b[1])) for b in blocks.tolist())
    assert sizes == [1] * 8 + [9] * 8
    assert (4, 4, 5, 5) not in {tuple(b) for b in blocks.tolist()}


def test_min_block_counts_small_mixed_blocks_as_occupied():
    free = np.ones((9, 9), dtype=bool)
    free[4, 4] = False
    blocks = decompose(free, min_block_cells=3)  # the mixed 3x3 centre block has area 9 <= 3**2
    assert len(blocks) == 8
    assert all((b[2] - b[0]) == 3 and (b[3] - b[1]) == 3 for b in blocks.tolist())
    with pytest.raises(MapError):
        decompose(free, min_block_cells=0)
    with pytest.raises(MapError):
        decompose(np.zeros((0, 3), dtype=bool))


def test_all_occupied_and_all_free():
    assert decompose(np.zeros((5, 7), dtype=bool)).shape == (0, 4)
    b = decompose(np.ones((5, 7), dtype=bool))
    assert b.tolist() == [[0, 0, 5, 7]]
    tl = build_two_layer(np.zeros((4, 4), dtype=bool))
    assert tl.n_blocks == 0 and tl.n_regions == 0


@settings(max_examples=60, deadline=None)
@given(maps, st.integers(1, 3))
def test_blocks_pure_disjoint_and_cover_the_free_space(free, m):
    tl = build_two_layer(free, min_block_cells=m)
    S = integral_image(free)
    b = tl.blocks
    area = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    assert np.all(rect_free(S, b) == area)  # every block is all free
    covered = np.zeros(free.shape, dtype=int)
    for r0, c0, r1, c1 in b.tolist():
        covered[r0:r1, c0:c1] += 1
    assert covered.max(initial=0) <= 1  # disjoint
    assert np.array_equal(covered == 1, tl.labels >= 0)
    assert not np.any((covered == 1) & ~free)
    if m == 1:
        assert np.array_equal(covered == 1, free)  # exact decomposition


@settings(max_examples=60, deadline=None)
@given(maps, st.integers(1, 3))
def test_layer1_edges_equal_the_dilation_rule(free, m):
    tl = build_two_layer(free, min_block_cells=m)
    if tl.n_blocks > 400:
        return
    got = [tuple(e) for e in tl.edges.tolist()]
    assert len(got) == len(set(got)) and all(i < j for i, j in got)
    assert set(got) == brute_adjacency(tl.blocks)
    c = tl.block_centres_xy
    if tl.edges.shape[0]:
        d = np.hypot(*(c[tl.edges[:, 0]] - c[tl.edges[:, 1]]).T)
        assert np.allclose(tl.weights, d)


@settings(max_examples=60, deadline=None)
@given(maps, st.integers(1, 3))
def test_regions_obstacle_free_maximal_and_cover_every_block(free, m):
    tl = build_two_layer(free, min_block_cells=m)
    S = integral_image(free)
    R = tl.regions
    h, w = free.shape
    assert np.all(rect_free(S, R) == (R[:, 2] - R[:, 0]) * (R[:, 3] - R[:, 1]))  # obstacle-free
    eff = tl.labels >= 0  # the free space layer 1 sees (mixed blocks below the minimum size are occupied)
    assert np.all(rect_free(integral_image(eff), R) == (R[:, 2] - R[:, 0]) * (R[:, 3] - R[:, 1]))
    for r0, c0, r1, c1 in R.tolist():  # maximal: no side can grow by one cell
        assert r1 == h or not eff[r1, c0:c1].all()
        assert r0 == 0 or not eff[r0 - 1, c0:c1].all()
        assert c1 == w or not eff[r0:r1, c1].all()
        assert c0 == 0 or not eff[r0:r1, c0 - 1].all()
    # every block is covered by exactly the region it records, and lies inside it
    assert np.all(tl.region_of_block >= 0)
    ids = np.sort(tl.region_block_ids)
    assert np.array_equal(ids, np.arange(tl.n_blocks))
    for k in range(tl.n_regions):
        bl = tl.blocks_of(k)
        assert np.all(tl.region_of_block[bl] == k)
        rb = tl.blocks[bl]
        r = R[k]
        assert np.all((rb[:, 0] >= r[0]) & (rb[:, 1] >= r[1]) & (rb[:, 2] <= r[2]) & (rb[:, 3] <= r[3]))
    # portals: the intersection of the closed rectangles, non-empty
    P = tl.portals
    assert np.all(P[:, 0] <= P[:, 2]) and np.all(P[:, 1] <= P[:, 3])


@settings(max_examples=60, deadline=None)
@given(maps, st.integers(1, 3))
def test_connectivity_is_preserved_in_both_layers(free, m):
    """Free cells 8-connected in the grid at the minimum block size (the cells of free blocks) are connected
    in layer 1 and in layer 2, and cells in different grid components are not."""
    tl = build_two_layer(free, min_block_cells=m)
    eff = (tl.labels >= 0).astype(np.uint8)
    if m == 1:
        assert np.array_equal(eff.astype(bool), free)
    n, cc = cv2.connectedComponents(eff, connectivity=8)
    comp1 = components_of(tl.n_blocks, tl.edges)
    # each layer-1 component is exactly one grid component
    grid_comp_of_block = cc[tl.blocks[:, 0], tl.blocks[:, 1]] if tl.n_blocks else np.zeros(0, int)
    assert len(comp1) == n - 1
    for comp in comp1:
        assert len({int(grid_comp_of_block[i]) for i in comp}) == 1
    comp2 = components_of(tl.n_regions, tl.region_edges)
    assert len(comp2) == n - 1
    for comp in comp2:
        blocks = np.concatenate([tl.blocks_of(k) for k in comp])
        assert len({int(grid_comp_of_block[i]) for i in blocks}) == 1


@settings(max_examples=80, deadline=None)
@given(maps, st.integers(1, 3))
def test_compiled_build_kernels_equal_the_numpy_references(free, m):
    """The compiled label image, layer-1 adjacency and region growing give exactly what the vectorised numpy
    versions give (same pairs; same regions, block assignment and CSR)."""
    S = integral_image(free)
    blocks = decompose(free, m, S)
    labels = block_label_image(blocks, free.shape)
    ref = np.full(free.shape, -1, dtype=np.int32)
    for k, (r0, c0, r1, c1) in enumerate(blocks.tolist()):
        ref[r0:r1, c0:c1] = k
    assert np.array_equal(labels, ref)
    e = layer1_edges(blocks, labels)
    assert {tuple(x) for x in e.tolist()} == {tuple(x) for x in layer1_edges_join(blocks).tolist()}
    assert len({tuple(x) for x in e.tolist()}) == e.shape[0]
    eff = labels >= 0
    Se = integral_image(eff)
    got = grow_regions(blocks, eff, Se, labels=labels)
    want = grow_regions_batched(blocks, eff, Se)
    for a, b in zip(got, want, strict=True):
        assert np.array_equal(a, b)


def test_occupancy_grid_input_world_geometry():
    free = np.ones((30, 60), dtype=bool)
    free[:, 29:31] = False
    free[10:14, 29:31] = True  # a door
    grid = OccupancyGrid.from_free_mask(free, 0.1, origin_x=-2.0, origin_y=1.0)
    tl = build_two_layer(grid, min_block_cells=2)
    assert tl.resolution == 0.1 and tl.origin_x == -2.0
    c = tl.block_corners_xy
    assert np.all(c[:, 0] >= -2.0 - 1e-9) and np.all(c[:, 2] <= -2.0 + 6.0 + 1e-9)
    assert np.all(c[:, 1] >= 1.0 - 1e-9) and np.all(c[:, 3] <= 1.0 + 3.0 + 1e-9)
    # point location: a free world point is in a region containing it, an obstacle point in none
    p = np.array([[-2.0 + 0.55, 1.0 + 0.55], [-2.0 + 2.95, 1.0 + 0.5]])
    reg = tl.region_at(p)
    assert reg[0] >= 0 and reg[1] == -1
    rc = tl.region_corners_xy[reg[0]]
    assert rc[0] <= p[0, 0] <= rc[2] and rc[1] <= p[0, 1] <= rc[3]
    assert len(components_of(tl.n_regions, tl.region_edges)) == 1
