"""The arguments of every ``holoslam`` command (one ``_add_*`` per sub-command) and the parser they make."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from holoslam import __version__
from holoslam.choices import SOLVE_METHODS, SOLVE_STARTS, RobustKernel, TextNoise
from holoslam.cli_commands import (
    cmd_config,
    cmd_datasets,
    cmd_demo,
    cmd_evaluate,
    cmd_export,
    cmd_inspect,
    cmd_objects,
    cmd_plan,
    cmd_run,
    cmd_simulate,
    cmd_solve,
    cmd_tags,
    cmd_topology,
    cmd_warmup,
)


def _parse_xy(text: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected x,y in metres (for example 1.5,-2), got {text!r}"
        ) from None
    return x, y


def _add_run(sub: Any) -> None:
    """The ``run`` command's arguments."""
    s = sub.add_parser("run", help="ingest, optimise and export one or many logs")
    s.add_argument("logs", nargs="+", help="MCAP files, rosbag2 folders, or folders of them")
    s.add_argument("-o", "--output", required=True, type=Path, help="output folder (one sub-folder per log)")
    s.add_argument("--config", type=Path, help="YAML run configuration (see README)")
    s.add_argument("--workers", type=int, help="parallel processes for many logs (default: all cores)")
    s.add_argument(
        "--scheduler", help="Dask scheduler address (tcp://host:8786) to run many logs on a cluster"
    )
    s.add_argument(
        "--force",
        action="store_true",
        help="many logs: run every log again (default: a log whose folder is complete for the same log and "
        "configuration is skipped as up to date)",
    )
    s.add_argument("--map", type=Path, metavar="STORE",
                   help="a map store (created when absent): the log becomes a new session of it, relocalised and "
                   "joined to its world when it can be placed; OUT is then in the store's world frame")
    s.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    s.add_argument("--json", action="store_true", help="print the summary as JSON only")
    s.set_defaults(func=cmd_run)


def _add_demo(sub: Any) -> None:
    """The ``demo`` command's arguments."""
    s = sub.add_parser(
        "demo", help="run the main job on the bundled household log (from any folder; output ./holoslam-demo)"
    )
    s.add_argument(
        "-o", "--output", type=Path, default=Path("holoslam-demo"), help="output folder (default ./holoslam-demo)"
    )
    s.add_argument("--config", type=Path, help="YAML run configuration (see README)")
    s.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    s.add_argument("--json", action="store_true", help="print the summary as JSON only")
    s.set_defaults(func=cmd_demo)


def _add_warmup(sub: Any) -> None:
    """The ``warmup`` command's arguments."""
    s = sub.add_parser(
        "warmup", help="compile the numba kernels a run uses into numba's cache (once per install)"
    )
    s.add_argument("--workers", type=int, help="compiling processes (default: the cores)")
    s.add_argument("--all", action="store_true", help="recompile every recorded signature, cached or not")
    s.set_defaults(func=cmd_warmup)


def _add_objects(sub: Any) -> None:
    """The ``objects`` command's arguments."""
    s = sub.add_parser("objects", help="the objects of a map store and their history across sessions")
    s.add_argument("store", type=Path, help="a map store ('holoslam run LOG --map STORE')")
    s.add_argument("--id", help="one object (e.g. O05)")
    s.add_argument("--at", type=int, metavar="SESSION", help="one session (its id)")
    s.add_argument("--now", action="store_true",
                   help="with --id: where it is now in the store's holographic graph (the places it is handled from)")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_objects)


def _add_config(sub: Any) -> None:
    """The ``config`` command's arguments."""
    s = sub.add_parser("config", help="the run configuration: --dump writes every setting with its default")
    s.add_argument("--dump", action="store_true", help="write the whole run configuration as YAML")
    s.add_argument("--config", type=Path, help="a YAML run configuration to merge over the defaults first")
    s.add_argument("-o", "--output", type=Path, help="file to write (default: standard output)")
    s.set_defaults(func=cmd_config)


def _add_inspect(sub: Any) -> None:
    """The ``inspect`` command's arguments."""
    s = sub.add_parser("inspect", help="summarise a log's channels without reading its messages")
    s.add_argument("log", type=Path)
    s.add_argument("--mapping", type=Path, help="YAML topic-role mapping for custom topics")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_inspect)


def _add_simulate(sub: Any) -> None:
    """The ``simulate`` command's arguments."""
    s = sub.add_parser("simulate", help="write a simulated reference-household log")
    s.add_argument("-o", "--output", required=True, type=Path, help="MCAP file to write (a folder with --days)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument(
        "--duration", type=float, default=None, help="seconds of robot time (default: whole route)"
    )
    s.add_argument("--image-rate", type=float, default=None, help="max camera snapshots per second")
    s.add_argument("--camera-rate", type=float, default=0.0, metavar="HZ",
                   help="a camera stream: every frame at HZ for the whole drive, with motion blur (default 0: "
                   "snapshots only)")
    s.add_argument("--exposure-ms", type=float, default=None,
                   help="the stream's exposure in ms (default 10), over which the robot's motion blurs a frame")
    s.add_argument("--noise-scale", type=float, default=1.0, help="multiply every sensor noise by this")
    s.add_argument("--profile", default="default",
                   help="the robot: default, noisy (3x every noise), skid-steer (another odometer), dense-lidar (1,081 beams at 40 Hz); see holoslam.sim.profiles")
    s.add_argument("--wall-codes", type=int, default=0, help="foreign QR codes on the walls (0-12)")
    s.add_argument("--sizeless-labels", type=int, default=0, help="labels printed without their size (0-8)")
    s.add_argument("--days", type=int, default=None, metavar="N",
                   help="N days of the household into the folder -o: objects moved, removed and added between days, "
                   "furniture moved, a different start each day, the truth in days.json (holoslam.sim.days)")
    s.add_argument("--building", action="store_true",
                   help="a large building instead of the household: a 350 m floor of long corridors and 300+ rooms, "
                   "a 1.4 Hz 180-beam laser, 80 minutes unless --duration (holoslam.sim.building)")
    s.add_argument("--changes", type=int, nargs=2, default=[5, 10], metavar=("LO", "HI"),
                   help="with --days: changes per day, drawn from LO..HI (default 5 10)")
    s.add_argument("--furniture", type=int, nargs=2, default=None, metavar=("LO", "HI"),
                   help="with --days: pieces of furniture moved per day, drawn from LO..HI (default 0 2: mostly "
                   "chairs; holoslam.sim.furniture_moves)")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_simulate)


def _add_solve(sub: Any) -> None:
    """The ``solve`` command's arguments."""
    s = sub.add_parser("solve", help="optimise a g2o (or TORO/iSAM text) pose graph")
    s.add_argument("input", type=Path)
    s.add_argument("-o", "--output", required=True, type=Path, help="optimised graph (.g2o)")
    s.add_argument("--tum", type=Path, help="also write the optimised poses as TUM text")
    s.add_argument("--method", choices=list(SOLVE_METHODS), default="lm")
    s.add_argument(
        "--init",
        choices=list(SOLVE_STARTS),
        default=None,
        help="start of the optimisation (default with lm: auto, LM from the chordal start, from the file's guess "
        "only when that solution disagrees with the measurements (the lower kept), and the slow incremental start "
        "only when the kept solution still disagrees; the output says what each start reached, which did not run "
        "and why, and whether they agree; with isam2: file)",
    )
    s.add_argument(
        "--kernel",
        choices=[k.value for k in RobustKernel],
        default="none",
        help="robust kernel on every edge (default none: plain least squares, as gtsam and g2o)",
    )
    s.add_argument(
        "--kernel-parameter",
        type=float,
        default=1.0,
        help="the kernel's width in whitened units (residual / sigma; default 1.0)",
    )
    s.add_argument(
        "--noise",
        choices=[n.value for n in TextNoise],
        default="gtsam_auto",
        help="how EDGE2/ODOMETRY/LANDMARK noise numbers read (EDGE_SE2 is always information); "
        "iSAM's own files (victoriaPark.txt, cityTrees10000.txt) carry information",
    )
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_solve)


def _add_plan(sub: Any) -> None:
    """The ``plan`` command's arguments."""
    s = sub.add_parser("plan", help="route from a pose to an object in a run's output")
    s.add_argument("run", type=Path, help="a run's output folder")
    s.add_argument("--to", required=True, help="object id (or type)")
    s.add_argument("--from", dest="from_xy", type=_parse_xy, help="start x,y in metres (default: last pose)")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_plan)


def _add_export(sub: Any) -> None:
    """The ``export`` command's arguments."""
    s = sub.add_parser("export", help="re-export a saved run (pictures, results MCAP, graphs), or a map store "
                       "(merged map, every session's trajectory, objects)")
    s.add_argument("run", type=Path, help="a run folder, or a map store file")
    s.add_argument("--to", type=Path, help="folder to write into (default: the run folder)")
    s.add_argument(
        "--formats", nargs="+", default=["all"], choices=["all", "pictures", "mcap", "graphs", "tum"]
    )
    s.set_defaults(func=cmd_export)


def _add_evaluate(sub: Any) -> None:
    """The ``evaluate`` command's arguments."""
    s = sub.add_parser("evaluate", help="score a run's trajectory against ground truth (relations or TUM)")
    s.add_argument("target", type=Path, help="a run folder (its trajectory.tum) or a TUM trajectory file")
    ref = s.add_mutually_exclusive_group(required=True)
    ref.add_argument(
        "--relations", type=Path, help="a .relations file (Freiburg benchmark): relation errors, mean ± std"
    )
    ref.add_argument("--truth", type=Path, help="a TUM ground truth: ATE after SE(2) alignment, and RPE")
    s.add_argument("--frame", default="base", help="score this frame of the robot, e.g. laser (the Freiburg "
                   "benchmark's): any frame the run's log fixes to its base by a static transform (default base)")
    s.add_argument(
        "--max-dt",
        type=float,
        default=0.05,
        help="a relation stamp is matched to the nearest pose within this many seconds (default 0.05)",
    )
    s.add_argument(
        "--rpe-delta",
        type=float,
        default=1.0,
        help="seconds between the two poses of an RPE pair (default 1)",
    )
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_evaluate)


def _add_datasets(sub: Any) -> None:
    """The ``datasets`` command's arguments."""
    s = sub.add_parser("datasets", help="list the bundled and known datasets and where they are")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_datasets)


def _add_tags(sub: Any) -> None:
    """The ``tags`` command's arguments."""
    s = sub.add_parser("tags", help="decode the QR labels in image files")
    s.add_argument("images", nargs="+")
    s.add_argument("--json", action="store_true", help="one JSON object per decoded code")
    s.set_defaults(func=cmd_tags)


def _add_topology(sub: Any) -> None:
    """The ``topology`` command's arguments."""
    s = sub.add_parser(
        "topology",
        help="topology graph of a ROS map_server map (PGM/PNG + YAML); with --rooms / --png its rooms too",
        description="The topology graph of a map, built as 'holoslam run' builds it (same settings and defaults: "
        "the run configuration's topology section, or --config). With --rooms or --png the rooms, doorways and "
        "places of the holographic graph too, written beside the GraphML as <name>_holographic.graphml/.json.",
    )
    s.add_argument("map", type=Path, help="map YAML")
    s.add_argument("-o", "--output", required=True, type=Path, help="GraphML to write (JSON beside it)")
    s.add_argument(
        "--rooms",
        type=Path,
        metavar="ROOMS.png",
        help="write the room label image: 16-bit PNG the map's size, 0 = not a room, ids = the room nodes' ids",
    )
    s.add_argument("--png", type=Path, metavar="PICTURE.png", help="draw the map, its rooms, topology and places")
    s.add_argument("--config", type=Path, help="YAML run configuration (its topology, holographic, robot sections)")
    s.add_argument(
        "--min-free-area",
        type=float,
        metavar="M2",
        help="cleaning: free regions smaller are dropped (default: the run's, 0.25 m^2)",
    )
    s.add_argument(
        "--min-obstacle-area",
        type=float,
        metavar="M2",
        help="cleaning: obstacle islands smaller are filled (default: the run's, 0.05 m^2)",
    )
    s.add_argument(
        "--unknown-islands",
        choices=["obstacle", "free"],
        help="cleaning: unknown cells count as obstacle, or islands of unknown cells only are free "
        "(default: the run's, obstacle)",
    )
    s.add_argument("--close-cells", type=int, metavar="N", help="open free space by a disc first (default 0)")
    s.add_argument("--erode-cells", type=int, metavar="N", help="erode free space by a disc first (default 0)")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_topology)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="holoslam",
        description="Factor-graph SLAM backend for household service robots: logs in, holographic maps out.",
    )
    p.add_argument("--version", action="version", version=f"holoslam {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in (_add_run, _add_demo, _add_warmup, _add_config, _add_inspect, _add_simulate, _add_solve, _add_plan, _add_export, _add_objects, _add_evaluate, _add_datasets, _add_tags, _add_topology):
        add(sub)
    return p
