"""The first session of a store keeps the side each object was seen from, as every later session does: the view
tests of the next days (``changes.in_view_mask``, ``frustum.covering_images``) need it, or they count a place
in view from behind its label."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from holoslam.lifelong.changes import ChangeConfig, in_view_mask
from holoslam.lifelong.session import _founding


def _session():
    """A robot driving along y = 0 from x = 0 to 4 m in 40 s, reading a cup at (2, 1) from x = 1..3 m."""
    t = np.arange(401, dtype=np.int64) * 100_000_000
    wTb = np.column_stack([np.linspace(0.0, 4.0, 401), np.zeros(401), np.zeros(401)])
    obs = [SimpleNamespace(stamp_ns=int(s), object_id="O01") for s in t[100:301:20]]
    o = SimpleNamespace(object_type="cup", payload="", w_position=np.array([2.0, 1.0, 0.8]), sightings=len(obs))
    st = SimpleNamespace(sol=SimpleNamespace(cov_wTa=None), traj=SimpleNamespace(stamps_ns=t, wTb=wTb),
                         seen=SimpleNamespace(observations=obs))
    return st, {"O01": (np.array([2.0, 1.0]), np.eye(2) * 1e-4, o)}


def test_the_founding_session_stores_the_side_an_object_was_seen_from():
    st, sobj = _session()
    (obj,) = _founding(st, np.zeros((1, 3)), sobj).objects
    assert obj.status == "new" and obj.view is not None
    # readings from (1..3, 0) of a cup at (2, 1): the mean unit direction to the robot is straight down (-y)
    np.testing.assert_allclose(obj.view, [0.0, -1.0], atol=1e-9)
    # so a later robot behind the label (y = 2) does not have its place in view; one in front does
    behind = np.array([[2.0, 2.0]])
    front = np.array([[2.0, 0.0]])
    assert not in_view_mask(obj.w_xy, obj.view, behind, None, ChangeConfig())[0]
    assert in_view_mask(obj.w_xy, obj.view, front, None, ChangeConfig())[0]
