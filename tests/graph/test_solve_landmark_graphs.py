"""Incremental start on a real landmark graph: the first 4000 lines of the gtsam wheel's Victoria Park
(2524 poses, bearing/range tree sightings). Batch LM from the odometry chain stops in a local minimum there
(E 2093.0); an iSAM2 pass that initialises each new pose from the current estimate reaches 991.16. holoslam's
``Method.ISAM2`` and ``Initialisation.AUTO`` must land where a direct gtsam incremental loop lands."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from holoslam.graph.build import BuildOptions
from holoslam.graph.problem import problem_from_g2o
from holoslam.io.g2o import read_g2o
from holoslam.solve import Initialisation, Method, SolveOptions, solve

gtsam = pytest.importorskip("gtsam")

LINES = 4000


@pytest.fixture(scope="module")
def vp_head(tmp_path_factory: pytest.TempPathFactory) -> Path:
    src = Path(gtsam.findExampleDataFile("victoria_park.txt"))
    out = tmp_path_factory.mktemp("vp") / "victoria_park_head.txt"
    out.write_text("\n".join(src.read_text().splitlines()[:LINES]) + "\n")
    return out


def _direct_incremental(path: Path) -> tuple[float, float]:
    """gtsam alone: load2D + the prior holoslam adds on the first pose; (E of LM from load2D's guess, E of an iSAM2
    pass fed pose by pose with every factor whose latest pose it is, then 2 LM iterations)."""
    graph, init = gtsam.load2D(str(path))
    poses = sorted(k for k in init.keys() if gtsam.Symbol(k).chr() == 0)
    sigmas = gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-4, 1e-4, 1e-5]))
    graph.add(gtsam.PriorFactorPose2(poses[0], init.atPose2(poses[0]), sigmas))
    e_lm = graph.error(gtsam.LevenbergMarquardtOptimizer(graph, init).optimize())

    rank = {k: r for r, k in enumerate(poses)}
    groups: list[list] = [[] for _ in poses]
    for f in range(graph.size()):
        keys = graph.at(f).keys()
        groups[max(rank[k] for k in keys if k in rank)].append(graph.at(f))
    params = gtsam.ISAM2Params()
    params.setFactorization("QR")
    isam = gtsam.ISAM2(params)
    est: dict[int, object] = {poses[0]: init.atPose2(poses[0])}
    seen: set[int] = set()
    for r, k in enumerate(poses):
        factors, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        if r:
            odo = next(f for f in groups[r] if isinstance(f, gtsam.BetweenFactorPose2))
            est[k] = est[odo.keys()[0]].compose(odo.measured())
        values.insert(k, est[k])
        for f in groups[r]:
            factors.push_back(f)
            if isinstance(f, gtsam.BearingRangeFactor2D) and f.keys()[1] not in seen:
                seen.add(f.keys()[1])
                m = f.measured()
                b, rng = m.bearing().theta(), m.range()
                values.insert(f.keys()[1], est[k].transformFrom(np.array([rng * np.cos(b), rng * np.sin(b)])))
        isam.update(factors, values)
        est[k] = isam.calculateEstimatePose2(k)
    lm = gtsam.LevenbergMarquardtParams()
    lm.setMaxIterations(2)
    polished = gtsam.LevenbergMarquardtOptimizer(graph, isam.calculateEstimate(), lm).optimize()
    return float(e_lm), float(graph.error(polished))


@pytest.fixture(scope="module")
def reference(vp_head: Path) -> tuple[float, float]:
    return _direct_incremental(vp_head)


def _options() -> SolveOptions:
    return SolveOptions(
        reject_outliers=False,
        detect_moved=False,
        final_gaussian=False,
        build=BuildOptions().without_kernels(),
    )


def test_direct_reference_shows_the_trap(reference: tuple[float, float]) -> None:
    e_lm, e_inc = reference
    assert e_inc < 0.6 * e_lm  # otherwise the graph does not test the incremental start


def test_isam2_matches_direct_gtsam(vp_head: Path, reference: tuple[float, float]) -> None:
    problem = problem_from_g2o(read_g2o(vp_head))
    sol = solve(problem, replace(_options(), method=Method.ISAM2, isam2_final_lm_iterations=2))
    assert sol.final_error == pytest.approx(reference[1], rel=1e-6)


def test_auto_reaches_the_incremental_optimum(vp_head: Path, reference: tuple[float, float]) -> None:
    """AUTO's chordal start (rotations from the odometry tree, positions and landmarks from one linear solve over
    every sighting) lands where the incremental start lands; LM from the file's chain is trapped."""
    e_lm, e_inc = reference
    problem = problem_from_g2o(read_g2o(vp_head))
    sol = solve(problem, replace(_options(), initialisation=Initialisation.AUTO))
    assert sol.initialisation is Initialisation.CHORDAL
    assert sol.final_error == pytest.approx(e_inc, rel=1e-6)
    assert sol.starts is not None and sol.starts.fits
    # the chordal solution explains the sightings: neither the file's chain nor the incremental pass runs
    assert [c for c, _why in sol.starts.skipped] == [Initialisation.PROBLEM] and not sol.starts.fallback_ran
    both = solve(
        problem, replace(_options(), initialisation=Initialisation.AUTO, auto_enough_when_fits=False)
    )
    got = dict(both.candidates)
    assert got[Initialisation.PROBLEM] == pytest.approx(e_lm, rel=1e-6)  # LM from the file's chain: trapped
    assert (
        both.starts is not None
        and both.starts.agree is False
        and both.initialisation is Initialisation.CHORDAL
    )


def test_auto_runs_the_incremental_start_when_the_best_does_not_fit(
    vp_head: Path, reference: tuple[float, float]
) -> None:
    """With the file's chain as the only candidate, LM is trapped (0.8 % of the measurements beyond the 99.99 %
    chi-square bound, where 0.01 % is expected): the incremental start runs and is kept."""
    e_lm, e_inc = reference
    problem = problem_from_g2o(read_g2o(vp_head))
    opts = replace(_options(), initialisation=Initialisation.AUTO, auto_candidates=(Initialisation.PROBLEM,))
    sol = solve(problem, opts)
    got = dict(sol.candidates)
    assert sol.starts is not None and sol.starts.fallback_ran and sol.starts.fits
    assert sol.initialisation is Initialisation.INCREMENTAL
    assert sol.final_error == pytest.approx(e_inc, rel=1e-6)
    assert got[Initialisation.PROBLEM] == pytest.approx(e_lm, rel=1e-6)
    # the odometry tree has no loops: the chain satisfies every odometry measurement, LAGO would return it
    both = (Initialisation.PROBLEM, Initialisation.LAGO)
    lago = solve(problem, replace(opts, auto_candidates=both, auto_fallback=None))
    assert Initialisation.LAGO not in dict(lago.candidates)
    assert [c for c, _why in lago.starts.skipped] == [Initialisation.LAGO]
