"""The loop search beside local SLAM (``holoslam.submaps.loop_pipeline``): a search sees the finished submaps and
breaks of its own node, never those that arrive while it runs, and hands its closures over when collected."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import pytest

from holoslam.submaps.loop_pipeline import LoopPipeline


class _Search:
    """A stand-in for ``LoopSearch``: each search waits for ``go``, then returns what it saw."""

    def __init__(self) -> None:
        self.grids: dict[int, object] = {}
        self.breaks: list[int] = []
        self.go = threading.Event()

    def add_submap(self, index: int, grid: object) -> None:
        self.grids[index] = grid

    def add_break(self, index: int) -> None:
        self.breaks.append(index)

    def search(self, n: int) -> list[tuple[int, list[int], list[int]]]:
        assert self.go.wait(10.0)
        return [(n, sorted(self.grids), list(self.breaks))]


def test_a_search_sees_its_nodes_submaps_and_the_later_ones_after_it_is_collected():
    loops = _Search()
    with ThreadPoolExecutor(max_workers=1) as pool:
        pipe = LoopPipeline(loops, pool)  # type: ignore[arg-type]
        pipe.add_submap(0, "grid 0")  # nothing under way: at once
        assert loops.grids == {0: "grid 0"} and not pipe.busy
        pipe.submit(5)
        assert pipe.busy
        pipe.add_submap(1, "grid 1")  # finished while the search runs: held back
        pipe.add_break(6)
        pipe.add_submap(2, "grid 2")
        assert sorted(loops.grids) == [0] and loops.breaks == []
        loops.go.set()
        assert pipe.collect() == [(5, [0], [])]  # what its node saw
        assert sorted(loops.grids) == [0, 1, 2] and loops.breaks == [6] and not pipe.busy
        pipe.submit(9)
        assert pipe.collect() == [(9, [0, 1, 2], [6])]
        assert pipe.collect() == []  # none under way


def test_a_second_search_before_the_first_is_collected_is_refused():
    loops = _Search()
    loops.go.set()
    with ThreadPoolExecutor(max_workers=1) as pool:
        pipe = LoopPipeline(loops, pool)  # type: ignore[arg-type]
        pipe.submit(1)
        with pytest.raises(RuntimeError, match="collect"):
            pipe.submit(2)
        assert pipe.collect() == [(1, [], [])]


def test_a_search_that_fails_raises_when_collected_and_the_held_submaps_still_arrive():
    class Failing(_Search):
        def search(self, n: int):
            assert self.go.wait(10.0)
            raise ValueError(f"search of node {n} failed")

    loops = Failing()
    with ThreadPoolExecutor(max_workers=1) as pool:
        pipe = LoopPipeline(loops, pool)  # type: ignore[arg-type]
        pipe.submit(3)
        pipe.add_submap(1, "grid 1")
        loops.go.set()
        with pytest.raises(ValueError, match="node 3"):
            pipe.collect()
        assert sorted(loops.grids) == [1] and not pipe.busy


def test_a_nodes_bundle_holds_its_submaps_nodes_as_they_were_at_the_node():
    """``LocalSlam.bundle``: the points of the node and the nodes behind it, made later (the loop search calls it
    in its thread while local SLAM goes on): the nodes added since are not in it, and it equals the bundle made at
    once."""
    import numpy as np
    from test_scanmatch import BEAMS_360, ROOM, points, ray_scan

    from holoslam.submaps.local_slam import LocalSlam, LocalSlamConfig

    rng = np.random.default_rng(1)
    slam = LocalSlam(LocalSlamConfig(scans_per_submap=200), np.zeros(3))

    def drive(k: int):
        T = np.array([0.8 + 0.1 * k, 2.0, 0.0])
        r = ray_scan(ROOM, T, BEAMS_360, rng, 0.01)
        return slam.add(k * 200_000_000, T, lambda: np.diag([1e-4, 1e-4, 1e-6]), points(r, BEAMS_360),
                        np.where(np.isfinite(r), r, np.inf), BEAMS_360, 0.1 * k)

    for k in range(10):
        node = drive(k)
    later, now = slam.bundle(node, 0.45), slam.bundle(node, 0.45)()
    assert len(now) == 5 * len(node.b_points)  # the node and the four behind it, 0.1 m apart
    for k in range(10, 15):
        drive(k)
    assert np.array_equal(later(), now)
    assert not np.array_equal(slam.bundle(node, 0.45)(), now)  # made from the submap's last nodes instead
