"""Topology (cleaning + thinning + graph) and holographic graph on real maps, and their scaling.

    .venv/bin/python benchmarks/bench_holographic.py [--repeat N] [--runs RUN_DIR ...] [--no-tiled]

Maps: the public maps of ../shared/maps and ../shared/rooms (when present; nav2_depot's grey 205 counted as
unknown, as its README says), the ``map.yaml`` of any run folders given with ``--runs`` (e.g. the Freiburg logs
mapped by ``holoslam run``), and a furnished office floor (office_a_furnitures) tiled to 1500 x 1500 and
4000 x 4000 cells. Both stages run as the pipeline calls them (``RunConfig`` defaults: topology with
``close_cells`` 0 and the default cleaning, holographic with the run's rooms, reach model and places), after
one warm-up call (numba kernels loaded); times are medians over ``--repeat`` runs in this process.

Columns: ``topo_s`` / ``holo_s`` stage times (wall clock) and ``holo_cpu`` the holographic stage's CPU time of
this process (``time.process_time``: what the wall time is on an idle machine; a shared machine's load inflates
the wall time, not this); ``nodes`` / ``edges`` of the topology; ``comp`` / ``cyc`` its
components and independent cycles with the default cleaning and no opening (``holoslam topology``'s
defaults) beside ``regions`` / ``islands``, the free regions >= 0.25 m^2 and obstacle islands >= 0.05 m^2
counted on the map (issue 14: they must be equal); ``raw_nodes`` the topology without cleaning; the
holographic graph's places.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

SHARED = Path(__file__).resolve().parents[1].parent / "shared"


def load(path: Path):
    import cv2

    from holoslam.io.grid import read_grid
    from holoslam.maps.grid import OccupancyGrid

    g = read_grid(path)
    if path.stem == "nav2_depot":  # README: 205 is unknown although the YAML's free_thresh makes it free
        img = cv2.imread(str(path.with_suffix(".pgm")), cv2.IMREAD_UNCHANGED)
        occ = np.flipud(np.where(img >= 254, 0, np.where(img == 205, -1, 100))).astype(np.int8)
        g = OccupancyGrid(occ, g.resolution, g.origin_x, g.origin_y, g.occupied_thresh, g.free_thresh)
    return g


def tiled(grid, size: int):
    from holoslam.maps.grid import OccupancyGrid

    h, w = grid.shape
    occ = np.tile(grid.occupancy, (size // h + 1, size // w + 1))[:size, :size]
    return OccupancyGrid(occ, grid.resolution, free_thresh=grid.free_thresh)


def significant(grid) -> tuple[int, int]:
    """Free regions >= 0.25 m^2 (8-connected) and obstacle islands >= 0.05 m^2 (4-connected non-free
    components not touching the edge, after the small regions are dropped), with scipy.ndimage."""
    from scipy import ndimage

    res2 = grid.resolution**2
    lab, n = ndimage.label(grid.free, structure=np.ones((3, 3)))
    keep = np.bincount(lab.ravel(), minlength=n + 1) * res2 >= 0.25
    keep[0] = False
    olab, m = ndimage.label(np.pad(~keep[lab], 1, constant_values=True))
    oarea = np.bincount(olab.ravel(), minlength=m + 1) * res2
    return int(keep.sum()), sum(1 for k in range(1, m + 1) if k != olab[0, 0] and oarea[k] >= 0.05)


def measure(name: str, grid, repeat: int, counts: bool = True) -> dict:
    import networkx as nx

    from holoslam.config import RunConfig
    from holoslam.mapping import reach_model
    from holoslam.maps.holographic import build_holographic
    from holoslam.maps.passages import EdgePaths
    from holoslam.maps.rooms import rooms_of_grid
    from holoslam.maps.topology import cycle_rank, topology_from_grid, topology_from_settings

    cfg = RunConfig()
    tc, hc = cfg.topology, cfg.holographic

    def topo():
        return topology_from_settings(grid, tc)

    def holo(T):  # the stage as the pipeline runs it: rooms, then the graph on them
        ep = EdgePaths(T)
        rooms = rooms_of_grid(grid, T, hc.rooms, ep)
        return build_holographic(
            grid, T, reach_model=reach_model(cfg.robot), params=hc.places, rooms=rooms, edge_paths=ep
        )

    T = topo()
    H = holo(T)
    tt, th, tcpu = [], [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        T = topo()
        t1 = time.perf_counter()
        c1 = time.process_time()
        H = holo(T)
        t2 = time.perf_counter()
        tcpu.append(time.process_time() - c1)
        tt.append(t1 - t0)
        th.append(t2 - t1)
    places: dict[str, int] = {}
    for _n, p in H.nodes(data="place"):
        places[p] = places.get(p, 0) + 1
    row = dict(
        map=name,
        size=f"{grid.shape[1]}x{grid.shape[0]}",
        topo_s=statistics.median(tt),
        holo_s=statistics.median(th),
        holo_cpu=statistics.median(tcpu),
        nodes=T.number_of_nodes(),
        edges=T.number_of_edges(),
        places=" ".join(f"{k} {v}" for k, v in sorted(places.items())),
    )
    if counts:
        D = topology_from_grid(grid)  # holoslam topology's defaults: cleaning, no opening
        row.update(comp=nx.number_connected_components(D), cyc=cycle_rank(D))
        row["regions"], row["islands"] = significant(grid)
        row["raw_nodes"] = topology_from_grid(grid, cleaning=None).number_of_nodes()
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--runs", nargs="*", default=[], help="run folders whose map.yaml to include")
    ap.add_argument("--no-tiled", action="store_true")
    a = ap.parse_args()
    maps = sorted((SHARED / "maps").glob("*.yaml")) + sorted((SHARED / "rooms").glob("*.yaml"))
    maps += [Path(r) / "map.yaml" for r in a.runs]
    rows = []
    head = (
        f"{'map':30s} {'cells':>10s} {'topo_s':>7s} {'holo_s':>7s} {'holo_cpu':>8s} {'nodes':>6s} {'edges':>6s} "
        f"{'comp':>5s} {'regions':>7s} {'cyc':>5s} {'islands':>7s} {'raw_nodes':>9s}  places"
    )
    print(head)

    def show(r):
        print(
            f"{r['map']:30s} {r['size']:>10s} {r['topo_s']:7.3f} {r['holo_s']:7.3f} {r['holo_cpu']:8.3f} "
            f"{r['nodes']:6d} {r['edges']:6d} "
            f"{r.get('comp', ''):>5} {r.get('regions', ''):>7} {r.get('cyc', ''):>5} {r.get('islands', ''):>7} "
            f"{r.get('raw_nodes', ''):>9}  {r['places']}",
            flush=True,
        )

    for path in maps:
        name = path.stem if path.name != "map.yaml" else path.parent.name
        rows.append(measure(name, load(path), a.repeat))
        show(rows[-1])
    office = SHARED / "rooms" / "office_a_furnitures.yaml"
    if not a.no_tiled and office.exists():
        for size in (1500, 4000):
            rows.append(
                measure("office_a_furnitures tiled", tiled(load(office), size), max(1, a.repeat // 2))
            )
            show(rows[-1])
    for r in rows:
        if r["map"].endswith("tiled"):
            goal = 1.0 if r["size"] == "1500x1500" else 10.0
            print(
                f"holographic stage at {r['size']}: {r['holo_s']:.2f} s wall, {r['holo_cpu']:.2f} s CPU "
                f"(goal <= {goal:g} s)"
            )
    bad = [r["map"] for r in rows if "comp" in r and (r["comp"], r["cyc"]) != (r["regions"], r["islands"])]
    print(
        f"components/cycles equal to significant regions/islands on {len(rows) - len(bad)} of {len(rows)} maps"
    )
    if bad:
        print("  not on:", ", ".join(bad))


if __name__ == "__main__":
    main()
