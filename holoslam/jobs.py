"""One library call per light CLI command (solve, inspect, tags, topology, evaluate, datasets; the pipeline's
own jobs are in :mod:`holoslam.pipeline`). Each imports only what its job uses, so that a command that solves a
g2o file or reads a log's summary does not load the front end, the simulator or the compiled kernels. Each
returns a result record (or JSON-able data) that knows its numbers; the CLI turns it into text.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from holoslam.choices import SOLVE_METHODS, SOLVE_STARTS
from holoslam.errors import ConfigError, HoloslamError, IngestError

if TYPE_CHECKING:
    from holoslam.config import RobotConfig
    from holoslam.evaluate import GroundTruthErrors, RelationErrors
    from holoslam.graph.solution import Solution, StartsReport
    from holoslam.maps.settings import HolographicConfig, TopologyConfig
    from holoslam.solve import IterationHook, SolveOptions

__all__ = [
    "Evaluation",
    "evaluate_trajectory",
    "trajectory_path",
    "G2oSolveSummary",
    "solve_g2o_file",
    "solve_graph_file",
    "SOLVE_METHODS",
    "SOLVE_STARTS",
    "inspect_log_file",
    "list_datasets",
    "decode_tags",
    "topology_from_map_file",
    "MapTopology",
    "map_topology",
]


@dataclass(frozen=True)
class Evaluation:
    """What ``holoslam evaluate`` measured: the trajectory scored, what it was scored against, and the errors
    (``relations`` for a ``.relations`` file, ``truth`` for a TUM ground truth)."""

    trajectory: str
    reference: str
    poses: int
    relations: RelationErrors | None = None
    truth: GroundTruthErrors | None = None

    @property
    def ok(self) -> bool:
        """False when nothing could be scored (no relation had a pose near both of its stamps)."""
        return self.relations is None or self.relations.n_matched > 0

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "trajectory": self.trajectory,
            "reference": self.reference,
            "poses": self.poses,
        }
        if self.relations is not None:
            out["relation_errors"] = self.relations.to_dict()
        if self.truth is not None:
            out["ground_truth_errors"] = self.truth.to_dict()
        return out


def trajectory_path(target: str | Path) -> Path:
    """The TUM file to score: ``target`` itself, or the ``trajectory.tum`` of a complete run folder (one with a
    valid ``run.json``; any other folder is refused with a one-line ``IngestError``)."""
    p = Path(target)
    if p.is_dir():
        from holoslam.io.run_manifest import require_complete

        require_complete(p)  # a folder is a run's only when its run.json says it is complete
        tum = p / "trajectory.tum"
        if not tum.is_file():
            raise IngestError(
                f"{p}: a folder without trajectory.tum; give a run folder written by 'holoslam run' or a TUM file"
            )
        return tum
    if not p.exists():
        raise IngestError(f"{p}: no such file or folder; give a run folder or a TUM trajectory file")
    return p


def evaluate_trajectory(
    target: str | Path,
    *,
    relations: str | Path | None = None,
    truth: str | Path | None = None,
    max_dt_s: float = 0.05,
    rpe_delta_s: float = 1.0,
    frame: str = "",
) -> Evaluation:
    """Score a run folder's ``trajectory.tum`` (or any TUM file) against a ``.relations`` file (relation
    errors: poses matched to the nearest stamp within ``max_dt_s``) or a TUM ground truth (ATE after SE(2)
    alignment and RPE over ``rpe_delta_s``). Exactly one of ``relations`` and ``truth``. ``frame``: score the
    pose of that frame of the robot instead of the base's (a run folder: its log's static transforms, in
    report.json; the Freiburg benchmark scores the laser's)."""
    import math

    from holoslam.evaluate import ground_truth_errors, relation_errors
    from holoslam.io.relations import read_relations

    if (relations is None) == (truth is None):
        raise ConfigError("give exactly one reference: a .relations file or a TUM ground truth")
    if not (math.isfinite(max_dt_s) and max_dt_s >= 0):
        raise ConfigError(f"the stamp tolerance must be a finite number of seconds >= 0, got {max_dt_s}")
    if not (math.isfinite(rpe_delta_s) and rpe_delta_s > 0):
        raise ConfigError(f"the RPE time step must be a finite number of seconds > 0, got {rpe_delta_s}")
    tum = trajectory_path(target)
    stamps, wTb = _read_trajectory(tum)
    bTf = frame_pose(target, frame)
    if bTf is not None:
        from holoslam.geometry import compose

        wTb = compose(wTb, bTf)
    if relations is not None:
        rel = read_relations(relations)
        errors = relation_errors(stamps, wTb, rel, max_dt_ns=int(round(max_dt_s * 1e9)))
        return Evaluation(str(tum), str(relations), int(len(stamps)), relations=errors)
    gt_path = trajectory_path(truth)  # type: ignore[arg-type]
    gt_stamps, gt_wTb = _read_trajectory(gt_path)
    if not (stamps.max() >= gt_stamps.min() and stamps.min() <= gt_stamps.max()):
        raise IngestError(
            f"{tum}: no pose inside the ground truth's time span ({gt_stamps.min() / 1e9:.6f} to "
            f"{gt_stamps.max() / 1e9:.6f} s; the trajectory spans {stamps.min() / 1e9:.6f} to "
            f"{stamps.max() / 1e9:.6f} s); give the ground truth of the same log, stamped in the same clock"
        )
    errors_gt = ground_truth_errors(
        stamps, wTb, gt_stamps, gt_wTb, rpe_delta_ns=int(round(rpe_delta_s * 1e9))
    )
    return Evaluation(str(tum), str(gt_path), int(len(stamps)), truth=errors_gt)


def frame_pose(run: str | Path, frame: str):
    """The planar pose (x, y, yaw) of ``frame`` in the run's base frame (None for the base itself or ""), from
    the run folder's report.json (``RunReport.frames``)."""
    import numpy as np

    from holoslam.io.run_folder import load_run

    if frame in ("", "base"):
        return None
    if not Path(run).is_dir():
        raise ConfigError(f"--frame {frame}: {run} is a TUM file; give the run folder, whose report.json holds the "
                          "log's frames")
    frames = (load_run(run, parts=("report",)).report or {}).get("frames") or {}
    poses = frames.get("poses") or {}
    if frame == frames.get("base"):
        return None
    if frame not in poses:
        raise ConfigError(f"{Path(run) / 'report.json'}: no frame {frame!r} fixed to the robot's base "
                          f"{frames.get('base', '?')!r}; its frames: {', '.join(sorted(poses)) or 'none recorded'} "
                          "(runs before this version did not record them: run the log again)")
    return np.asarray(poses[frame], dtype=np.float64)


def _read_trajectory(path: Path) -> tuple[Any, Any]:
    """(stamps_ns, wTb) of a TUM file, with every way it can be unusable said as an IngestError."""
    import numpy as np

    from holoslam.io.trajectory import read_tum

    try:
        stamps, wTb = read_tum(path)
    except IsADirectoryError:
        raise IngestError(f"{path}: is a folder; give a TUM trajectory file") from None
    except UnicodeDecodeError:
        raise IngestError(
            f"{path}: not a text file; a TUM trajectory holds lines 'stamp x y z qx qy qz qw'"
        ) from None
    except OSError as e:
        raise IngestError(f"{path}: cannot be read ({e.strerror})") from None
    if len(stamps) == 0:
        raise IngestError(
            f"{path}: no pose in the file; a TUM trajectory holds lines 'stamp x y z qx qy qz qw'"
        )
    if not np.all(np.isfinite(wTb)):
        raise IngestError(f"{path}: a pose holds a non-finite number (nan or inf); give finite poses")
    return stamps, wTb


# ------------------------------------------------------------------------------------------- holoslam solve

_START_NAME = {v.value: k for k, v in SOLVE_STARTS.items()}


def start_name(initialisation: Any) -> str:
    """The CLI's name of a start (``file`` for the problem's own guess)."""
    value = getattr(initialisation, "value", initialisation)
    return _START_NAME.get(str(value), str(value))


@dataclass(frozen=True)
class G2oSolveSummary:
    """What ``solve_g2o_file`` did: sizes, iterations, errors, times (read / build+solve / write), the start kept
    and, for ``Initialisation.AUTO``, every start's outcome and whether they agree (``starts``)."""

    in_path: str
    out_path: str | None
    num_poses: int
    num_landmarks: int
    num_factors: int
    iterations: int
    initial_error: float
    final_error: float
    seconds_read: float
    seconds_solve: float
    seconds_write: float
    skipped: tuple[str, ...] = ()
    initialisation: str = "problem"  # the start used (with AUTO: the kept one)
    candidates: tuple[tuple[str, float], ...] = ()  # AUTO: (start, final error; nan = failed)
    starts: StartsReport | None = None
    tum: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: every number, the starts as a list of records (CLI start names), their agreement and the
        fallback decision."""
        out: dict[str, Any] = {
            k: getattr(self, k)
            for k in (
                "in_path", "out_path", "num_poses", "num_landmarks", "num_factors", "iterations",
                "initial_error", "final_error", "seconds_read", "seconds_solve", "seconds_write",
            )
        }  # fmt: skip
        out["skipped"] = list(self.skipped)
        out["initialisation"] = start_name(self.initialisation)
        out["candidates"] = [[start_name(c), e] for c, e in self.candidates]
        if self.starts is not None:
            r = self.starts
            out["starts"] = [
                {
                    "start": start_name(o.initialisation),
                    "final_error": o.final_error,
                    "iterations": o.iterations,
                    "seconds": o.seconds,
                    "max_dxy_m": o.max_dxy,
                    "max_dtheta_rad": o.max_dtheta,
                    "reached": None if o.reached is None else start_name(o.reached),
                    "failure": o.failure or None,
                }
                for o in r.outcomes
            ]
            out["starts_skipped"] = [[start_name(c), why] for c, why in r.skipped]
            out["starts_agree"] = r.agree
            out["beyond_chi2"] = r.beyond
            out["measurements"] = r.measurements
            out["beyond_limit"] = r.beyond_limit
            out["fallback"] = None if r.fallback is None else start_name(r.fallback)
            out["fallback_ran"] = r.fallback_ran
        if self.tum is not None:
            out["tum"] = self.tum
        return out


def solve_g2o_file(
    in_path: str | Path,
    out_path: str | Path | None = None,
    method: Any = "batch",
    initialisation: Any = "auto",
    noise: Any = None,
    options: SolveOptions | None = None,
    iteration_hook: IterationHook | None = None,
) -> tuple[G2oSolveSummary, Solution]:
    """Read a 2D g2o / TORO / iSAM graph, optimise it with its first pose fixed (or the FIX vertices) and no robust
    kernels, and write the optimised graph as g2o (when ``out_path`` is given). ``initialisation`` defaults to
    ``AUTO``: LM from the chordal start, then from the file's guess only when that solution does not fit (see
    :mod:`holoslam.graph.starts`). ``options`` (when given) replaces ``method`` and ``initialisation``."""
    from holoslam.graph.build import BuildOptions
    from holoslam.graph.problem import problem_from_g2o
    from holoslam.io.g2o import TextNoise, parse_g2o, read_g2o_text
    from holoslam.io.g2o_write import with_estimate, write_g2o
    from holoslam.solve import Initialisation, Method, SolveOptions, solve

    t0 = time.perf_counter()
    text = read_g2o_text(in_path)
    g = parse_g2o(text, source=str(in_path), noise=TextNoise.GTSAM_AUTO if noise is None else noise)
    problem = problem_from_g2o(g, fix_first=True)
    t1 = time.perf_counter()
    opts = options or SolveOptions(
        method=Method(method),
        initialisation=Initialisation(initialisation),
        reject_outliers=False,
        detect_moved=False,
        final_gaussian=False,
        build=BuildOptions().without_kernels(),
    )
    sol = solve(problem, opts, iteration_hook)
    t2 = time.perf_counter()
    if out_path is not None:
        lm_ids = [int(n) for n in sol.landmark_ids]
        assert problem.pose_ids is not None  # set by SlamProblem.__post_init__
        # measurements read from EDGE_SE2 lines are copied as they stand (exact, and fast)
        write_g2o(
            with_estimate(g, problem.pose_ids, sol.wTa, lm_ids, sol.w_landmarks), out_path, source_text=text
        )
    t3 = time.perf_counter()
    nf = len(problem.relative) + len(problem.landmarks) + len(problem.priors)
    summary = G2oSolveSummary(
        in_path=str(in_path),
        out_path=None if out_path is None else str(out_path),
        num_poses=problem.num_poses,
        num_landmarks=len(sol.landmark_ids),
        num_factors=nf,
        iterations=sol.iterations,
        initial_error=sol.initial_error,
        final_error=sol.final_error,
        seconds_read=t1 - t0,
        seconds_solve=t2 - t1,
        seconds_write=t3 - t2,
        skipped=tuple(f"{s.tag} x{s.count} (first at line {s.first_line})" for s in g.skipped),
        initialisation=(sol.initialisation or Initialisation(opts.initialisation)).value,
        candidates=tuple((c.value, e) for c, e in sol.candidates),
        starts=sol.starts,
    )
    return summary, sol


def solve_graph_file(
    input_path: str | Path,
    output: str | Path,
    tum: str | Path | None = None,
    method: str = "lm",
    init: str | None = None,
    kernel: str = "none",
    kernel_parameter: float = 1.0,
    noise: str = "gtsam_auto",
) -> G2oSolveSummary:
    """``holoslam solve``: optimise a g2o / TORO / iSAM text pose graph (first pose fixed) and write the result
    (g2o, and TUM). ``method``: lm (batch Levenberg-Marquardt) or isam2; ``init``: file (the file's vertices),
    odometry, lago, chordal, incremental or auto (default with lm: LM from the chordal start, from the file's
    guess only when that solution disagrees with the measurements, the lower kept, the incremental start only when
    the kept solution still disagrees; with isam2: file). ``kernel`` (none, huber, cauchy, dcs, geman_mcclure; parameter in whitened units) puts a robust
    kernel on every edge and landmark measurement, as g2o's ``-robustKernel`` does: a few wrong loop closures
    then no longer bend the graph, at the price of a non-convex cost. ``noise`` says how the noise numbers of
    EDGE2 / EDGE / ODOMETRY / LANDMARK lines read (g2o's EDGE_SE2 always carries information): gtsam_auto (as
    gtsam's load2D), covariance, information (iSAM's own files such as victoriaPark.txt), toro_information or
    sqrt_information."""
    if init is None:
        init = "file" if method == "isam2" else "auto"
    if method not in SOLVE_METHODS or init not in SOLVE_STARTS:
        raise ConfigError(
            f"method must be one of {sorted(SOLVE_METHODS)} and init one of {sorted(SOLVE_STARTS)}"
        )
    from holoslam.graph.build import BuildOptions
    from holoslam.graph.factors import NO_KERNEL, Kernel, RobustKernel
    from holoslam.io.g2o import TextNoise
    from holoslam.solve import Initialisation, Method, SolveOptions

    noises = [n.value for n in TextNoise]
    if noise not in noises:
        raise ConfigError(f"noise {noise!r} is not one of {noises}")
    kernels = [k.value for k in RobustKernel]
    if kernel not in kernels:
        raise ConfigError(f"kernel {kernel!r} is not one of {kernels}")
    if not (math.isfinite(kernel_parameter) and kernel_parameter > 0):
        raise ConfigError(f"the kernel parameter must be a finite number > 0, got {kernel_parameter}")
    if not Path(input_path).is_file():
        raise IngestError(f"graph file {input_path} does not exist")
    robust = Kernel(RobustKernel(kernel), float(kernel_parameter))
    # with a kernel: step (1) of solve's outlier scheme only (kernels, no chi2 rejection rounds)
    options = SolveOptions(
        method=Method(SOLVE_METHODS[method]),
        initialisation=Initialisation(SOLVE_STARTS[init]),
        reject_outliers=robust.kind is not RobustKernel.NONE,
        max_rounds=0,
        detect_moved=False,
        final_gaussian=False,
        build=BuildOptions(
            loop_kernel=robust, landmark_kernel=robust, heading_kernel=NO_KERNEL, robust_kinds=("g2o",)
        ),
    )
    summary, solution = solve_g2o_file(input_path, output, noise=TextNoise(noise), options=options)
    if tum is None:
        return summary
    import numpy as np

    from holoslam.io.trajectory import write_tum

    ids = solution.pose_ids if solution.pose_ids is not None else np.arange(len(solution.wTa))
    # g2o carries no time: the pose index (or vertex id) stands for seconds
    write_tum(tum, np.asarray(ids, dtype=np.int64) * 1_000_000_000, solution.wTa)
    from dataclasses import replace

    return replace(summary, tum=str(tum))


# -------------------------------------------------------------------------------- inspect, datasets, tags, maps


def inspect_log_file(log: str | Path, mapping: str | Path | None = None) -> tuple[str, dict[str, Any]]:
    """``holoslam inspect``: the channel table of a log (summary section only) as text and as JSON-able data."""
    from holoslam.io.mcap import format_summary, inspect_log, summary_to_dict

    s = inspect_log(log, mapping=mapping)
    return format_summary(s), summary_to_dict(s)


def list_datasets() -> list[dict[str, Any]]:
    """``holoslam datasets``: the bundled and known datasets with where they are on this machine."""
    from holoslam.io.datasets import find_dataset, load_manifest

    rows = []
    for name, entry in load_manifest().items():
        path = find_dataset(name)
        extra = entry.extra or {}
        rows.append(
            {
                "name": name,
                "kind": entry.where,
                "file": entry.file,
                "path": None if path is None else str(path),
                "source": str(extra.get("how_to_get") or extra.get("source") or extra.get("url") or ""),
                "licence": entry.licence,
            }
        )
    return rows


def decode_tags(images: Sequence[str]) -> list[dict[str, Any]]:
    """``holoslam tags``: decode the QR codes of image files; an unreadable file yields an ``error`` item and the
    others go on."""
    from holoslam.vision.qr import decode_image_file, detection_to_json

    out: list[dict[str, Any]] = []
    for path in images:
        try:
            dets = decode_image_file(path)
        except HoloslamError as e:
            out.append({"image": path, "error": str(e)})
            continue
        out.extend(detection_to_json(d, path) for d in dets)
    return out


def topology_from_map_file(map_yaml: str | Path, output: str | Path, **kwargs: Any) -> dict[str, Any]:
    """``holoslam topology`` as a dict: :func:`map_topology`'s summary (kept for callers of this name)."""
    return map_topology(map_yaml, output, **kwargs).to_dict()


# ---------------------------------------------------------------------------------------------- topology


@dataclass(frozen=True)
class MapTopology:
    """What ``holoslam topology`` made of a map: its size, the cleaning applied, the topology's counts, and
    (when rooms were asked for) the rooms, doorways, wide openings and holographic places; times (s) and the
    files written."""

    map: str
    cells: str
    cleaning: str
    nodes: int
    edges: int
    components: int
    independent_cycles: int
    topology_s: float
    files: tuple[str, ...]
    rooms: int | None = None
    doorways: int | None = None
    wide_openings: int | None = None
    places: str | None = None
    rooms_s: float | None = None

    def to_dict(self) -> dict[str, Any]:
        import dataclasses

        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}

    def to_text(self) -> str:
        d = self.to_dict()
        d["files"] = ", ".join(self.files)
        return "\n".join(f"{k}: {v}" for k, v in d.items())


def map_topology(
    map_yaml: str | Path,
    output: str | Path,
    *,
    topology: TopologyConfig | None = None,
    holographic: HolographicConfig | None = None,
    robot: RobotConfig | None = None,
    rooms_png: str | Path | None = None,
    png: str | Path | None = None,
) -> MapTopology:
    """Topology graph of a ROS map_server map written as GraphML (and JSON node-link beside it), built as a run
    builds it (``topology``: the run configuration's section, cleaning, opening, spur pruning; default the
    run's). With ``rooms_png`` or ``png`` the rooms and the holographic graph's places are found too
    (``holographic`` section; ``robot`` for the reach model, default ``ReachModel()``: the graph has no objects)
    and the holographic graph is written beside the topology (``<name>_holographic``):
    ``rooms_png`` gets the room label image (16-bit, the map image's size and row order, 0 = not a room, ids =
    the ``room_id`` of the room nodes ``room:<id>``), ``png`` a picture of the map with its rooms, topology and
    places."""
    import time

    from holoslam.io.graphs import write_graph_files, write_graphml, write_node_link_json
    from holoslam.io.grid import read_grid, write_label_png
    from holoslam.maps.cleaning import CleaningReport
    from holoslam.maps.holographic import ReachModel, build_holographic
    from holoslam.maps.passages import EdgePaths
    from holoslam.maps.polyline import compact_paths
    from holoslam.maps.rooms import rooms_of_grid
    from holoslam.maps.settings import HolographicConfig, TopologyConfig
    from holoslam.maps.topology import cycle_rank, to_graphml_ready, topology_from_settings

    tc = topology or TopologyConfig()
    hc = holographic or HolographicConfig()
    out = Path(output)
    for target in (out, rooms_png, png):
        if target is not None and not Path(target).parent.is_dir():
            raise ConfigError(f"folder {Path(target).parent} does not exist; create it first")
    grid = read_grid(map_yaml)
    t0 = time.perf_counter()
    G = topology_from_settings(grid, tc, robot_radius_m=None if robot is None else robot.radius_m)
    t_topology = time.perf_counter() - t0
    ready = to_graphml_ready(compact_paths(G))  # paths simplified to the map's resolution, as a run writes them
    files = [str(write_graphml(ready, out)), str(write_node_link_json(ready, out.with_suffix(".json")))]
    rep = CleaningReport(**{k[len("cleaned_") :]: v for k, v in G.graph.items() if k.startswith("cleaned_")})
    c = tc.cleaning
    cleaning = (
        f"free regions < {c.min_free_area_m2:g} m^2 dropped: {rep.free_regions_dropped} "
        f"({rep.free_cells_dropped} cells); obstacle islands < {c.min_obstacle_area_m2:g} m^2 filled: "
        f"{rep.islands_filled} ({rep.island_cells_filled} cells"
        + (f", {rep.unknown_islands_filled} of unknown cells only" if c.unknown_islands == "free" else "")
        + f"); unknown cells count as {c.unknown_islands}; opening {tc.close_cells} cells, erosion "
        f"{tc.erode_cells} cells; left: {rep.free_regions} free regions, {rep.islands} obstacle islands"
    )
    import networkx as nx

    base = dict(
        map=str(map_yaml),
        cells=f"{grid.shape[1]} x {grid.shape[0]} at {grid.resolution} m",
        cleaning=cleaning,
        nodes=G.number_of_nodes(),
        edges=G.number_of_edges(),
        components=nx.number_connected_components(G) if G.number_of_nodes() else 0,
        independent_cycles=cycle_rank(G),
        topology_s=round(t_topology, 3),
    )
    if rooms_png is None and png is None:
        return MapTopology(**base, files=tuple(files))
    t0 = time.perf_counter()
    ep = EdgePaths(G)
    rooms = rooms_of_grid(grid, G, hc.rooms, ep)
    rb = robot
    reach = (
        ReachModel()
        if rb is None
        else ReachModel(rb.radius_m, rb.arm_reach_m, rb.reach_z_min_m, rb.reach_z_max_m, rb.reach_through_m)
    )
    H = build_holographic(grid, G, reach_model=reach, params=hc.places, rooms=rooms, edge_paths=ep)
    t_rooms = time.perf_counter() - t0
    places: dict[str, int] = {}
    for _n, place in H.nodes(data="place"):
        places[place] = places.get(place, 0) + 1
    files += [str(p) for p in write_graph_files(compact_paths(H), out.parent, out.stem + "_holographic")]
    if rooms_png is not None:
        files.append(str(write_label_png(rooms.labels, rooms_png)))
    if png is not None:
        from holoslam import viz

        fig = viz.map_figure(
            grid,
            topology=G,
            holographic=H,
            rooms=rooms.labels,
            title=f"{_map_name(map_yaml)}: {rooms.n_rooms} rooms; topology {G.number_of_nodes()} nodes, "
            f"{G.number_of_edges()} edges",
        )
        fig.savefig(png, dpi=110)
        files.append(str(png))
    return MapTopology(
        **base,
        files=tuple(files),
        rooms=rooms.n_rooms,
        doorways=sum(1 for d in rooms.doorways if d.kind == "door"),
        wide_openings=sum(1 for d in rooms.doorways if d.kind == "opening"),
        places=", ".join(f"{k} {v}" for k, v in sorted(places.items())),
        rooms_s=round(t_rooms, 3),
    )


def _map_name(map_yaml: str | Path) -> str:
    """A map's name for a title: the YAML's stem, or its folder's name for a run folder's ``map.yaml``."""
    p = Path(map_yaml)
    return p.parent.name if p.stem == "map" and p.parent.name else p.stem
