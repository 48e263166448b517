"""Optimise standard 2D pose graphs with holoslam and with a direct gtsam call, in the same process.

For each file: poses, factors, LM iterations, initial and final error, the median time of holoslam's whole path
(read, build, solve: ``holoslam.solve.solve_g2o_file``) next to gtsam's (``readG2o`` / ``load2D`` +
``LevenbergMarquardtOptimizer``, with the same prior on the first pose), their ratio (goal <= 1.2) and the relative
difference of their final errors (goal <= 1e-6). Times are process CPU times (``time.process_time``: the machine is
shared, wall time measures the neighbours), both paths including the freeing of their gtsam objects. A second
table runs ``Initialisation.AUTO`` (LM from the file's guess, the odometry chain, LAGO and an incremental iSAM2
pass; the lowest final error wins) and shows each start's final error. A third table runs an incremental iSAM2
pass over the landmark graphs (the wheel's Victoria Park; iSAM's victoriaPark and cityTrees10000 read as
information) against LM from the odometry chain and batch LM run to convergence from the iSAM2 estimate.

    python benchmarks/bench_posegraph.py [--quick] [--repeats 3] [--files intel,CSAIL]

Data: the gtsam wheel's ``victoria_park.txt`` and ``w10000.graph``, and the files in ``$HOLOSLAM_POSEGRAPH_DIR``
(default ``../shared/posegraph`` relative to the repository) when present.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from dataclasses import replace
from pathlib import Path

import gtsam
import numpy as np

from holoslam.solve import Initialisation, Method, SolveOptions, solve, solve_g2o_file

REPO = Path(__file__).resolve().parents[1]
BIG = 5000  # poses: --quick skips files at least this big


def datasets() -> list[tuple[str, Path, str]]:
    """(name, path, gtsam reader) of every file present."""
    out = [
        ("victoria_park (wheel)", Path(gtsam.findExampleDataFile("victoria_park.txt")), "load2D"),
        ("w10000 (wheel)", Path(gtsam.findExampleDataFile("w10000.graph")), "load2D"),
    ]
    folder = Path(os.environ.get("HOLOSLAM_POSEGRAPH_DIR", REPO.parent / "shared" / "posegraph"))
    for name in (
        "intel",
        "CSAIL",
        "MITb",
        "FR079",
        "FRH",
        "M3500",
        "manhattan",
        "intel_g2o943",
        "manhattanOlson3500",
        "city10000",
        "ais2klinik",
    ):
        p = folder / f"{name}.g2o"
        if p.exists():
            out.append((name, p, "readG2o"))
    return out


def count_poses(path: Path) -> int:
    ids = set()
    with open(path) as f:
        for line in f:
            parts = line.split()
            if parts and parts[0] in ("VERTEX_SE2", "VERTEX2", "EDGE_SE2", "EDGE2", "ODOMETRY"):
                ids.add(int(parts[1]))
                if parts[0] not in ("VERTEX_SE2", "VERTEX2"):
                    ids.add(int(parts[2]))
    return len(ids)


def gtsam_direct(path: Path, reader: str) -> tuple[float, float, int, int]:
    """readG2o / load2D + LM with a prior on the first pose; returns (seconds, final error, iterations, factors)."""
    t0 = time.process_time()
    if reader == "readG2o":
        graph, values = gtsam.readG2o(str(path))
    else:
        graph, values = gtsam.load2D(str(path))
    first = min(k for k in values.keys() if gtsam.Symbol(k).chr() == 0)
    graph.add(
        gtsam.PriorFactorPose2(
            first, values.atPose2(first), gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-4, 1e-4, 1e-5]))
        )
    )
    opt = gtsam.LevenbergMarquardtOptimizer(graph, values, gtsam.LevenbergMarquardtParams())
    result = opt.optimize()
    error, iterations, size = graph.error(result), opt.iterations(), graph.size()
    del graph, values, opt, result  # freeing the C++ objects is part of either path (holoslam's frees inside)
    return time.process_time() - t0, error, iterations, size


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help=f"skip files with {BIG} poses or more")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--files", default="", help="comma-separated subset of names")
    ap.add_argument("--no-init", action="store_true", help="skip the initialisation comparison")
    args = ap.parse_args()

    files = datasets()
    if args.files:
        want = set(args.files.split(","))
        files = [f for f in files if f[0].split(" ")[0] in want]
    if args.quick:
        files = [f for f in files if count_poses(f[1]) < BIG]

    print(
        "## holoslam vs direct gtsam (batch LM from the file's initial guess, first pose fixed), "
        f"median of {args.repeats}"
    )
    hdr = (
        f"{'file':24s} {'poses':>6s} {'factors':>7s} {'iters':>5s} {'initial E':>12s} {'final E':>12s} "
        f"{'gtsam E':>12s} {'rel diff':>9s} {'holoslam s':>10s} {'gtsam s':>8s} {'ratio':>6s}"
    )
    print(hdr)
    print("-" * len(hdr))
    summaries = {}
    for name, path, reader in files:
        ours, theirs = [], []
        for _ in range(args.repeats):
            t0 = time.process_time()
            summary, _sol = solve_g2o_file(path)
            ours.append(time.process_time() - t0)
            t, e_g, it_g, nf = gtsam_direct(path, reader)
            theirs.append(t)
        summaries[name] = (path, summary)
        to, tg = statistics.median(ours), statistics.median(theirs)
        rel = abs(summary.final_error - e_g) / max(abs(e_g), 1e-300)
        print(
            f"{name:24s} {summary.num_poses:6d} {nf:7d} {summary.iterations:5d} {summary.initial_error:12.6g} "
            f"{summary.final_error:12.6g} {e_g:12.6g} {rel:9.1e} {to:10.3f} {tg:8.3f} {to / tg:6.2f}"
        )

    if args.no_init:
        return
    print()
    print(
        "## Initialisation.AUTO: final error of LM from each start; AUTO keeps the lowest (the global optimum)"
    )
    inits = (Initialisation.PROBLEM, Initialisation.ODOMETRY, Initialisation.LAGO, Initialisation.INCREMENTAL)
    hdr = (
        f"{'file':24s} "
        + " ".join(f"{i.value:>14s}" for i in inits)
        + f" {'AUTO picks':>12s} {'AUTO E':>12s} {'AUTO cpu s':>10s} {'file guess best?':>17s}"
    )
    print(hdr)
    print("-" * len(hdr))
    for name, (path, _) in summaries.items():
        t0 = time.process_time()
        s_auto, sol = solve_g2o_file(path, initialisation=Initialisation.AUTO)
        dt = time.process_time() - t0
        got = dict(sol.candidates)
        cells = []
        for init in inits:
            if init in got:
                cells.append(f"{got[init]:14.6g}")
            elif init is Initialisation.ODOMETRY:
                cells.append(f"{'(= guess)':>14s}")
            elif init is Initialisation.LAGO:  # not run: an earlier start satisfies every edge (no loops)
                cells.append(f"{'(= chain)':>14s}")
            else:
                cells.append(f"{'-':>14s}")
        e_guess = got.get(Initialisation.PROBLEM, float("nan"))
        ok = abs(e_guess - s_auto.final_error) <= 1e-6 * s_auto.final_error
        print(
            f"{name:24s} "
            + " ".join(cells)
            + f" {sol.initialisation.value:>12s} {s_auto.final_error:12.6g} {dt:10.2f} {'yes' if ok else 'no':>17s}"
        )

    landmark_graphs(summaries, args.files)


def landmark_graphs(summaries: dict, wanted: str) -> None:
    """Incremental iSAM2 (+2 LM iterations) on the landmark graphs, against batch LM from the odometry chain (the
    trap) and batch LM run to convergence from the iSAM2 estimate. The wheel's victoria_park.txt stores
    covariances (gtsam's reading); iSAM's victoriaPark.txt and cityTrees10000.txt are read as information, the
    convention SPEC §7's 204.05 and 285.00 were measured with (and SLAM++'s)."""
    from holoslam.graph.problem import problem_from_g2o
    from holoslam.io.g2o import TextNoise, read_g2o

    folder = Path(os.environ.get("HOLOSLAM_POSEGRAPH_DIR", REPO.parent / "shared" / "posegraph"))
    graphs = [
        (name, path, TextNoise.GTSAM_AUTO)
        for name, (path, _) in summaries.items()
        if name.startswith("victoria")
    ]
    for name in ("victoriaPark", "cityTrees10000"):
        if (folder / f"{name}.txt").exists() and (not wanted or name in wanted.split(",")):
            graphs.append((f"{name} (iSAM, info)", folder / f"{name}.txt", TextNoise.INFORMATION))
    if not graphs:
        return
    print()
    print(
        "## incremental iSAM2 on landmark graphs (QR, relinearise 0.1 every 10th update, new poses from the current "
        "estimate, new landmarks from their first sighting) + 2 LM iterations, vs LM from the odometry chain and "
        "batch LM to convergence from the iSAM2 estimate (CPU s)"
    )
    hdr = (
        f"{'file':28s} {'LM from chain':>14s} {'s':>6s} {'iSAM2+2LM E':>14s} {'s':>6s} {'LM from it E':>14s} "
        f"{'s':>6s} {'max |dxy| m':>11s} {'rel diff':>9s}"
    )
    print(hdr)
    print("-" * len(hdr))
    base = SolveOptions(reject_outliers=False, detect_moved=False, final_gaussian=False)
    base = replace(base, build=base.build.without_kernels())
    for name, path, noise in graphs:
        problem = problem_from_g2o(read_g2o(path, noise=noise))
        t0 = time.process_time()
        chain = solve(problem, base)
        t1 = time.process_time()
        inc = solve(problem, replace(base, method=Method.ISAM2, isam2_final_lm_iterations=2))
        t2 = time.process_time()
        start = replace(
            problem,
            initial_wTa=inc.wTa,
            initial_landmarks=dict(zip(inc.landmark_ids, inc.w_landmarks, strict=True)),
        )
        bat = solve(start, base)
        t3 = time.process_time()
        dxy = np.abs(inc.wTa[:, :2] - bat.wTa[:, :2]).max()
        rel = abs(inc.final_error - bat.final_error) / bat.final_error
        print(
            f"{name:28s} {chain.final_error:14.8g} {t1 - t0:6.1f} {inc.final_error:14.8g} {t2 - t1:6.1f} "
            f"{bat.final_error:14.8g} {t3 - t2:6.1f} {dxy:11.3g} {rel:9.1e}"
        )


if __name__ == "__main__":
    main()
