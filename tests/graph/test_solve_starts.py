"""The default start of ``holoslam solve`` (``Initialisation.AUTO``): LM from the chordal start, then from the
file's guess only when that solution disagrees with the measurements (the lower kept), the incremental start only
when the kept solution still disagrees; and the output says which starts ran, what each reached, which were not
run and why, and whether they agree.

MITb (808 poses, ``../shared/posegraph``) is the graph where LM from the file's guess stops in a local minimum
(E 385.12, where the optimum is 20.6035): the default must not."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from graph_worlds import square_loop
from repo_paths import SHARED

from holoslam import geometry as geo
from holoslam.cli import main
from holoslam.graph.build import BuildOptions
from holoslam.graph.initialise import chordal
from holoslam.graph.problem import LandmarkMeasurements, RelativePoseMeasurements, SlamProblem
from holoslam.jobs import solve_g2o_file
from holoslam.solve import Initialisation, SolveOptions, solve

gtsam = pytest.importorskip("gtsam")

POSEGRAPH = SHARED / "posegraph"
MITB = POSEGRAPH / "MITb.g2o"
MITB_OPTIMUM, MITB_TRAP = 20.6035, 385.122

PLAIN = SolveOptions(
    reject_outliers=False, detect_moved=False, final_gaussian=False, build=BuildOptions().without_kernels()
)


def _mitb() -> Path:
    if not MITB.is_file():
        pytest.skip(f"the shared pose graphs are not here ({POSEGRAPH})")
    return MITB


def _exact_problem(wTa: np.ndarray, guess: np.ndarray, pairs: list[tuple[int, int]]) -> SlamProblem:
    i, j = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    cov = np.tile(np.diag([0.01, 0.02, 0.001]), (len(pairs), 1, 1))
    rel = RelativePoseMeasurements(i, j, geo.between(wTa[i], wTa[j]), cov, "g2o")
    return SlamProblem(len(wTa), rel, initial_wTa=guess)


# ------------------------------------------------------------------------------------------ chordal start


def test_chordal_start_is_exact_on_noise_free_measurements():
    """Two laps of a square with loop closures, a guess whose headings are wrong by up to 2.5 rad: the chordal
    start recovers every pose (anchor 0 kept where the guess puts it)."""
    truth = square_loop(n_side=5)
    n = len(truth)
    rng = np.random.default_rng(1)
    guess = truth.copy()
    guess[1:, 2] = geo.wrap(guess[1:, 2] + rng.uniform(-2.5, 2.5, n - 1))
    guess[1:, :2] += rng.normal(0.0, 3.0, (n - 1, 2))
    pairs = [(k, k + 1) for k in range(n - 1)] + [(k, k + n // 2) for k in range(0, n // 2, 3)]
    wTa, landmarks = chordal(_exact_problem(truth, guess, pairs))
    assert landmarks == {}
    assert np.abs(wTa[:, :2] - truth[:, :2]).max() < 1e-6
    assert np.abs(geo.wrap(wTa[:, 2] - truth[:, 2])).max() < 1e-8


def test_chordal_start_pins_each_unconnected_part_at_its_guess():
    """Two chains that no measurement joins, and a pose seen only by a landmark sighting: each part keeps its
    first pose's guess and is exact inside; nothing raises."""
    truth = square_loop(n_side=3)[:10]
    guess = truth + np.array([0.5, -0.5, 0.3])
    pairs = [(k, k + 1) for k in range(4)] + [(k, k + 1) for k in range(5, 8)]  # 0-4, 5-8; 9 alone
    problem = _exact_problem(truth, guess, pairs)
    sight = LandmarkMeasurements(
        np.array([9, 8]), ("L", "L"), np.array([[1.0, 0.0], [2.0, 0.5]]), np.tile(np.eye(2) * 0.01, (2, 1, 1))
    )
    problem = replace(problem, landmarks=sight)
    wTa, landmarks = chordal(problem)
    assert np.allclose(wTa[0], guess[0]) and np.allclose(wTa[5, 2], guess[5, 2])
    for a, b in pairs:
        assert np.allclose(geo.between(wTa[a], wTa[b]), geo.between(truth[a], truth[b]), atol=1e-8)
    assert set(landmarks) == {"L"} and np.all(np.isfinite(wTa))


def _trapped_square() -> SlamProblem:
    """A square with loop closures, exact measurements (optimum 0) and a guess whose headings are flipped: LM
    from the guess stops in a local minimum."""
    truth = square_loop(n_side=6)
    n = len(truth)
    rng = np.random.default_rng(0)
    bad = truth.copy()
    bad[1:, 2] = geo.wrap(bad[1:, 2] + rng.choice([-2.5, 2.5], n - 1))
    pairs = [(k, k + 1) for k in range(n - 1)] + [(k, k + n // 2) for k in range(0, n // 2, 2)]
    return _exact_problem(truth, bad, pairs)


AUTO = replace(PLAIN, initialisation=Initialisation.AUTO)
FILE_FIRST = replace(AUTO, auto_candidates=(Initialisation.PROBLEM, Initialisation.CHORDAL))


def test_auto_keeps_the_chordal_solution_when_the_file_guess_traps_lm():
    """Every candidate run (auto_enough_when_fits off), the file's guess first: LM from it stops in a local
    minimum, LM from the chordal start reaches the truth; the report says the starts disagree and which was
    kept."""
    problem = _trapped_square()
    file_only = solve(problem, PLAIN)
    auto = solve(problem, replace(FILE_FIRST, auto_enough_when_fits=False))
    assert file_only.final_error > 1.0  # trapped (the measurements are exact: the optimum is 0)
    assert auto.final_error < 1e-9 and auto.initialisation is Initialisation.CHORDAL
    report = auto.starts
    assert report is not None and report.agree is False and report.kept is Initialisation.CHORDAL
    got = {o.initialisation: o for o in report.outcomes}
    assert got[Initialisation.PROBLEM].final_error == pytest.approx(file_only.final_error, rel=1e-9)
    assert got[Initialisation.PROBLEM].max_dxy > 0.1 and got[Initialisation.CHORDAL].max_dxy == 0.0
    assert report.fits and not report.fallback_ran and report.skipped == ()


def test_default_auto_runs_the_chordal_start_first_and_stops_when_it_fits():
    """The default: the chordal start first; its solution explains the measurements (none beyond the chi-square
    bound), so the file's guess is not solved, and the report says why."""
    auto = solve(_trapped_square(), AUTO)
    report = auto.starts
    assert auto.final_error < 1e-9 and report is not None and report.kept is Initialisation.CHORDAL
    assert [o.initialisation for o in report.outcomes] == [Initialisation.CHORDAL]
    assert report.agree is None and report.beyond == 0 and report.fits and not report.fallback_ran
    ((skipped, why),) = report.skipped
    assert skipped is Initialisation.PROBLEM
    assert why.startswith("the chordal start's solution already fits the measurements: 0 of ")
    assert "at most 5 allowed" in why


def test_a_later_start_runs_when_the_first_solution_does_not_fit():
    """The file's guess first: its local minimum leaves measurements beyond the chi-square bound, so the chordal
    start runs (and is kept); from a good guess the file's solution fits and the chordal start is not solved."""
    problem = _trapped_square()
    auto = solve(problem, FILE_FIRST)
    report = auto.starts
    assert report is not None and [o.initialisation for o in report.outcomes] == [
        Initialisation.PROBLEM,
        Initialisation.CHORDAL,
    ]
    assert report.kept is Initialisation.CHORDAL and auto.final_error < 1e-9 and report.skipped == ()
    assert solve(problem, PLAIN).final_error > 1.0  # the file's guess alone: trapped
    good = replace(problem, initial_wTa=square_loop(n_side=6))
    report = solve(good, FILE_FIRST).starts
    assert report is not None and [o.initialisation for o in report.outcomes] == [Initialisation.PROBLEM]
    assert [c for c, _ in report.skipped] == [Initialisation.CHORDAL] and report.fits


def test_default_auto_starts_from_a_guess_that_already_fits():
    """The default with a guess that already fits the measurements (before any solve): LM from it, first, and the
    chordal start is not built; the trapped square's guess does not fit, so there the chordal start goes first."""
    good = replace(_trapped_square(), initial_wTa=square_loop(n_side=6))
    auto = solve(good, AUTO)
    report = auto.starts
    assert report is not None and [o.initialisation for o in report.outcomes] == [Initialisation.PROBLEM]
    assert [c for c, _ in report.skipped] == [Initialisation.CHORDAL] and report.fits
    assert auto.final_error < 1e-9
    trapped = solve(_trapped_square(), AUTO).starts
    assert trapped is not None and trapped.outcomes[0].initialisation is Initialisation.CHORDAL


# ---------------------------------------------------------------------------------------------- MITb


def test_default_solve_of_mitb_reaches_the_global_optimum(tmp_path):
    """The library default (AUTO) on MITb: the optimum 20.6035, not the local minimum 385.12 where LM from the
    file's guess stops; the optimised file reads back with gtsam at the optimum."""
    out = tmp_path / "mitb.g2o"
    summary, sol = solve_g2o_file(_mitb(), out)
    assert sol.final_error == pytest.approx(MITB_OPTIMUM, rel=1e-5)
    assert summary.initialisation == "chordal"
    trap, _ = solve_g2o_file(_mitb(), initialisation="problem")
    assert trap.final_error == pytest.approx(MITB_TRAP, rel=1e-5)  # the trap is measured, not assumed
    both, _ = solve_g2o_file(_mitb(), options=replace(AUTO, auto_enough_when_fits=False))
    assert dict(both.candidates)["problem"] == pytest.approx(MITB_TRAP, rel=1e-5)
    assert both.final_error == pytest.approx(MITB_OPTIMUM, rel=1e-5) and both.initialisation == "chordal"
    graph, values = gtsam.readG2o(str(out))
    first = min(values.keys())
    graph.add(gtsam.PriorFactorPose2(first, values.atPose2(first), gtsam.noiseModel.Isotropic.Sigma(3, 1e-4)))
    assert graph.error(values) == pytest.approx(MITB_OPTIMUM, rel=1e-5)


def test_holoslam_solve_says_which_starts_ran_and_why_the_file_start_did_not_on_mitb(tmp_path, capsys):
    src = _mitb()
    assert main(["solve", str(src), "-o", str(tmp_path / "o.g2o")]) == 0
    text = capsys.readouterr().out
    assert "initialisation: chordal" in text
    assert "  chordal: E 20.6035 " in text and ", kept" in text
    assert "  file: not solved (the chordal start's solution already fits the measurements: 1 of 827 " in text
    assert "starts_agree: only one start ran (above: why the others did not)" in text
    assert "incremental: not run, the kept solution fits the measurements" in text
    assert main(["solve", str(src), "-o", str(tmp_path / "o.g2o"), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["final_error"] == pytest.approx(MITB_OPTIMUM, rel=1e-5)
    assert [s["start"] for s in d["starts"]] == ["chordal"]
    assert [s[0] for s in d["starts_skipped"]] == ["file"]
    assert d["beyond_chi2"] == 1 and d["beyond_limit"] == 5
    assert d["starts_agree"] is None and d["fallback"] == "incremental" and d["fallback_ran"] is False


def test_the_starts_agree_when_every_candidate_runs(tmp_path):
    """The gtsam wheel's w100.graph with every candidate run: both starts reach one solution (the file start's
    LM stops when it gets to the chordal start's); the summary says so."""
    src = gtsam.findExampleDataFile("w100.graph")
    summary, _ = solve_g2o_file(src, options=replace(AUTO, auto_enough_when_fits=False))
    d = summary.to_dict()
    assert d["starts_agree"] is True and d["initialisation"] == "chordal"
    assert [s["start"] for s in d["starts"]] == ["chordal", "file"]
    assert d["starts"][1]["reached"] == "chordal"


def test_explicit_start_has_no_starts_report(tmp_path, capsys):
    src = gtsam.findExampleDataFile("w100.graph")
    assert main(["solve", src, "-o", str(tmp_path / "o.g2o"), "--init", "file", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["initialisation"] == "file" and "starts" not in d
    assert main(["solve", src, "-o", str(tmp_path / "o.g2o"), "--init", "chordal", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["initialisation"] == "chordal"


# ------------------------------------------------------------------------------------------ written file


def test_written_graph_copies_the_edge_lines_it_read(tmp_path):
    """EDGE_SE2 lines are written as they were read (no information matrix inverted twice); the vertices carry
    the optimised poses."""
    src = tmp_path / "in.g2o"
    edges = [
        "EDGE_SE2 0 1 1 0 1.5708 100 0 0 100 0 400",
        "EDGE_SE2 1 2 1 0 1.5708 100 1e-3 0 100 0 400",
        "EDGE_SE2 2 3 1 0 1.5708 100 0 0 100 0 400",
        "EDGE_SE2 3 0 1 0 1.5708 100 0 0 100 0 400",
    ]
    src.write_text(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1.1 0.1 1.5\nVERTEX_SE2 2 1.0 1.2 3.0\nVERTEX_SE2 3 -0.1 0.9 -1.6\n"
        + "\n".join(edges)
        + "\n"
    )
    _, sol = solve_g2o_file(src, tmp_path / "out.g2o")
    lines = (tmp_path / "out.g2o").read_text().splitlines()
    assert [ln for ln in lines if ln.startswith("EDGE_SE2")] == edges
    assert lines[1].startswith("VERTEX_SE2 1 ") and np.allclose(
        [float(v) for v in lines[1].split()[2:]], sol.wTa[1]
    )
