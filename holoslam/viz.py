"""Pictures of holoslam results (matplotlib, imported lazily; no pyplot: no GUI backend, no global state).

Each ``draw_*`` function draws onto a matplotlib ``Axes`` the caller gives, in world metres, and returns the
artists it added; :func:`map_figure` and :func:`trajectory_figure` return a new ``Figure`` (render it with
``fig.savefig(path)``; writing files is the caller's job). Importing this module does not import matplotlib.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from holoslam.maps.grid import cells_to_world

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from holoslam.maps.grid import OccupancyGrid
    from holoslam.planning.routes import Route
    from holoslam.planning.twolayer import TwoLayerGraph

__all__ = [
    "draw_grid",
    "draw_topology",
    "draw_holographic",
    "draw_planning",
    "draw_route",
    "draw_trajectory",
    "covariance_ellipse",
    "map_figure",
    "trajectory_figure",
    "draw_rooms",
    "store_figure",
    "map_figsize",
]

PLACE_COLOURS = {"room": "tab:red", "doorway": "tab:green", "crossing": "tab:blue", "dead_end": "tab:purple"}


def _extent(grid: OccupancyGrid) -> tuple[float, float, float, float]:
    h, w = grid.shape
    return (
        grid.origin_x,
        grid.origin_x + w * grid.resolution,
        grid.origin_y,
        grid.origin_y + h * grid.resolution,
    )


#: An image drawn on axes is pooled to at most this many pixels per display pixel of the axes (two: a map
#: picture stays as sharp as its figure can show at up to twice the figure's dpi); a 7,000 x 5,000-cell
#: floor would otherwise be resampled by matplotlib in float RGBA at full size (1.1 GB per layer, issue 26).
IMAGE_PIXELS_PER_DISPLAY_PIXEL = 2.0


def map_figsize(shape: tuple[int, int], size_in: float) -> tuple[float, float]:
    """Inches of a map's figure: the map's longer side ``size_in`` long (a tall map is not drawn ``size_in``
    wide, which made a 350 m building drawn north-south 24 inches tall: every layer resampled at full size,
    1.5 GB per picture), plus room for the axes' labels."""
    h, w = max(int(shape[0]), 1), max(int(shape[1]), 1)
    if h <= w:
        return (size_in, size_in * h / w + 0.5)
    return (max(size_in * w / h, 2.0) + 1.0, size_in + 0.5)


def _stride(ax: Axes, shape: tuple[int, int]) -> int:
    """Cells per drawn pixel: 1 unless the grid has more cells than ``IMAGE_PIXELS_PER_DISPLAY_PIXEL`` times
    the axes' display pixels along a side."""
    bb = ax.get_window_extent()
    px = max(float(bb.width), float(bb.height), 1.0) * IMAGE_PIXELS_PER_DISPLAY_PIXEL
    return max(1, int(max(shape) // px))


def _pooled(img: np.ndarray, f: int, fill: int, how: str) -> np.ndarray:
    """(H, W) -> (ceil(H / f), ceil(W / f)) blocks of f x f cells (padded with ``fill``), each the block's
    minimum (``min``: walls stay visible at any scale) or its first cell (``first``: labels)."""
    if f == 1:
        return img
    h, w = img.shape
    if how == "first":
        return img[::f, ::f]
    pad = np.full((-(-h // f) * f, -(-w // f) * f), fill, dtype=img.dtype)
    pad[:h, :w] = img
    return pad.reshape(pad.shape[0] // f, f, pad.shape[1] // f, f).min(axis=(1, 3))


def _pooled_extent(grid: OccupancyGrid, f: int) -> tuple[float, float, float, float]:
    h, w = grid.shape
    if f == 1:
        return _extent(grid)
    hh, ww = -(-h // f) * f, -(-w // f) * f
    return (grid.origin_x, grid.origin_x + ww * grid.resolution, grid.origin_y, grid.origin_y + hh * grid.resolution)


def draw_grid(ax: Axes, grid: OccupancyGrid) -> list[Any]:
    """The occupancy grid: free white, occupied black, unknown grey (row 0 at the bottom). A grid larger than the
    axes can show is pooled first (``IMAGE_PIXELS_PER_DISPLAY_PIXEL``; a block with an obstacle is drawn black)."""
    occ = grid.occupancy
    code = np.full(grid.shape, 153, dtype=np.uint8)  # unknown: 0.6 grey
    code[(occ >= 0) & (occ <= grid.free_thresh * 100.0)] = 255
    code[occ >= grid.occupied_thresh * 100.0] = 0
    f = _stride(ax, grid.shape)
    img = _pooled(code, f, 153, "min").astype(np.float32) / np.float32(255.0)
    im = ax.imshow(
        img, origin="lower", extent=_pooled_extent(grid, f), cmap="gray", vmin=0, vmax=1, interpolation="nearest"
    )
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    return [im]


def draw_rooms(ax: Axes, grid: OccupancyGrid, labels: np.ndarray, alpha: float = 0.45) -> list[Any]:
    """A room label image ((H, W), 0 = none, grid row order) as translucent colours over the map, one colour per
    room id (a fixed palette cycled by id, so neighbours rarely share one); pooled as the grid is."""
    from matplotlib import colormaps

    f = _stride(ax, grid.shape)
    lab = _pooled(np.asarray(labels), f, 0, "first")
    pal = colormaps["tab20"](np.arange(20)).astype(np.float32)
    rgba = np.zeros(lab.shape + (4,), dtype=np.float32)
    on = lab > 0
    rgba[on] = pal[(lab[on] * 7) % 20]
    rgba[on, 3] = alpha
    im = ax.imshow(rgba, origin="lower", extent=_pooled_extent(grid, f), interpolation="nearest", zorder=1)
    return [im]


def _cells_xy(path: np.ndarray, res: float, ox: float, oy: float) -> np.ndarray:
    return cells_to_world(path, ox, oy, res)


def draw_topology(ax: Axes, topology, grid: OccupancyGrid, colour: str = "tab:cyan") -> list[Any]:
    """Topology edges along their skeleton paths and nodes coloured by kind."""
    from matplotlib.collections import LineCollection

    segs = [
        _cells_xy(d["path"], grid.resolution, grid.origin_x, grid.origin_y)
        for _u, _v, d in topology.edges(data=True)
        if "path" in d and not isinstance(d["path"], str)
    ]
    arts: list[Any] = [ax.add_collection(LineCollection(segs, colors=colour, linewidths=1.0))]
    kinds = {"junction": "tab:orange", "endpoint": "tab:pink", "isolated": "k", "loop": "tab:olive"}
    for kind, c in kinds.items():
        pts = np.array([(d["x"], d["y"]) for _n, d in topology.nodes(data=True) if d.get("kind") == kind])
        if pts.size:
            arts.append(ax.scatter(pts[:, 0], pts[:, 1], s=12, c=c, label=kind, zorder=3))
    return arts


#: Node names are written beside the nodes of a holographic graph of at most this many nodes (a household's
#: dozens); on a building's thousands they would cover the map and cost seconds of text layout.
LABELS_MAX_NODES = 300


def draw_holographic(ax: Axes, G, labels: bool | None = None) -> list[Any]:
    """The holographic graph: passages along their waypoints, environment nodes by place, objects as
    stars (hollow when unreachable, red-edged when seen only once), object edges as dashed lines to their places.
    ``labels``: the node names beside the nodes (None: when the graph has at most ``LABELS_MAX_NODES``)."""
    from matplotlib.collections import LineCollection

    if labels is None:
        labels = G.number_of_nodes() <= LABELS_MAX_NODES

    arts: list[Any] = []
    passages, links = [], []
    for u, v, d in G.edges(data=True):
        if d.get("kind") == "passage":
            p = d.get("passage")
            if isinstance(p, np.ndarray) and p.ndim == 2:
                passages.append(p)
        elif d.get("kind") == "object_edge":
            a, b = G.nodes[u], G.nodes[v]
            links.append(np.array([[a["x"], a["y"]], [b["x"], b["y"]]]))
    if passages:
        arts.append(ax.add_collection(LineCollection(passages, colors="tab:brown", linewidths=1.5, zorder=2)))
    if links:
        arts.append(
            ax.add_collection(
                LineCollection(links, colors="tab:gray", linewidths=0.6, linestyles="--", zorder=2)
            )
        )
    for place, c in PLACE_COLOURS.items():
        nodes = [
            (n, d)
            for n, d in G.nodes(data=True)
            if d.get("kind") == "environment" and d.get("place") == place
        ]
        if nodes:
            xy = np.array([(d["x"], d["y"]) for _n, d in nodes])
            size = 40 if G.number_of_nodes() <= LABELS_MAX_NODES else 12
            arts.append(ax.scatter(xy[:, 0], xy[:, 1], s=size, c=c, label=place, zorder=4, edgecolors="k"))
            if labels:
                for n, d in nodes:
                    arts.append(
                        ax.annotate(
                            str(n), (d["x"], d["y"]), fontsize=6, xytext=(3, 3), textcoords="offset points"
                        )
                    )
    objs = [
        (n, d, G.degree(n) > 0, 0 < int(d.get("sightings", 0)) < 2)
        for n, d in G.nodes(data=True)
        if d.get("kind") == "object"
    ]
    for reach, once in ((True, False), (False, False), (True, True), (False, True)):
        sel = [(n, d) for n, d, r, o in objs if r == reach and o == once]
        if sel:
            xy = np.array([(d["x"], d["y"]) for _n, d in sel])
            what = ("object" if reach else "object (unreachable)") + (", seen once" if once else "")
            arts.append(
                ax.scatter(
                    xy[:, 0],
                    xy[:, 1],
                    s=60,
                    marker="*",
                    facecolors="gold" if reach else "none",
                    edgecolors="red" if once else "darkgoldenrod",
                    label=what,
                    zorder=5,
                )
            )
            if labels:
                for n, d in sel:
                    arts.append(
                        ax.annotate(
                            str(n), (d["x"], d["y"]), fontsize=5, xytext=(2, -7), textcoords="offset points"
                        )
                    )
    return arts


def draw_planning(ax: Axes, tl: TwoLayerGraph, layer: int = 2, edges: bool = False) -> list[Any]:
    """Layer 1 (free blocks) or layer 2 (convex regions) as rectangles; ``edges`` adds the adjacency."""
    from matplotlib.collections import LineCollection, PolyCollection

    rects = tl.block_corners_xy if layer == 1 else tl.region_corners_xy
    polys = (
        np.stack([rects[:, [0, 1]], rects[:, [2, 1]], rects[:, [2, 3]], rects[:, [0, 3]]], axis=1)
        if rects.shape[0]
        else np.zeros((0, 4, 2))
    )
    rng = np.random.default_rng(0)
    colours = rng.uniform(0.3, 0.95, size=(polys.shape[0], 3))
    alpha = 0.25 if layer == 2 else 0.4
    arts: list[Any] = [
        ax.add_collection(
            PolyCollection(
                list(polys),
                facecolors=np.column_stack([colours, np.full(len(colours), alpha)]),
                edgecolors="k",
                linewidths=0.3,
            )
        )
    ]
    if edges:
        if layer == 1:
            c, e = tl.block_centres_xy, tl.edges
        else:
            r = tl.region_corners_xy
            c, e = np.column_stack([(r[:, 0] + r[:, 2]) / 2, (r[:, 1] + r[:, 3]) / 2]), tl.region_edges
        if e.shape[0]:
            arts.append(
                ax.add_collection(
                    # an (E, 2, 2) array of segments (the stub names a sequence)
                    LineCollection(np.stack([c[e[:, 0]], c[e[:, 1]]], 1),  # type: ignore[arg-type]
                                   colors="tab:blue", linewidths=0.5)
                )
            )
    ax.autoscale_view()
    return arts


def draw_route(ax: Axes, route: Route | np.ndarray, colour: str = "tab:red") -> list[Any]:
    """A planned route's waypoints (or a (K, 2) array) with start (circle) and goal (cross)."""
    wp = route if isinstance(route, np.ndarray) else route.waypoints
    wp = np.asarray(wp, dtype=np.float64).reshape(-1, 2)
    (line,) = ax.plot(wp[:, 0], wp[:, 1], "-", color=colour, lw=2, zorder=6)
    s = ax.scatter(wp[:1, 0], wp[:1, 1], marker="o", c=colour, zorder=7)
    g = ax.scatter(wp[-1:, 0], wp[-1:, 1], marker="x", c=colour, s=60, zorder=7)
    return [line, s, g]


def covariance_ellipse(
    wTb: np.ndarray, cov_wTb: np.ndarray, n_sigma: float = 2.0, n_points: int = 48
) -> np.ndarray:
    """(n_points, 2) world outline of the n-sigma position ellipse of a pose whose covariance is in the pose's
    own frame (the x, y block is rotated into the world by the pose's heading)."""
    x, y, th = np.asarray(wTb, dtype=np.float64).reshape(3)
    c, s = np.cos(th), np.sin(th)
    R = np.array([[c, -s], [s, c]])
    P = R @ np.asarray(cov_wTb, dtype=np.float64)[:2, :2] @ R.T
    vals, vecs = np.linalg.eigh(0.5 * (P + P.T))
    vals = np.clip(vals, 0.0, None)
    t = np.linspace(0.0, 2.0 * np.pi, n_points)
    circle = np.stack([np.cos(t), np.sin(t)], axis=1)
    return np.array([x, y]) + n_sigma * (circle * np.sqrt(vals)) @ vecs.T


def draw_trajectory(
    ax: Axes,
    wTb: np.ndarray,
    cov_wTb: np.ndarray | None = None,
    every: int = 1,
    n_sigma: float = 2.0,
    colour: str = "tab:blue",
    label: str | None = None,
    points: bool = False,
) -> list[Any]:
    """A trajectory (N, 3) as a line (or, with ``points``, as separate dots: e.g. submap anchors, which a line
    would join across walls), with n-sigma covariance ellipses at every ``every``-th pose when ``cov_wTb``
    (N, 3, 3) is given."""
    from matplotlib.collections import LineCollection

    T = np.asarray(wTb, dtype=np.float64).reshape(-1, 3)
    style: dict[str, Any] = dict(ls="none", marker="o", ms=2.5) if points else dict(ls="-", lw=1.2)
    (line,) = ax.plot(T[:, 0], T[:, 1], color=colour, label=label, **style)
    arts: list[Any] = [line]
    if cov_wTb is not None:
        C = np.asarray(cov_wTb, dtype=np.float64).reshape(-1, 3, 3)
        idx = np.arange(0, T.shape[0], max(int(every), 1))
        ell = [covariance_ellipse(T[i], C[i], n_sigma) for i in idx if np.all(np.isfinite(C[i][:2, :2]))]
        if ell:
            arts.append(ax.add_collection(LineCollection(ell, colors=colour, linewidths=0.6, alpha=0.7)))
    ax.set_aspect("equal")
    return arts


#: a figure's margins in inches (left, bottom, right, top): room for the tick labels of a map in metres (up to
#: four digits and a sign at matplotlib's default 10 pt), the axis labels and the title. Fixed margins instead
#: of ``tight_layout``: measuring every tick label's extent took a third of a run's picture time (0.2 s of the
#: household run's 8 s), for margins that differ by a few points
MARGINS_IN = (0.75, 0.5, 0.2, 0.4)


def _set_margins(fig: Figure) -> None:
    """Set the figure's subplot margins to ``MARGINS_IN`` (no layout engine: ``savefig`` draws once)."""
    w, h = fig.get_size_inches()
    left, bottom, right, top = MARGINS_IN
    fig.subplots_adjust(left=left / w, bottom=bottom / h, right=1 - right / w, top=1 - top / h)


def map_figure(
    grid: OccupancyGrid,
    topology=None,
    holographic=None,
    planning: TwoLayerGraph | None = None,
    planning_layer: int = 2,
    route: Route | np.ndarray | None = None,
    title: str | None = None,
    size_in: float = 8.0,
    rooms: np.ndarray | None = None,
) -> Figure:
    """A new figure of the grid with any of: room labels, topology, planning layer, holographic graph, route."""
    from matplotlib.figure import Figure

    h, w = grid.shape
    fig = Figure(figsize=map_figsize((h, w), size_in))
    ax = fig.add_subplot(1, 1, 1)
    draw_grid(ax, grid)
    if rooms is not None:
        draw_rooms(ax, grid, rooms)
    if planning is not None:
        draw_planning(ax, planning, layer=planning_layer)
    if topology is not None:
        draw_topology(ax, topology, grid)
    if holographic is not None:
        draw_holographic(ax, holographic)
    if route is not None:
        draw_route(ax, route)
    x0, x1, y0, y1 = _extent(grid)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    if title:
        ax.set_title(title)
    if topology is not None or holographic is not None:
        ax.legend(loc="upper right", fontsize=6)
    _set_margins(fig)
    return fig


def trajectory_figure(
    trajectories: dict[str, np.ndarray],
    covariances: dict[str, np.ndarray] | None = None,
    grid: OccupancyGrid | None = None,
    every: int = 10,
    title: str | None = None,
) -> Figure:
    """A new figure with named trajectories (N, 3) (e.g. dead reckoning, optimised, ground truth), optional
    per-pose covariances (N, 3, 3) drawn as 2-sigma ellipses, over an optional grid."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 7))
    ax = fig.add_subplot(1, 1, 1)
    if grid is not None:
        draw_grid(ax, grid)
    colours = ["tab:blue", "tab:red", "tab:green", "tab:orange", "tab:purple"]
    for i, (name, T) in enumerate(trajectories.items()):
        cov = (covariances or {}).get(name)
        draw_trajectory(ax, T, cov, every=every, colour=colours[i % len(colours)], label=name)
    ax.legend(fontsize=7)
    if title:
        ax.set_title(title)
    _set_margins(fig)
    return fig


def store_figure(ex: Any, object_ids: tuple[str, ...] = (), title: str | None = None, size_in: float = 8.0
                 ) -> Figure:
    """A map store (``holoslam.lifelong.export.StoreExport``): the merged grid, every joined session's trajectory
    (one colour each), the objects where they are now (gone ones as crosses) and the history of ``object_ids``:
    their place in each session that saw them, joined in order and labelled with the session."""
    from matplotlib.figure import Figure

    grid = ex.grid
    h, w = grid.shape
    fig = Figure(figsize=map_figsize((h, w), size_in))
    ax = fig.add_subplot(1, 1, 1)
    draw_grid(ax, grid)
    colours = [f"C{k % 10}" for k in range(len(ex.trajectories))]
    for c, (sid, (_t, wTb, joined)) in zip(colours, sorted(ex.trajectories.items()), strict=True):
        if joined:
            ax.plot(wTb[:, 0], wTb[:, 1], "-", lw=0.6, color=c, alpha=0.7, label=f"session {sid}")
    for o in ex.objects_now:
        if o.w_xy is None:
            continue
        gone = o.status == "gone"
        ax.plot(o.w_xy[0], o.w_xy[1], "x" if gone else "o", ms=4, color="tab:red" if gone else "black")
        ax.annotate(o.object_id, o.w_xy, fontsize=5, xytext=(2, 2), textcoords="offset points")
    for oid in object_ids:
        hist = [o for o in ex.history if o.object_id == oid and o.w_xy is not None and o.status != "unplaced"]
        if not hist:
            continue
        xy = np.array([o.w_xy for o in hist])
        ax.plot(xy[:, 0], xy[:, 1], "-o", color="tab:orange", lw=1.5, ms=5, label=f"{oid} by session")
        for o in hist:
            ax.annotate(f"{o.session_id}:{o.status}", o.w_xy, fontsize=6, color="tab:orange", xytext=(3, -8),
                        textcoords="offset points")
    x0, x1, y0, y1 = _extent(grid)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.legend(loc="upper right", fontsize=6)
    if title:
        ax.set_title(title)
    _set_margins(fig)
    return fig
