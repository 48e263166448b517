"""Room segmentation on the room-segmentation benchmark of Bormann et al. (ICRA 2016): recall and precision per
map and on average beside the figures reported for the benchmark's methods, and the time per map.

    .venv/bin/python benchmarks/bench_rooms.py [--dir ../shared/rooms] [--repeat 3] [--write OUT_DIR]

Maps: every ``<name>.yaml`` / ``<name>_furnitures.yaml`` with a ``<name>_gt_segmentation.png`` in ``--dir``
(ten maps, plain and furnished; see its README). Each map is segmented as ``holoslam topology MAP.yaml --rooms``
does it with the run's defaults: the topology (cleaning, thinning; ``topo_s``), then the rooms
(``holoslam.maps.rooms.rooms_of_grid``; ``rooms_s``), wall clock, and ``cpu_s`` the CPU time of both
(``time.process_time``: the wall time of an idle machine; a shared machine's load inflates only the wall time),
medians over ``--repeat`` runs after one warm-up call (numba kernels loaded). The label image (rows as the map image) is scored by holoslam's own metric
(``holoslam.evaluate_rooms``) and, when ``score_rooms.py`` is in ``--dir``, by that independent scorer too: the
``agree`` column says both give the same four numbers (to 1e-12). ``--write`` writes each label image as a 16-bit
PNG, for ``score_rooms.py score PRED.png GT.png``.

Reported figures (recall / precision %, averaged over the benchmark's 20 maps, read in a secondary source): see
``REPORTED``; their runtimes are per map on the authors' machine.
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import time
from pathlib import Path

import numpy as np

SHARED = Path(__file__).resolve().parents[1].parent / "shared"

REPORTED = {  # method: (recall, precision) %, plain and furnished; runtime s per map
    "morphological": ((98.1, 88.5), (84.6, 90.5), 1.6),
    "distance transform": ((96.9, 88.4), (76.1, 88.4), 1.8),
    "Voronoi": ((95.0, 94.8), (86.6, 94.5), 13.0),
    "feature-based (AdaBoost)": ((89.2, 90.4), (85.1, 87.1), 269.0),
}


def _reference_scorer(folder: Path):
    """score_rooms.py of the benchmark folder as a module, or None."""
    path = folder / "score_rooms.py"
    if not path.is_file():
        return None
    spec = importlib.util.spec_from_file_location("score_rooms_reference", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return mod


def segment(grid):
    """(topology, rooms) of a grid as ``holoslam topology --rooms`` makes them (the run's defaults)."""
    from holoslam.config import RunConfig
    from holoslam.maps.rooms import rooms_of_grid
    from holoslam.maps.topology import topology_from_settings

    cfg = RunConfig()
    tc = cfg.topology
    c0 = time.process_time()
    t0 = time.perf_counter()
    topo = topology_from_settings(grid, tc)
    t1 = time.perf_counter()
    rooms = rooms_of_grid(grid, topo, cfg.holographic.rooms)
    t2 = time.perf_counter()
    return topo, rooms, t1 - t0, t2 - t1, time.process_time() - c0


def main() -> None:
    import cv2

    from holoslam.evaluate_rooms import gt_room_labels, score_rooms
    from holoslam.io.grid import read_grid, write_label_png

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dir", type=Path, default=SHARED / "rooms")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--write", type=Path, help="folder to write each map's room label PNG into")
    a = ap.parse_args()
    gts = sorted(a.dir.glob("*_gt_segmentation.png"))
    if not gts:
        raise SystemExit(f"no *_gt_segmentation.png in {a.dir}")
    ref = _reference_scorer(a.dir)
    if a.write:
        a.write.mkdir(parents=True, exist_ok=True)
    segment(read_grid(a.dir / f"{gts[0].name[: -len('_gt_segmentation.png')]}.yaml"))  # warm-up
    averages = {}
    all_agree = True
    for variant, label in (("", "plain"), ("_furnitures", "furnished")):
        print(f"\n{label} maps")
        print(
            f"{'map':28s} {'cells':>10s} {'GT':>4s} {'seg':>4s} {'recall':>7s} {'prec.':>7s} "
            f"{'topo_s':>7s} {'rooms_s':>7s} {'cpu_s':>6s} {'agree':>6s}"
        )
        rows = []
        for gt_path in gts:
            name = gt_path.name[: -len("_gt_segmentation.png")]
            yaml = a.dir / f"{name}{variant}.yaml"
            if not yaml.is_file():
                continue
            grid = read_grid(yaml)
            runs = [segment(grid) for _ in range(max(a.repeat, 1))]
            _topo, rooms, _, _, _ = runs[-1]
            t_topo = statistics.median(r[2] for r in runs)
            t_rooms = statistics.median(r[3] for r in runs)
            t_cpu = statistics.median(r[4] for r in runs)
            pred = np.flipud(rooms.labels)  # rows as the map image (and the GT image)
            gt_grey = cv2.imread(str(gt_path), cv2.IMREAD_GRAYSCALE)
            s = score_rooms(pred, gt_room_labels(gt_grey))
            agree = "-"
            if ref is not None:
                r = ref.score_segmentation(pred, ref.gt_room_labels(gt_grey))
                same = all(
                    abs(r[k] - getattr(s, k)) <= 1e-12
                    for k in ("recall", "precision", "recall_pixel", "precision_pixel")
                ) and (r["n_gt_rooms"], r["n_pred_segments"]) == (s.gt_rooms, s.segments)
                agree = "yes" if same else "NO"
                all_agree &= same
            if a.write:
                write_label_png(rooms.labels, a.write / f"{name}{variant}_rooms.png")
            rows.append((s.recall, s.precision, t_topo, t_rooms, t_cpu))
            print(
                f"{name + variant:28s} {grid.shape[1]:>4d}x{grid.shape[0]:<5d} {s.gt_rooms:4d} {s.segments:4d} "
                f"{100 * s.recall:7.1f} {100 * s.precision:7.1f} {t_topo:7.2f} {t_rooms:7.2f} {t_cpu:6.2f} "
                f"{agree:>6s}",
                flush=True,
            )
        rec = 100 * np.mean([r[0] for r in rows])
        prec = 100 * np.mean([r[1] for r in rows])
        tmax = max(r[2] + r[3] for r in rows)
        cmax = max(r[4] for r in rows)
        averages[label] = (rec, prec, tmax, len(rows), cmax)
        print(f"{'average (holoslam)':28s} {'':>10s} {'':>4s} {'':>4s} {rec:7.1f} {prec:7.1f}")
    print(
        "\naverages, recall / precision % (reported methods: the benchmark's 20 maps; holoslam: these maps)"
    )
    print(f"{'method':28s} {'plain':>14s} {'furnished':>14s} {'s per map':>10s}")
    for label, (plain, furn, t) in REPORTED.items():
        print(f"{label:28s} {plain[0]:6.1f} /{plain[1]:5.1f} {furn[0]:6.1f} /{furn[1]:5.1f} {t:10.1f}")
    p, f = averages.get("plain"), averages.get("furnished")
    if p and f:
        print(
            f"{'holoslam':28s} {p[0]:6.1f} /{p[1]:5.1f} {f[0]:6.1f} /{f[1]:5.1f} {max(p[2], f[2]):10.2f} "
            f"(slowest map, topology + rooms, wall; {max(p[4], f[4]):.2f} s CPU)"
        )
        vor = REPORTED["Voronoi"]
        ok = p[0] >= vor[0][0] and p[1] >= vor[0][1] and f[0] >= vor[1][0] and f[1] >= vor[1][1]
        print(
            f"at or above Voronoi on both: {'yes' if ok else 'no'}; under 2 s per map: wall "
            f"{'yes' if max(p[2], f[2]) < 2.0 else 'no'}, CPU {'yes' if max(p[4], f[4]) < 2.0 else 'no'}"
        )
    if ref is not None:
        print(f"holoslam's metric and score_rooms.py agree on every map: {'yes' if all_agree else 'NO'}")


if __name__ == "__main__":
    main()
