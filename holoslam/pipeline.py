"""The main job, ``run``: a log in, every result of a run out (``RunResult``), as a sequence of named stages::

    log --ingest--> records --vision--> object observations (+ feature sets, Eq. 13)
        --front end--> submaps + SLAM problem (Eq. 12, 14-16) --optimise--> anchors, objects, covariances
        --triangulation--> codes without a printed size --trajectory--> base poses, located objects
        --maps--> occupancy grid, thinning topology, holographic graph, two-layer planning graph --> report

Each stage lives in the module named after what it holds (``sightings``, ``submaps.frontend``, ``optimise``,
``trajectory``, ``objects``, ``mapping``, ``report``); every stage is timed (``timing.StageClock``). Writing a
run folder and the other jobs around runs are in ``holoslam.run_jobs``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

# The configuration tree lives in holoslam.config; re-exported here for existing callers.
from holoslam.config import (
    GridConfig,
    HolographicConfig,
    PlanningConfig,
    RobotConfig,
    RunConfig,
    SolverConfig,
    SolverMethod,
    TopologyConfig,
    VisionConfig,
    load_run_config,
)
from holoslam.timing import Progress, StageClock

if TYPE_CHECKING:
    from holoslam.report import RunReport

__all__ = [
    "RunConfig",
    "SolverConfig",
    "SolverMethod",
    "GridConfig",
    "TopologyConfig",
    "HolographicConfig",
    "PlanningConfig",
    "RobotConfig",
    "VisionConfig",
    "load_run_config",
    "RunResult",
    "run",
    "run_data",
    "FRONT_END",
]

FRONT_END = "front end (submaps, Eq. 12/14/15/16)"  # the front end stage's name in progress and timings


@dataclass(frozen=True, eq=False)
class RunResult:
    """Everything a run produced, as numpy arrays, records and networkx graphs (nothing written yet)."""

    source: str
    config: RunConfig
    stamps_ns: np.ndarray  # (N,) odometry and scan stamps, sorted, unique
    wTb: np.ndarray  # (N, 3) optimised base trajectory at stamps_ns
    dead_reckoning_wTb: np.ndarray  # (N, 3)
    anchor_stamps_ns: np.ndarray  # (K,)
    wTa: np.ndarray  # (K, 3)
    cov_wTa: np.ndarray | None  # (K, 3, 3) body frame
    objects: tuple  # holoslam.maps.holographic.ObjectInfo
    moved_objects: tuple
    problem: Any  # holoslam.graph.problem.SlamProblem
    solution: Any  # holoslam.solve.Solution
    frontend: Any  # holoslam.submaps.frontend.FrontEnd
    grid: Any  # OccupancyGrid
    topology: Any  # nx.MultiGraph
    holographic: Any  # nx.Graph
    planning: Any  # TwoLayerGraph
    report: RunReport
    rooms: Any = None  # holoslam.maps.rooms.RoomSegmentation: ids = the holographic graph's room nodes


def run(log_path: str | Path, config: RunConfig | None = None, progress: Progress | None = None) -> RunResult:
    """The main job on one log: ingest, locate objects, build and optimise the graph, build the maps and
    graphs. Raises ``IngestError`` when the log lacks what a run needs (odometry and laser scans)."""
    from holoslam.io.mcap import read_log

    cfg = config or RunConfig()
    clock = StageClock(progress)
    with clock.stage("ingest"):
        log, ingest_report = read_log(log_path, mapping=cfg.mapping, require=["odometry", "scan"])
    return _run_stages(log, ingest_report, cfg, clock, str(log_path))


def run_data(log: Any, ingest_report: Any, config: RunConfig | None = None,
             progress: Progress | None = None) -> RunResult:
    """``run`` on a log already in memory (a ``holoslam.types.LogData`` and the ``IngestReport`` that
    ``holoslam.io.mcap.read_log`` returned with it), e.g. one edited in a notebook."""
    cfg = config or RunConfig()
    return _run_stages(log, ingest_report, cfg, StageClock(progress), str(log.source))


@dataclass(frozen=True, eq=False)
class SlamStages:
    """What the stages up to the located objects produced (``slam_stages``), before the maps: the front end,
    the solution (anchors from the keyframe solve), the sightings, the keyframe solve, the trajectory and the
    located objects, all in the run's own frame (the odometry's at the first scan)."""

    fe: Any
    sol: Any
    seen: Any
    revisits: Any
    traj: Any
    objects: tuple


#: the libraries the stages after the front end import (maps, graphs, report, pictures): ~1 s of imports, mostly
#: Python, done in the vision thread while the front end's compiled kernels leave the GIL free
_LATER_MODULES = ("networkx", "scipy.spatial", "matplotlib.figure", "matplotlib.backends.backend_agg",
                  "matplotlib.collections", "holoslam.report_build", "holoslam.evaluate", "holoslam.io.results_mcap")


def _import_later_stages() -> None:
    """Import ``_LATER_MODULES`` ahead of their stages (the run imports them anyway; one that fails to import
    here fails there, with its own message)."""
    import importlib

    for name in _LATER_MODULES:
        try:
            importlib.import_module(name)
        except ImportError:
            return


def slam_stages(log: Any, cfg: RunConfig, clock: StageClock) -> SlamStages:
    """The stages of a run from vision to the located objects (``run`` without the maps and the report); a
    second pass of the SLAM stages on corrected odometry when the first finds the odometer off where the scans
    cannot see motion (``holoslam.optimise.odometer_pass``)."""
    import dataclasses
    from concurrent.futures import ThreadPoolExecutor

    from holoslam.optimise import odometer_pass, single_pass
    from holoslam.sightings import see_objects

    # the vision stages read only the log (images, tag messages): they run in a thread while the front end does,
    # which needs their observations only once its local SLAM is done (OpenCV, zxing-cpp and the front end's
    # kernels release the GIL; the results are the same either way)
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="holoslam-vision") as pool:
        sightings = pool.submit(see_objects, log, cfg.vision, clock.background())
        pool.submit(_import_later_stages)  # after the vision stage, while the front end runs
        st = _slam_pass(log, cfg, clock, sightings.result)
    fix = odometer_pass(log, st.fe, lambda: st.traj, cfg.frontend)
    if fix is None:
        return st
    clock.progress(fix.notice())
    st = _slam_pass(fix.apply(log), dataclasses.replace(cfg, frontend=single_pass(cfg.frontend)), clock,
                    sightings.result)
    return dataclasses.replace(st, fe=dataclasses.replace(st.fe, odometer_correction=fix))


def _slam_pass(log: Any, cfg: RunConfig, clock: StageClock, seen_of: Any) -> SlamStages:
    """``slam_stages``' SLAM stages on ``log``: the front end (the sightings ``seen_of()`` once its local SLAM is
    done), the solve, the objects triangulated, the keyframes, the trajectory and the located objects."""
    from holoslam.objects import located_objects
    from holoslam.optimise import keyframe_anchors, reestimate_anchors, revisit_nodes, solve_options
    from holoslam.sightings import triangulate_objects
    from holoslam.solve import solve
    from holoslam.submaps.frontend import build_problem, corrected_log
    from holoslam.trajectory import run_trajectory

    with clock.stage(FRONT_END):
        fe = build_problem(log, lambda: seen_of().observations, cfg.frontend, clock.progress_of(FRONT_END),
                           optimize=reestimate_anchors)
    if fe.odometer_correction is not None:  # local SLAM's check found the odometer off, and it started again
        clock.progress(fe.odometer_correction.notice())
    log = corrected_log(log, fe)  # the odometry the front end mapped with (corrected when it found it off)
    seen = seen_of()
    with clock.stage("optimise"):
        options = solve_options(cfg.solver)
        sol = solve(fe.problem, options)
    fe, sol, seen = triangulate_objects(seen, fe, sol, log, cfg, options, clock)
    with clock.stage("keyframes (revisits)"):
        revisits = revisit_nodes(fe, sol, cfg.frontend, clock.progress_of("keyframes (revisits)"))
        sol = keyframe_anchors(sol, fe.anchor_stamps_ns, revisits)
    with clock.stage("trajectory"):
        traj = run_trajectory(log, fe, sol, revisits)
        objects = located_objects(fe.problem, sol, seen)
    return SlamStages(fe, sol, seen, revisits, traj, objects)


def finish_run(log: Any, ingest_report: Any, st: SlamStages, cfg: RunConfig, clock: StageClock, source: str,
               session: Any = None) -> RunResult:
    """The map stages and the report after ``slam_stages`` (``session``: a lifelong session's summary for the
    report, ``holoslam.lifelong``)."""
    from holoslam.mapping import build_maps
    from holoslam.objects import located_by
    from holoslam.report_build import build_report
    from holoslam.warmup import wait_for_kernels

    wait_for_kernels("holoslam.maps", "holoslam.planning", "holoslam._common_fast")  # a first run's pool: not twice

    fe, sol, seen, traj, objects = st.fe, st.sol, st.seen, st.traj, st.objects
    maps = build_maps(log, fe, sol, traj, objects, cfg, clock)
    report = build_report(log=log, ingest_report=ingest_report, sightings=seen, fe=fe, sol=sol, objects=objects,
                          maps=maps, trajectory=traj, timings=clock.total(),
                          located_by=located_by(seen.observations, objects),
                          codes_truth=cfg.vision.foreign_landmarks, revisits=st.revisits)
    if session is not None:
        import dataclasses

        report = dataclasses.replace(report, session=session)
    return RunResult(
        source=source,
        config=cfg,
        stamps_ns=traj.stamps_ns,
        wTb=traj.wTb,
        dead_reckoning_wTb=traj.dead_reckoning_wTb,
        anchor_stamps_ns=np.asarray(fe.anchor_stamps_ns, dtype=np.int64),
        wTa=sol.wTa,
        cov_wTa=sol.cov_wTa,
        objects=objects,
        moved_objects=tuple(sol.moved_objects),
        problem=fe.problem,
        solution=sol,
        frontend=fe,
        grid=maps.grid,
        topology=maps.topology,
        holographic=maps.holographic,
        planning=maps.planning,
        report=report,
        rooms=maps.rooms,
    )


def _run_stages(log: Any, ingest_report: Any, cfg: RunConfig, clock: StageClock, source: str) -> RunResult:
    """The stages after ingestion (``run``)."""
    return finish_run(log, ingest_report, slam_stages(log, cfg, clock), cfg, clock, source)
