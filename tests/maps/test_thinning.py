"""Thinning (seed 000): the vectorised bare rule equals the reference; thin() keeps topology and leaves no
removable cell."""

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from repo_paths import benchmark_module

from holoslam.errors import MapError
from holoslam.maps.thinning import (
    _thin_mask,
    _thin_numpy,
    count_removable,
    neighbour_codes,
    preprocess_free,
    removable_mask,
    thin,
    thin_reference,
    zhang_suen,
)


def topology(mask: np.ndarray) -> tuple[int, int]:
    """(8-connected components of the set, 4-connected holes of its complement)."""
    m = np.asarray(mask, dtype=np.uint8)
    comps = cv2.connectedComponents(m, connectivity=8)[0] - 1
    bg = np.pad(1 - m, 1, constant_values=1).astype(np.uint8)
    holes = cv2.connectedComponents(bg, connectivity=4)[0] - 2
    return comps, holes


masks = arrays(bool, st.tuples(st.integers(1, 16), st.integers(1, 16)), elements=st.booleans())


@settings(max_examples=150, deadline=None)
@given(masks)
def test_vectorised_bare_rule_equals_reference(m):
    assert np.array_equal(zhang_suen(m), thin_reference(m))


@settings(max_examples=150, deadline=None)
@given(masks)
def test_thin_keeps_topology_and_leaves_no_removable_cell(m):
    t = thin(m)
    assert not (t & ~m).any()
    assert topology(t) == topology(m)
    assert count_removable(t) == 0


def test_reference_rule_on_a_t_shape_matches_hand_result():
    # a 3-wide horizontal bar over a 3-wide vertical stem: the bare rule leaves a one-cell T skeleton
    m = np.zeros((9, 11), bool)
    m[1:4, 1:10] = True
    m[4:8, 4:7] = True
    t = thin_reference(m)
    assert topology(t) == (1, 0)
    assert t[2, 2:8].all()  # the bar's middle row survives (the rule shortens the east end)
    assert t[3:6, 5].all()  # and the stem's middle column
    assert t.sum() == 9


def test_bare_rule_erases_2x2_block_thin_keeps_it():
    m = np.zeros((6, 6), bool)
    m[2:4, 2:4] = True
    assert not thin_reference(m).any()  # the seed's rule alone deletes the whole region
    t = thin(m)
    assert t.sum() >= 1 and topology(t) == (1, 0)


def test_bare_rule_breaks_thick_diagonal_thin_keeps_it_connected():
    m = np.zeros((14, 14), bool)
    for i in range(1, 12):
        m[i, i] = m[i, i + 1] = True  # two-cell-thick diagonal
    assert topology(m) == (1, 0)
    assert thin_reference(m).sum() <= 2  # the bare rule erodes it from both ends
    t = thin(m)
    assert topology(t) == (1, 0)
    assert count_removable(t) == 0
    assert t[1:3, 1:4].any() and t[10:12, 10:13].any()  # still spans the whole line


def test_small_ring_keeps_its_hole():
    m = np.ones((5, 5), bool)
    m[2, 2] = False
    t = thin(m)
    assert topology(t) == (1, 1)
    assert count_removable(t) == 0


def test_staircase_is_removable_and_thin_removes_it():
    stair = np.zeros((6, 6), bool)
    for i in range(5):
        stair[i, i] = stair[i, i + 1] = True  # 4-connected staircase
    stair[5, 5] = True
    assert count_removable(stair) > 0
    t = thin(stair)
    assert count_removable(t) == 0 and topology(t) == (1, 0)
    assert t[0, :2].any() and t[5, 5]  # both ends kept


def test_endpoints_and_isolated_cells_are_never_deleted():
    m = np.zeros((7, 7), bool)
    m[1, 1:6] = True  # a line: endpoints at both ends
    m[5, 5] = True  # isolated cell
    for f in (thin, thin_reference, zhang_suen):
        t = f(m)
        assert t[1, 1] and t[1, 5] and t[5, 5]


def test_corridor_skeleton_runs_down_the_middle():
    m = np.zeros((40, 200), bool)
    m[10:31, 5:195] = True  # 21-cell wide corridor
    t = thin(m)
    rows = np.flatnonzero(t[:, 100])
    assert rows.tolist() == [20]
    assert topology(t) == (1, 0)


def test_large_rooms_have_same_skeleton_as_dense_reference_rule():
    rng = np.random.default_rng(3)
    m = np.ones((60, 70), bool)
    for _ in range(15):
        r, c = rng.integers(0, 60, 2)
        m[r : r + rng.integers(2, 9), c : c + rng.integers(2, 9)] = False
    assert np.array_equal(zhang_suen(m), thin_reference(m))


def test_removable_mask_definition():
    line = np.zeros((3, 5), bool)
    line[1, :] = True
    assert count_removable(line) == 0  # middle cells disconnect, end cells are endpoints
    corner = np.zeros((3, 3), bool)
    corner[0, 0] = corner[0, 1] = corner[1, 1] = True
    assert removable_mask(corner)[0, 1]
    codes = neighbour_codes(np.ones((3, 3), bool))
    assert codes[1, 1] == 255 and codes[0, 0] == 0b00011100  # east, south-east, south


def test_preprocess_erodes_and_opens():
    m = np.zeros((30, 30), bool)
    m[5:25, 5:25] = True
    m[0:2, 0:2] = True  # a speck narrower than the opening
    p = preprocess_free(m, close_cells=1)
    assert not p[0:2, 0:2].any() and p[10, 10]
    e = preprocess_free(m, erode_cells=3)
    assert e[15, 15] and not e[6, 15]
    with pytest.raises(MapError):
        preprocess_free(m, erode_cells=-1)
    with pytest.raises(MapError):
        thin(np.zeros(5, bool))


# the compiled kernels (holoslam.maps._thin_fast) against the numpy active-set implementation, cell for cell,
# in every mode (guarded / bare rule, with / without the one-cell-thin passes)
MODES = [(True, True), (True, False), (False, True), (False, False)]


def blobs(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """Rooms-like mask: free space with random rectangular obstacles (wide regions: many subiterations)."""
    m = np.ones((h, w), bool)
    for _ in range(int(rng.integers(0, 12))):
        r, c = rng.integers(0, max(h, 1), 2)
        m[r : r + rng.integers(1, 10), c : c + rng.integers(1, 12)] = False
    return m


@settings(max_examples=100, deadline=None)
@given(arrays(bool, st.tuples(st.integers(1, 24), st.integers(1, 24)), elements=st.booleans()))
def test_compiled_equals_numpy_on_random_masks(m):
    for guard, one_cell in MODES:
        assert np.array_equal(
            _thin_mask(m, guard=guard, one_cell=one_cell), _thin_numpy(m, guard=guard, one_cell=one_cell)
        )


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 70), st.integers(1, 70))
def test_compiled_equals_numpy_on_room_masks(seed, h, w):
    m = blobs(np.random.default_rng(seed), h, w)
    for guard, one_cell in MODES:
        assert np.array_equal(
            _thin_mask(m, guard=guard, one_cell=one_cell), _thin_numpy(m, guard=guard, one_cell=one_cell)
        )


def test_compiled_equals_numpy_past_255_subiterations():
    # a 300-cell-wide square: > 255 subiterations, so the uint8 stamps of the kernel wrap and are cleared
    m = np.zeros((310, 306), bool)
    m[3:303, 2:302] = True
    m[150, 100] = False  # a one-cell hole: the skeleton must keep a cycle round it
    for guard, one_cell in MODES:
        assert np.array_equal(
            _thin_mask(m, guard=guard, one_cell=one_cell), _thin_numpy(m, guard=guard, one_cell=one_cell)
        )
    assert topology(thin(m)) == (1, 1)


def test_compiled_equals_numpy_and_reference_on_the_bare_rule():
    rng = np.random.default_rng(7)
    m = blobs(rng, 50, 64)
    assert np.array_equal(_thin_mask(m, guard=False, one_cell=False), thin_reference(m))
    t = _thin_mask(m, guard=True, one_cell=True)
    assert topology(t) == topology(m) and count_removable(t) == 0


@pytest.mark.slow
def test_compiled_equals_numpy_on_benchmark_maps():
    bench = benchmark_module("bench_thinning")
    grid = bench.household_grid()[0]
    household = grid.free
    maps = [household, np.tile(household, (3, 3))[:1000, :1000], bench.apartment(1000)]
    for m in maps:
        assert np.array_equal(thin(m), _thin_numpy(m, guard=True, one_cell=True))
