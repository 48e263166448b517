"""``StageClock``: the run's named stages, each announced to a progress callback and timed (wall seconds).

A stage is entered with ``with clock.stage(name):``; ``clock.progress_of(name)`` is the ``(done, total)`` callback a
long stage reports its own progress through. ``clock.timings`` maps each stage's name to its seconds, in run order.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["Progress", "StageClock"]

Progress = Callable[..., None]


def _noop(*_a: Any, **_k: Any) -> None:
    return None


class StageClock:
    """Times named stages and announces each to ``progress`` (``progress(name)`` on entry, and
    ``progress(name, done, total)`` from within, through ``progress_of``)."""

    def __init__(self, progress: Progress | None = None) -> None:
        self.progress: Progress = progress or _noop
        self.timings: dict[str, float] = {}
        self._t0 = time.perf_counter()

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        self.progress(name)
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.timings[name] = round(time.perf_counter() - t0, 4)

    def progress_of(self, name: str) -> Callable[[int, int], None]:
        """The ``(done, total)`` callback of stage ``name``."""
        return lambda done, total: self.progress(name, done, total)

    def background(self) -> StageClock:
        """A clock for stages run in a thread beside this clock's: the same timings, its stages announced, but
        not their ``(done, total)`` progress (two stages updating one progress line would garble it)."""
        clock = StageClock(lambda name, *_a, **_k: None if _a or _k else self.progress(name))
        clock.timings, clock._t0 = self.timings, self._t0
        return clock

    def total(self) -> dict[str, float]:
        """The stage timings with ``total``: wall seconds since the clock started."""
        self.timings["total"] = round(time.perf_counter() - self._t0, 4)
        return self.timings
