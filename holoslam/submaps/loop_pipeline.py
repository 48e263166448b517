"""The loop search beside local SLAM: one node's search runs in a thread while local SLAM goes on to the next
nodes, and its closures join the anchor graph when the next search is due.

Local SLAM (``local_slam.LocalSlam``) and the loop search (``loops.LoopSearch``) were one loop in one thread: at
every few nodes local SLAM waited for the search (the bundled household run: 357 searches, 1.2 s of its 3.7 s
front end; the searches' own threads then had the cores, local SLAM's matching none). Measured on the shared real
logs, whole runs on 2 cores, two alternated pairs: aces 28.8 / 27.5 -> 23.4 / 25.5 s, fr079 31.7 / 32.3 -> 27.9 /
29.7 s, intel 34.3 / 38.2 -> 33.6 / 33.9 s, their relation errors as before (intel 0.0186 -> 0.0187 m at the
laser, aces and fr079 the same to the digit). Here a search is
submitted with everything it reads taken at its node (the anchors' estimate, their covariances, dead
reckoning's disagreement, the node's bundle of points), and collected at the next search's node, before that
search is made; the finished submaps and the breaks of local SLAM that arrive meanwhile are held back and given
to the search in the order they came, once it is collected. So every search sees exactly what it saw in one
thread, and the result does not depend on the threads' timing: only the graph receives a search's closures a
few nodes later (at the next search, or at the end of the log), and re-estimates the anchors then.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

from holoslam.submaps.loops import LoopCandidate, LoopSearch
from holoslam.submaps.probgrid import ProbGrid

__all__ = ["LoopPipeline"]


class LoopPipeline:
    """A ``LoopSearch`` run one search at a time in ``pool`` (a one-thread executor the caller owns and shuts
    down): ``submit`` a search, ``collect`` its closures; ``add_submap`` / ``add_break`` reach the search at
    once when none is under way, else after it is collected (module docstring)."""

    def __init__(self, loops: LoopSearch, pool: ThreadPoolExecutor) -> None:
        self.loops = loops
        self._pool = pool
        self._pending: Future[list[LoopCandidate]] | None = None
        self._held: list[Callable[[], None]] = []

    @property
    def busy(self) -> bool:
        """A search was submitted and not yet collected."""
        return self._pending is not None

    def add_submap(self, index: int, grid: ProbGrid) -> None:
        self._apply(lambda: self.loops.add_submap(index, grid))

    def add_break(self, index: int) -> None:
        self._apply(lambda: self.loops.add_break(index))

    def submit(self, *args: Any, **kwargs: Any) -> None:
        """Start ``LoopSearch.search(*args, **kwargs)`` in the pool (collect the last one first): its arguments
        must be the node's values, not views of what local SLAM goes on changing."""
        if self._pending is not None:
            raise RuntimeError("LoopPipeline.submit: collect the search under way first")
        self._pending = self._pool.submit(self.loops.search, *args, **kwargs)

    def collect(self) -> list[LoopCandidate]:
        """The closures of the search under way ([] when none), once it is done; then the submaps and breaks
        held back meanwhile are given to the search. A search that raised raises here."""
        if self._pending is None:
            return []
        pending, self._pending = self._pending, None
        try:
            return pending.result()
        finally:
            held, self._held = self._held, []
            for apply in held:
                apply()

    def _apply(self, change: Callable[[], None]) -> None:
        if self._pending is None:
            change()
        else:
            self._held.append(change)
