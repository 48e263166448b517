"""The run's optimisation settings: solver options from the run configuration's ``solver`` section, the robust
kernels of a run, and the front end's re-estimate of the anchors after loop closures."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from holoslam.config import SolverConfig
    from holoslam.graph.build import BuildOptions
    from holoslam.graph.nodes import KeyframeSolve
    from holoslam.solve import SolveOptions
    from holoslam.submaps.odometer import OdometerCorrection

__all__ = ["solve_options", "run_build_options", "reestimate_anchors", "revisit_nodes", "keyframe_anchors", "map_log",
           "map_log_keyframes", "odometer_pass", "single_pass"]


def solve_options(cfg: SolverConfig) -> SolveOptions:
    """The final solve's options from the run configuration's ``solver`` section, with the run's kernels."""
    from holoslam.solve import CovarianceScope, SolveOptions

    return SolveOptions(
        method=cfg.method,
        reject_outliers=cfg.reject_outliers,
        chi2_probability=cfg.chi2_probability,
        covariances=CovarianceScope.ALL if cfg.covariances else CovarianceScope.NONE,
        max_iterations=cfg.max_iterations,
        isam2_relinearize_threshold=cfg.isam2_relinearize_threshold,
        build=run_build_options(),
    )


def reestimate_anchors(problem: Any) -> np.ndarray:
    """The front end's re-estimate after loop closures: the anchors' poses from the relative poses found so
    far, loops under the robust kernel, one plain solve (no outlier rounds: the final solve does those)."""
    from holoslam.solve import SolveOptions, solve

    opts = SolveOptions(reject_outliers=True, max_rounds=0, final_gaussian=False, detect_moved=False,
                        max_iterations=50, build=run_build_options())
    return solve(problem, opts).wTa


def run_build_options() -> BuildOptions:
    """Robust kernels of a run: loops under Huber (3 sigma), not DCS. On real logs the chain of scan matches is
    less certain than its covariances say, and DCS (redescending) drops the very closures that correct it;
    Huber keeps their pull linear beyond 3 sigma (Cartographer uses Huber on loops for the same reason). The
    chi-square rounds of the final solve remove what is still inconsistent."""
    from holoslam.graph import factors as fac
    from holoslam.graph.build import BuildOptions

    return BuildOptions(loop_kernel=fac.Kernel(fac.RobustKernel.HUBER, 3.0))


def revisit_nodes(fe: Any, sol: Any, cfg: Any, progress: Any = None) -> KeyframeSolve | None:
    """The keyframes matched into the old submaps they revisit and solved as poses beside the anchors
    (``holoslam.submaps.revisits``, ``holoslam.graph.nodes``), with the front end's settings ``cfg``:
    a ``KeyframeSolve`` for the trajectory, the map and the report, or None when
    ``cfg.revisits.enabled`` is off or the run has no keyframes."""
    from holoslam.graph.nodes import KeyframeSolve, solve_nodes
    from holoslam.submaps.revisits import graph_nodes, match_nodes

    if not cfg.revisits.enabled:
        return None
    nodes = graph_nodes(fe.submaps)
    if not len(nodes):
        return None
    from dataclasses import replace

    rcfg = replace(cfg.revisits, min_score=cfg.revisits.min_score * fe.score_scale)  # a sparse laser's scores
    matches = match_nodes(fe.submaps, nodes, sol.wTa, rcfg, cfg.local.match, progress)
    return KeyframeSolve(nodes, matches, solve_nodes(nodes, matches, sol.wTa, sol.cov_wTa, cfg.revisits))


def keyframe_anchors(sol: Any, anchor_stamps_ns: np.ndarray, revisits: KeyframeSolve | None) -> Any:
    """``sol`` with each anchor's pose taken from the keyframe solve (``revisit_nodes``): an anchor is the robot's
    pose at its stamp, a keyframe of the submap before it, and the keyframe solve holds every scan's evidence where
    the anchor solve holds each submap rigid (simulated household: anchors 7.8 -> 5.7 mm RMSE). The anchors'
    covariances stay the anchor solve's; ``revisits`` None returns ``sol`` unchanged."""
    import dataclasses

    if revisits is None:
        return sol
    nodes, ns = revisits.nodes, revisits.solution
    stamps = np.asarray(anchor_stamps_ns, np.int64)
    k = np.clip(np.searchsorted(nodes.stamps_ns, stamps), 0, len(nodes) - 1)
    hit = nodes.stamps_ns[k] == stamps
    wTa = np.where(hit[:, None], ns.wTn[k], np.asarray(sol.wTa, np.float64))
    return dataclasses.replace(sol, wTa=wTa)


def map_log(log: Any, frontend: Any = None, covariances: bool = True) -> tuple[Any, Any]:
    """The SLAM part of a run on a read log, without vision or maps: the front end with loops re-estimated, the
    final solve (the run's kernels and outlier rounds; anchor covariances when ``covariances``), the keyframe
    solve and its anchors, as ``holoslam.pipeline.run`` does. ``frontend``: a ``FrontEndConfig`` (default
    settings when None). Returns ``(FrontEnd, Solution)``."""
    fe, sol, _ = map_log_keyframes(log, frontend, covariances)
    return fe, sol


def map_log_keyframes(log: Any, frontend: Any = None, covariances: bool = True) -> tuple[Any, Any, Any]:
    """:func:`map_log`, and the keyframe solve (``KeyframeSolve`` or None) that places every scan of the run's
    trajectory (``trajectory.run_trajectory(frontend.corrected_log(log, fe), fe, sol, nodes)``); a second pass on
    corrected odometry when the first calls for one (``odometer_pass``), as a run makes."""
    import dataclasses

    from holoslam.solve import CovarianceScope, SolveOptions, solve
    from holoslam.submaps.frontend import FrontEndConfig, build_problem
    from holoslam.trajectory import run_trajectory

    cfg = frontend or FrontEndConfig()
    scope = CovarianceScope.ANCHORS if covariances else CovarianceScope.NONE

    def one_pass(log: Any) -> tuple[Any, Any, Any]:
        fe = build_problem(log, config=cfg, optimize=reestimate_anchors)
        sol = solve(fe.problem, SolveOptions(covariances=scope, build=run_build_options()))
        return fe, sol, revisit_nodes(fe, sol, cfg)

    fe, sol, nodes = one_pass(log)  # corrected by local SLAM's check of the odometer when it found it off
    fix = odometer_pass(log, fe, lambda: run_trajectory(log, fe, sol, nodes), cfg)
    if fix is not None:
        cfg = single_pass(cfg)
        fe, sol, nodes = one_pass(fix.apply(log))
        fe = dataclasses.replace(fe, odometer_correction=fix)
    return fe, keyframe_anchors(sol, fe.anchor_stamps_ns, nodes), nodes


def odometer_pass(log: Any, fe: Any, trajectory: Callable[[], Any], cfg: Any) -> OdometerCorrection | None:
    """After a SLAM pass over ``log`` (its front end ``fe``; ``trajectory()`` its ``RunTrajectory``, asked for only
    when needed): the odometry correction that calls for a second pass, or None
    (``holoslam.submaps.odometer.OdometerCorrectionConfig``, ``cfg.odometer`` of the ``FrontEndConfig``): the raw
    odometry against the solved keyframes off by more than a wheel's calibration, where the scans were blind
    along the track often enough for the map to have followed it. A run maps again on
    ``fix.apply(log)`` (``frontend.corrected_log``)."""
    from holoslam.submaps.odometer import odometer_bias, odometer_correction

    oc = cfg.odometer
    if not oc.open_for(fe.blind_share) or fe.odometer_correction is not None or not log.odometry:
        return None  # off, corrected already (local SLAM's check), or no ground for it
    traj = trajectory()
    odom_stamps_ns, odomTb = log.odometry_arrays()
    bias = odometer_bias(traj.key_stamps_ns, traj.wTk, odom_stamps_ns, odomTb, blind=fe.blind_at(traj.key_stamps_ns))
    return odometer_correction(bias, fe.blind_share, oc)


def single_pass(frontend: Any) -> Any:
    """The ``FrontEndConfig`` of a second pass: the odometer checked no more (it is corrected already)."""
    import dataclasses

    return dataclasses.replace(frontend, odometer=dataclasses.replace(frontend.odometer, enabled=False))
