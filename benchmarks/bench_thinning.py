"""Thinning and skeleton-to-graph on the household map and on 4000 x 4000 maps, next to skimage.

    .venv/bin/python benchmarks/bench_thinning.py [--quick] [--repeat N]

Maps:
- household: the reference household (holoslam.sim.world) scanned by a simulated 360-degree laser from
  standable points on a 0.5 m lattice, ray-cast into a 5 cm occupancy grid with holoslam.maps.occupancy;
- household x tiled: that grid's free mask tiled to 4000 x 4000 (many small rooms, few iterations);
- household x scaled: the free mask scaled up (nearest) to 4000 x 4000 (wide rooms, many iterations);
- apartment: a synthetic 4000 x 4000 grid of 5 m rooms with doors and 3000 random boxes.

Times are medians over --repeat runs in this process; `ratio` is holoslam thin / skimage skeletonize on the
same mask (wall time), `cpu_ratio` the same with this process's CPU time (steadier on a shared machine;
OpenCV's threads count in it), `graph_cpu_ms` the graph step's CPU time (median of at least 3 runs; the
first run in a process also pays the page faults of its first large allocations). Graph = skeleton_to_graph on thin's skeleton with a precomputed clearance map (the distance
transform is timed separately, as `clear`). Quality, for both skeletons: 8-connected components of free
space vs of the skeleton, holes (4-connected obstacle components not touching the border; all sizes, and
those of at least MIN_HOLE cells) vs independent cycles of the graph, and cells still removable
(count_removable: simple, not a line tip).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

MIN_HOLE = 9  # cells; reported separately (holes of any size must give a cycle of the graph)


def household_grid():
    from holoslam.maps.occupancy import build_grid
    from holoslam.sim.world import free_space, raycast, reference_household
    from holoslam.types import Scan

    world = reference_household()
    fs = free_space(world, 0.05)
    rr, cc = np.nonzero(fs.standable)
    xy = fs.xy_of(rr, cc)
    lattice = np.unique(np.round(xy / 0.5).astype(int), axis=0) * 0.5
    lattice = lattice[fs.standable[fs.cell_of(lattice)]]
    n = 360
    angles = -np.pi + np.arange(n) * (2 * np.pi / n)
    ranges = raycast(world.obstacle_segments(), lattice, np.broadcast_to(angles, (len(lattice), n)), 8.0)
    scans = [
        Scan(i, "laser", -np.pi, 2 * np.pi / n, 0.05, 8.0, r.astype(np.float32), np.isfinite(r))
        for i, r in enumerate(ranges)
    ]
    wTs = np.column_stack([lattice, np.zeros(len(lattice))])
    t = time.perf_counter()
    grid = build_grid(wTs, scans, resolution=0.05)
    return grid, time.perf_counter() - t, len(scans) * n


def apartment(h=4000, seed=1):
    rng = np.random.default_rng(seed)
    m = np.ones((h, h), np.uint8)
    for k in range(0, h, 100):
        m[k : k + 3, :] = 0
        m[:, k : k + 3] = 0
    for k in range(50, h, 100):
        for j in range(50, h, 100):
            m[k - 30 : k + 30, j - 52 : j - 40] = 1
            m[k - 52 : k - 40, j - 30 : j + 30] = 1
    for _ in range(3000):
        r, c = rng.integers(0, h, 2)
        s = rng.integers(3, 20, 2)
        m[r : r + s[0], c : c + s[1]] = 0
    return m.astype(bool)


def topology_numbers(mask: np.ndarray) -> tuple[int, int, int]:
    """(components, holes, holes of >= MIN_HOLE cells)."""
    import cv2

    m = mask.astype(np.uint8)
    comps = cv2.connectedComponents(m, connectivity=8)[0] - 1
    bg = np.pad(1 - m, 1, constant_values=1).astype(np.uint8)
    nlab, lab, stats, _ = cv2.connectedComponentsWithStats(bg, connectivity=4)
    border = lab[0, 0]
    sizes = np.delete(stats[1:, cv2.CC_STAT_AREA], border - 1)
    return comps, len(sizes), int((sizes >= MIN_HOLE).sum())


CPU: dict[str, float] = {}  # median process CPU time of the last median_time call per label


def median_time(f, repeat, label=None):
    """Median wall time over repeat runs (and, under label, the median CPU time of this process in CPU)."""
    ts, cs, outs = [], [], []
    for _ in range(repeat):
        c = time.process_time()
        t = time.perf_counter()
        outs.append(f())  # kept: freeing the previous result is not part of the next run
        ts.append(time.perf_counter() - t)
        cs.append(time.process_time() - c)
    if label:
        CPU[label] = statistics.median(cs)
    return statistics.median(ts), outs[-1]


def run(name, free, resolution, repeat, rows):
    import networkx as nx
    from skimage.morphology import skeletonize

    from holoslam.maps.thinning import count_removable, thin
    from holoslam.maps.topology import clearance_map, cycle_rank, skeleton_to_graph

    t_sk, sk_ref = median_time(lambda: skeletonize(free), repeat, "sk")
    t_thin, sk = median_time(lambda: thin(free), repeat, "thin")
    t_clear, clr = median_time(lambda: clearance_map(free, resolution), repeat)
    t_graph, G = median_time(
        lambda: skeleton_to_graph(sk, resolution=resolution, clearance=clr), max(repeat, 3), "graph"
    )
    Gref = skeleton_to_graph(sk_ref, resolution=resolution)
    comps, holes, big_holes = topology_numbers(free)
    rows.append(
        dict(
            map=name,
            size=f"{free.shape[0]}x{free.shape[1]}",
            free=int(free.sum()),
            skimage_s=t_sk,
            thin_s=t_thin,
            ratio=t_thin / t_sk,
            cpu_ratio=CPU["thin"] / CPU["sk"],
            graph_ms=1e3 * t_graph,
            graph_cpu_ms=1e3 * CPU["graph"],
            clear_ms=1e3 * t_clear,
            nodes=G.number_of_nodes(),
            edges=G.number_of_edges(),
            comps=f"{comps}/{nx.number_connected_components(G)}/{nx.number_connected_components(Gref)}",
            holes=f"{holes}({big_holes})/{cycle_rank(G)}/{cycle_rank(Gref)}",
            removable=f"{count_removable(sk)}/{count_removable(sk_ref)}",
            same_topology=topology_numbers(sk)[:2] == (comps, holes),
        )
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1000 x 1000 instead of 4000 x 4000")
    ap.add_argument("--repeat", type=int, default=3, help="runs per timing on the household map")
    args = ap.parse_args()
    import cv2

    side = 1000 if args.quick else 4000
    grid, t_grid, nbeams = household_grid()
    print(
        f"household grid: {grid.shape[0]}x{grid.shape[1]} cells at {grid.resolution} m from {nbeams} beams, "
        f"build_grid {t_grid:.2f} s"
    )
    free = grid.free
    rows: list[dict] = []
    run("household", free, grid.resolution, max(args.repeat, 5), rows)
    reps = -(-side // np.array(free.shape))
    tiled = np.tile(free, tuple(reps))[:side, :side]
    run("household x tiled", tiled, grid.resolution, 1, rows)
    scaled = cv2.resize(free.astype(np.uint8), (side, side), interpolation=cv2.INTER_NEAREST).astype(bool)
    run("household x scaled", scaled, grid.resolution * free.shape[1] / side, 1, rows)
    run("apartment", apartment(side), 0.05, 1, rows)

    head = [
        "map",
        "size",
        "free",
        "skimage_s",
        "thin_s",
        "ratio",
        "cpu_ratio",
        "graph_ms",
        "graph_cpu_ms",
        "clear_ms",
        "nodes",
        "edges",
        "comps",
        "holes",
        "removable",
        "same_topology",
    ]
    fmt = {
        "skimage_s": "{:.3f}",
        "thin_s": "{:.3f}",
        "ratio": "{:.2f}",
        "cpu_ratio": "{:.2f}",
        "graph_ms": "{:.1f}",
        "graph_cpu_ms": "{:.1f}",
        "clear_ms": "{:.1f}",
    }
    table = [[fmt.get(h, "{}").format(r[h]) for h in head] for r in rows]
    widths = [max(len(h), *(len(t[i]) for t in table)) for i, h in enumerate(head)]
    print("  ".join(h.ljust(w) for h, w in zip(head, widths, strict=True)))
    for t in table:
        print("  ".join(v.ljust(w) for v, w in zip(t, widths, strict=True)))
    print(
        "comps: free space / holoslam graph / graph of skimage's skeleton; holes: free-space holes (of >= "
        f"{MIN_HOLE} cells) / independent cycles of holoslam's graph / of skimage's; removable: holoslam / "
        "skimage; same_topology: holoslam skeleton has the components and holes of free space"
    )


if __name__ == "__main__":
    main()
