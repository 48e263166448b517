"""A label's support gone from its place (``holoslam.lifelong.support``): the session's laser saw the thing the label
was on (a chair carried away) gone, nothing occupied left within the issue's 0.3 m: the label is gone although
no image held its place (the camera's 2-D free-space test refuses lines over lower furniture)."""

from __future__ import annotations

import numpy as np

from holoslam.lifelong.changes import ChangeConfig, classify
from holoslam.lifelong.merge import MergedGrid
from holoslam.lifelong.support import support_left
from holoslam.store.records import ObjectState

RES = 0.05
PLACE = np.array([1.01, 1.0])  # a chair's label, 1 cm outside its edge at x = 1.0, facing +x


def _grid(block=None, known=None) -> MergedGrid:
    """A 3 m x 3 m grid at the world origin, free; ``block`` (x0, x1, y0, y1) occupied; ``known`` (x0, x1, y0, y1)
    the observed part (None: all of it)."""
    prob = np.full((60, 60), 0.1, np.float32)
    kn = np.ones((60, 60), bool)
    y, x = (np.mgrid[0:60, 0:60] + 0.5) * RES
    if block is not None:
        x0, x1, y0, y1 = block
        prob[(x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)] = 0.9
    if known is not None:
        x0, x1, y0, y1 = known
        kn = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
    return MergedGrid(prob, kn, (0.0, 0.0), RES)


CHAIR = (0.55, 1.0, 0.78, 1.22)  # the chair's footprint seen by the laser, the label on its +x side


def _left(stored, session) -> bool:
    c = ChangeConfig()
    return support_left(stored, session, PLACE, c.moved_m, c.p_occupied, c.support_min_cells, c.support_seen_share)


def test_the_chair_carried_away_takes_its_label():
    assert _left(_grid(CHAIR), _grid())  # its footprint observed free: gone


def test_no_conclusion_while_anything_stands_near_or_was_not_seen():
    assert not _left(_grid(CHAIR), _grid(CHAIR))  # the chair is there
    x0, x1, y0, y1 = CHAIR
    assert not _left(_grid(CHAIR), _grid((x0 - 0.15, x1 - 0.15, y0, y1)))  # pushed 0.15 m: within 0.3 m
    assert not _left(_grid(CHAIR), _grid(known=(0.0, 3.0, 1.6, 3.0)))  # the session's laser never saw the place
    assert not _left(_grid(CHAIR), _grid(known=(0.0, 3.0, 1.0, 3.0)))  # about half of it seen: it may be hidden
    assert not _left(_grid(), _grid())  # no support in the store (a table the scan passes under): nothing known
    assert not _left(_grid(CHAIR), None)  # a session without grids


def _state(oid, xy):
    return ObjectState(oid, "chair", "", "seen", np.array(xy, float), 0.8, np.eye(2) * 1e-4, 2, f"{oid}#1",
                       view=np.array([1.0, 0.0]))


def test_classify_calls_an_object_whose_support_left_gone():
    stored = {"A": _state("A", PLACE), "B": _state("B", (5.0, 5.0))}
    t = np.arange(10, dtype=np.int64) * 100_000_000
    far = np.full((10, 2), 20.0)  # never in the camera's view, no image
    assert classify(stored, {}, t, far, None, ChangeConfig(), images={}) == {}
    assert classify(stored, {}, t, far, None, ChangeConfig(), images={}, support_left=("A",)) == {"A": "gone"}
