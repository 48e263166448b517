"""Without a compass, the loop windows widen to dead reckoning's disagreement with the estimate only on a slow laser
(``LoopConfig.disagreement_window_max_hz``): 90 s of the real fr079 log at its own 4.6 Hz searches without it, the
same scans decimated to 1.4 Hz (the held-out hospital's rate) with it."""

from __future__ import annotations

import dataclasses
import inspect

import pytest
from repo_paths import SHARED

REALDATA = SHARED / "realdata"
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not (REALDATA / "fr079.mcap").exists(), reason="../shared/realdata is not here"),
]


def _cut(tmp_path_factory, seconds: float):
    from holoslam.io.mcap import read_log
    from holoslam.io.mcap_cut import cut_log

    path = tmp_path_factory.mktemp("fr079") / "cut.mcap"
    cut_log(REALDATA / "fr079.mcap", path, 0.0, seconds)
    return read_log(path, require=["odometry", "scan"])[0]


@pytest.fixture(scope="module")
def fr079_cut(tmp_path_factory):
    return _cut(tmp_path_factory, 90.0)


@pytest.fixture(scope="module")
def fr079_slow(tmp_path_factory):
    from holoslam import derive

    return derive.decimate_scans(_cut(tmp_path_factory, 400.0), 1.4)


def _widened(log, monkeypatch, **loops) -> list[bool]:
    """For each loop search of the front end on ``log``: was dead reckoning's disagreement passed to it?"""
    from holoslam.submaps import loops as loops_mod
    from holoslam.submaps.frontend import FrontEndConfig, build_problem

    seen: list[bool] = []
    search = loops_mod.LoopSearch.search
    sig = inspect.signature(search)

    def recording(self, *args, **kwargs):
        bound = sig.bind(self, *args, **kwargs)
        seen.append(bound.arguments.get("disagreement") is not None)
        return search(self, *args, **kwargs)

    cfg = FrontEndConfig()
    with monkeypatch.context() as m:  # undone before the next call
        m.setattr(loops_mod.LoopSearch, "search", recording)
        build_problem(log, config=dataclasses.replace(cfg, loops=dataclasses.replace(cfg.loops, **loops)))
    return seen


def test_the_disagreement_window_is_used_on_a_slow_laser_only(fr079_cut, fr079_slow, monkeypatch):
    # (the disagreement is None until the anchors give one: the first searches of a run have none either way)
    full = _widened(fr079_cut, monkeypatch)
    assert len(full) >= 20 and not any(full)  # 4.6 Hz: off
    slow = _widened(fr079_slow, monkeypatch)
    assert sum(slow) >= 5  # 1.2 Hz: on
    forced = _widened(fr079_cut, monkeypatch, disagreement_window_max_hz=float("inf"))
    assert len(forced) == len(full) and any(forced)
    off = _widened(fr079_slow, monkeypatch, disagreement_window=0.0)
    assert len(off) == len(slow) and not any(off)
