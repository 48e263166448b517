"""Placements: a moved or new object gets a placement name the store never gave before, also when the submaps
that saw its earlier places were retired."""

from __future__ import annotations

import numpy as np

from holoslam.lifelong.session import _placements
from holoslam.store.records import ObjectState


def test_a_new_placement_never_reuses_a_name():
    latest = {"O17": ObjectState("O17", "bowl", "", "moved", np.zeros(2), 0.9, np.eye(2), 2, "O17#2"),
              "O05": ObjectState("O05", "cup", "", "seen", np.ones(2), 0.5, np.eye(2), 2, "O05#1")}
    ever = {"O17#1", "O17#2", "O05#1", "O170#7"}
    out = _placements({"O17": "moved", "O05": "seen", "O99": "new"}, latest, ever)
    assert out == {"O17": "O17#3", "O05": "O05#1", "O99": "O99#1"}
