"""What a solve is asked to do: the method, the start, the outlier scheme and the covariances (numpy-free records).

``holoslam.solve`` re-exports every name here; they live apart so that the solver's parts (``graph.isam2``,
``graph.outliers``, ``graph.initialise``) can read the options without importing the solver.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum

from holoslam.choices import Initialisation, Method
from holoslam.graph.build import FAMILY_CODES, BuildOptions
from holoslam.graph.problem import MeasurementFamily

__all__ = [
    "IterationHook",
    "Method",
    "Initialisation",
    "Factorization",
    "CovarianceScope",
    "SolveOptions",
    "REL",
    "HEAD",
    "LMK",
    "DOF",
]

IterationHook = Callable[[int, float, float], None]
"""Called after each optimiser iteration (LM) or update (iSAM2) with (iteration, error_before, error_after)."""

REL, HEAD, LMK = (
    FAMILY_CODES[f]
    for f in (MeasurementFamily.RELATIVE, MeasurementFamily.HEADING, MeasurementFamily.LANDMARK)
)
DOF = {REL: 3, HEAD: 1, LMK: 2}  # dimension of one measurement of each family


class Factorization(str, Enum):
    QR = "qr"
    CHOLESKY = "cholesky"


class CovarianceScope(str, Enum):
    NONE = "none"
    ANCHORS = "anchors"
    LANDMARKS = "landmarks"
    ALL = "all"


@dataclass(frozen=True, slots=True)
class SolveOptions:
    method: Method = Method.BATCH
    initialisation: Initialisation = Initialisation.PROBLEM
    build: BuildOptions = BuildOptions()
    fix_first: bool = True  # add a tight prior on anchor 0 when the problem has none
    max_iterations: int = 100
    relative_error_tol: float = 1e-5
    absolute_error_tol: float = 1e-5
    isam2_factorization: Factorization = Factorization.QR
    isam2_relinearize_threshold: float = 0.1
    isam2_relinearize_skip: int = 10  # gtsam default; 2x faster than 1 on Victoria Park, same optimum
    isam2_extra_updates: int = 0  # updates without new factors after the last anchor (relinearise, converge)
    isam2_final_lm_iterations: int = 0  # Method.ISAM2: LM iterations that polish the iSAM2 estimate
    reject_outliers: bool = True
    chi2_probability: float = 0.9999  # a measurement is an outlier beyond this chi2 quantile of its dimension
    max_rounds: int = 4
    final_gaussian: bool = True
    detect_moved: bool = True
    min_moved_sightings: int = 2
    min_move_distance: float = 0.25  # m
    covariances: CovarianceScope = CovarianceScope.NONE
    covariance_anchors: tuple[int, ...] | None = None  # None: all anchors (when covariances asks for anchors)
    # Initialisation.AUTO: solve from each of these starts (a start equal to an earlier one, or that fails, is
    # skipped) and keep the solution with the lowest final error (ties: the earlier candidate). A later start
    # whose LM reaches an earlier start's solution (same error and poses to the tolerances below) stops there.
    # The chordal start comes first: LM from it reached the known optimum on every graph of ../shared/posegraph
    # and w10000 (in 2-7 iterations where LM from the file's guess took 2-18), while LM from the file's guess
    # stopped in a local minimum on MITb (385.12 vs 20.6035) and ais2klinik (86.6012 vs 86.4071). A pose graph
    # whose own guess already fits the measurements (the test below, before any solve: intel 4 of 2512 beyond,
    # FRH 0, intel_g2o943 5; MITb 19 of 827, ais2klinik 94 of 16,727 do not) starts from it instead
    # (``starts._order``): LM from it reaches the same optimum, and the chordal start is not built.
    auto_candidates: tuple[Initialisation, ...] = (Initialisation.CHORDAL, Initialisation.PROBLEM)
    # ... and a later candidate runs only when the best solution so far does not fit the measurements (the test
    # of ``auto_fallback_beyond`` below); False: every candidate runs. Measured on the 12 graphs above: the
    # chordal start's solution fits on every one (0-1 measurements beyond the bound, at most 5-128 allowed),
    # MITb's local minimum from the file's guess does not (7 of 827 beyond, 5 allowed). A fitting local minimum
    # (ais2klinik's 86.6012 from the file's guess leaves 0 beyond) is why the chordal start goes first.
    auto_enough_when_fits: bool = True
    # ... then ``auto_fallback`` runs only when the best solution disagrees with the measurements: more than
    # ``auto_fallback_beyond`` of them (and at least 5) beyond the chi2_probability quantile. A consistent
    # solution leaves 1 - chi2_probability (0.01 %) there; LM stuck in a local minimum leaves 0.8-64 %.
    auto_fallback: Initialisation | None = Initialisation.INCREMENTAL
    auto_fallback_beyond: float = 0.002
    # two starts agree when their final errors differ by at most this fraction; a later start's LM stops on
    # reaching an earlier start's solution when its error is within LM's relative tolerance of it and its poses
    # within ``auto_agree_xy`` metres / ``auto_agree_theta`` radians (LM's stopping rule, a relative error change
    # below 1e-5, leaves one minimum's poses centimetres apart on 10k-pose graphs: city10000 1.5 cm, M3500 9 cm
    # after the iteration that reaches the other start's error to 1e-7; different minima are metres apart)
    auto_agree_error: float = 1e-4
    auto_agree_xy: float = 0.1
    auto_agree_theta: float = 0.01
