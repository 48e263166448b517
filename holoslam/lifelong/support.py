"""The thing a label was on, gone from its place: evidence of absence from the laser (``changes.classify``).

A label is fixed to a thing (a chair's back, a cabinet's side) or stands on one (a cup on a nightstand), within
centimetres of its edge. Where the laser sees that thing (furniture standing at the scan's height), the store's
merged grid holds occupied cells next to the label's place: its **support**. A label does not float: when the
session's own laser observed those cells and found no occupied cell within ``ChangeConfig.moved_m`` of the place,
nothing the laser sees stands within the issue's "moved" distance of it any more, so the label is not at its place
either (carried away with its chair, or taken away and its stand with it). Its place was in the laser's view and
held nothing: gone, whether or not an image of the camera held the place. The camera's test cannot always tell:
its free-space test (``frustum``) counts every occupied cell of the 2-D grid on the line of sight as blocking,
and the grid cannot tell a dining table the camera looks over (0.75 m under a mast at 1.10 m) from a wall; on the
simulated days the checks of chairs' old places were all refused that way.

Nothing is concluded where the stored grid held no support (fewer than ``support_min_cells``: a label on a wall,
or on a table the scan passes under), nor where the session's laser observed less than ``support_seen_share`` of
it (the thing may stand hidden behind other furniture), nor where anything occupied is left within ``moved_m``
(a chair pushed by a few centimetres still holds its label near its place)."""

from __future__ import annotations

from typing import Any

import numpy as np

from holoslam import geometry as g
from holoslam.submaps.probgrid import cells_at

__all__ = ["session_grid", "support_left"]


def _cells_within(grid: Any, xy: np.ndarray, radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of ``grid``'s cells whose centres lie within ``radius_m`` of ``xy`` (inside the grid)."""
    res = grid.resolution
    c0 = int(np.floor((xy[0] - grid.origin[0]) / res))
    r0 = int(np.floor((xy[1] - grid.origin[1]) / res))
    k = int(np.ceil(radius_m / res)) + 1
    rr, cc = np.mgrid[r0 - k:r0 + k + 1, c0 - k:c0 + k + 1]
    cx = grid.origin[0] + (cc + 0.5) * res
    cy = grid.origin[1] + (rr + 0.5) * res
    H, W = grid.prob.shape
    ok = (np.hypot(cx - xy[0], cy - xy[1]) <= radius_m) & (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
    return rr[ok], cc[ok]


def support_left(stored: Any, session: Any, w_xy: np.ndarray, radius_m: float, p_occupied: float, min_cells: int,
                 seen_share: float) -> bool:
    """Whether the support of the label at ``w_xy`` left (module docstring): ``stored`` the store's merged grid
    before the session, ``session`` the session's own grid in the world (``MergedGrid`` both, ``session`` None:
    no evidence); at least ``min_cells`` occupied stored cells within ``radius_m``, ``seen_share`` of them
    observed by the session, and no cell of the session's within ``radius_m`` occupied."""
    if stored is None or session is None:
        return False
    xy = np.asarray(w_xy, np.float64)
    rr, cc = _cells_within(stored, xy, radius_m)
    occ = stored.known[rr, cc] & (stored.prob[rr, cc] > p_occupied)
    if int(occ.sum()) < min_cells:
        return False
    res = stored.resolution
    support = np.column_stack([stored.origin[0] + (cc[occ] + 0.5) * res, stored.origin[1] + (rr[occ] + 0.5) * res])
    known, _ = cells_at(session.prob, session.known, session.origin, session.resolution, support)
    if known.sum() < seen_share * len(support):
        return False
    sr, sc = _cells_within(session, xy, radius_m)
    return not bool((session.known[sr, sc] & (session.prob[sr, sc] > p_occupied)).any())


def session_grid(submaps: Any, sTa: np.ndarray, wTs: np.ndarray) -> Any:
    """The session's own submaps' grids merged in the world (anchors ``sTa`` in the session frame, placed by
    ``wTs``); None when it has none."""
    from holoslam.lifelong.merge import merge_submaps

    subs = [sm for sm in submaps if sm.grid is not None and sm.grid.known is not None]
    if not subs:
        return None
    wTa = g.compose(np.broadcast_to(np.asarray(wTs, np.float64), (len(subs), 3)),
                    np.asarray(sTa, np.float64)[[sm.index for sm in subs]])
    return merge_submaps(wTa, [(sm.grid.prob, sm.grid.known, sm.grid.origin, sm.grid.resolution) for sm in subs],
                         [0] * len(subs), margin_m=0.0)
