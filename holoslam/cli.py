"""The ``holoslam`` command: parses arguments, calls one library function per command, prints, and maps
errors to exit codes. Only this module prints or exits.

Exit codes: 0 success; 1 the job ran but something failed (a log in a batch, an unreachable goal);
2 bad input (a missing or unreadable required input, a malformed file or config, a usage error).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from holoslam import __version__
from holoslam.choices import SOLVE_METHODS, SOLVE_STARTS, RobustKernel, TextNoise
from holoslam.errors import ConfigError, HoloslamError, PlanningError

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2


class Progress:
    """Stage-by-stage progress on stderr: a line per finished stage with its time; quiet when asked."""

    def __init__(self, quiet: bool = False) -> None:
        self.quiet = quiet
        self.tty = sys.stderr.isatty()
        self._t0 = time.perf_counter()
        self._last = ""

    def __call__(self, stage: str, done: float | None = None, total: float | None = None) -> None:
        if self.quiet:
            return
        if done is not None and total:
            line = f"  {stage}: {100.0 * done / total:5.1f}%"
            if self.tty:
                sys.stderr.write("\r" + line.ljust(len(self._last)))
                sys.stderr.flush()
                self._last = line
            return
        if self._last:
            sys.stderr.write("\n")
            self._last = ""
        sys.stderr.write(f"[{time.perf_counter() - self._t0:7.2f}s] {stage}\n")
        sys.stderr.flush()


def _err(msg: str) -> None:
    sys.stderr.write(f"holoslam: {msg}\n")


def _json(v, indent: int | None = 2) -> str:
    """Strict JSON (NaN / infinity printed as null: ``NaN`` is not JSON and breaks jq and JSON.parse)."""
    from holoslam.io.jsonsafe import dumps

    return dumps(v, indent=indent)


def _parse_xy(text: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected x,y in metres (for example 1.5,-2), got {text!r}"
        ) from None
    return x, y


# ---------------------------------------------------------------------------------------------- commands


def cmd_simulate(a: argparse.Namespace) -> int:
    from holoslam.run_jobs import simulate, simulate_building, simulate_days

    if a.building:
        summary = simulate_building(a.output, seed=a.seed, duration_s=a.duration)
        print(_json(summary) if a.json else "\n".join(f"{k}: {v}" for k, v in summary.items()))
        return EXIT_OK

    if a.days is not None:
        days = simulate_days(a.output, a.days, seed=a.seed, duration_s=a.duration, changes=tuple(a.changes))
        print(_json(days) if a.json else "\n".join(
            f"day {d['day']}: {a.output / d['log']}, start {d['start_pose']}, changes: "
            + (", ".join(f"{c['id']} {c['change']}" for c in d["changes"]) or "none") for d in days["days"]))
        return EXIT_OK

    summary = simulate(
        a.output, seed=a.seed, duration_s=a.duration, image_rate_hz=a.image_rate, noise_scale=a.noise_scale,
        wall_codes=a.wall_codes, sizeless_labels=a.sizeless_labels, profile=a.profile,
        camera_rate_hz=a.camera_rate, exposure_ms=a.exposure_ms,
    )
    print(_json(summary) if a.json else "\n".join(f"{k}: {v}" for k, v in summary.items()))
    return EXIT_OK


def cmd_inspect(a: argparse.Namespace) -> int:
    from holoslam.jobs import inspect_log_file

    text, data = inspect_log_file(a.log, mapping=a.mapping)
    print(_json(data) if a.json else text)
    return EXIT_OK


def _compile_kernels_first(quiet: bool) -> Any:
    """Before a run: when numba's cache lacks recorded kernels (the first run after an install), say so once
    and compile them in parallel processes: the front end's before the run starts, the later stages' while it
    goes on (``holoslam.warmup``); later runs find them cached and print nothing. Returns the pool to shut down
    after the run, or None."""
    from holoslam.warmup import compile_in_background, estimate_seconds, pending

    todo = pending()
    if not todo:
        return None
    if not quiet:
        _err(f"compiling holoslam's kernels, once per install: ~{estimate_seconds(todo):.0f} s "
             f"({len(todo)} kernel signatures, in parallel; 'holoslam warmup' does it ahead)")
    return compile_in_background(todo)


def cmd_warmup(a: argparse.Namespace) -> int:
    from holoslam.warmup import load_signatures, pending, warm_up

    todo = load_signatures() if a.all else pending()
    if not todo:
        print("holoslam's kernels are compiled (numba's cache holds every recorded signature)")
        return EXIT_OK
    t0 = time.perf_counter()
    done = warm_up(todo, workers=a.workers)
    failed = [d for d in done if d[3]]
    for module, function, _s, error in failed:
        _err(f"warmup: {module}.{function}: {error} (the run compiles it on first use)")
    print(f"compiled {len(done) - len(failed)} kernel signatures of "
          f"{len({d[0] for d in done})} modules in {time.perf_counter() - t0:.1f} s")
    return EXIT_OK


def cmd_run(a: argparse.Namespace) -> int:
    from holoslam.batch import collect_logs
    from holoslam.config import load_run_config
    from holoslam.run_jobs import run_logs

    config = load_run_config(a.config)
    logs = collect_logs(a.logs)
    if not logs:
        raise ConfigError(
            f"no logs found in {', '.join(map(str, a.logs))}; give .mcap files or folders of them"
        )
    compiling = _compile_kernels_first(a.quiet or a.json)
    progress = Progress(quiet=a.quiet or a.json)
    try:
        if a.map is not None:
            outcome = _run_into_store(a, logs, config, progress)
        else:
            outcome = run_logs(logs, a.output, config, workers=a.workers, scheduler=a.scheduler,
                               progress=progress, force=a.force)
    finally:
        if compiling is not None:
            compiling.shutdown(wait=True, cancel_futures=True)
    if a.json:
        print(_json(outcome))
    elif not a.quiet:
        print(outcome["text"])
    return EXIT_OK if outcome["ok"] else EXIT_FAILED


def cmd_demo(a: argparse.Namespace) -> int:
    from holoslam.config import load_run_config
    from holoslam.run_jobs import run_demo

    compiling = _compile_kernels_first(a.quiet or a.json)
    progress = Progress(quiet=a.quiet or a.json)
    try:
        outcome = run_demo(a.output, load_run_config(a.config), progress=progress)
    finally:
        if compiling is not None:
            compiling.shutdown(wait=True, cancel_futures=True)
    if a.json:
        print(_json(outcome))
    elif not a.quiet:
        print(outcome["text"])
    return EXIT_OK if outcome["ok"] else EXIT_FAILED


def _run_into_store(a: argparse.Namespace, logs: list, config: Any, progress: Progress) -> dict:
    """``holoslam run LOG --map STORE -o OUT``: one log, a new session of the store."""
    from holoslam.run_jobs import run_session_to_folder

    if len(logs) != 1 or a.scheduler is not None:
        raise ConfigError(f"--map takes one log at a time (got {len(logs)}); run each log of a home in turn, "
                          "oldest first")
    return run_session_to_folder(logs[0], a.output, a.map, config, progress)


def cmd_objects(a: argparse.Namespace) -> int:
    from holoslam.lifelong.export import object_history

    hist = object_history(a.store, object_id=a.id, at=a.at)
    if a.now and a.id:
        from holoslam.lifelong.export import store_export, where_now

        now = where_now(store_export(a.store), a.id)
        print(_json({**hist.to_dict(), "now": now}) if a.json else hist.text() + "\n" + now["text"])
        return EXIT_OK
    print(_json(hist.to_dict()) if a.json else hist.text())
    return EXIT_OK


def cmd_solve(a: argparse.Namespace) -> int:
    from holoslam.jobs import solve_graph_file

    summary = solve_graph_file(
        a.input,
        a.output,
        tum=a.tum,
        method=a.method,
        init=a.init,
        kernel=a.kernel,
        kernel_parameter=a.kernel_parameter,
        noise=a.noise,
    )
    d = summary.to_dict()
    print(_json(d) if a.json else _solve_text(d))
    return EXIT_OK


def _g(x: float | None) -> str:
    return "-" if x is None else f"{x:.6g}"


def _starts_lines(d: dict) -> list[str]:
    """The starts of ``holoslam solve --init auto``: what each reached, whether they agree, and why the incremental
    start ran or not."""
    lines = []
    for s in d["starts"]:
        if s["failure"]:
            lines.append(f"  {s['start']}: failed ({s['failure']})")
            continue
        how = f"E {_g(s['final_error'])} after {s['iterations']} iterations, {s['seconds']:.2f} s"
        if s["start"] == d["initialisation"]:
            how += ", kept"
        elif s["reached"]:
            how += f", reached the {s['reached']} start's solution (stopped there)"
        else:
            how += f", poses up to {_g(s['max_dxy_m'])} m / {_g(s['max_dtheta_rad'])} rad from the kept"
        lines.append(f"  {s['start']}: {how}")
    lines += [f"  {name}: not solved ({why})" for name, why in d["starts_skipped"]]
    agree = {
        True: "yes: every start ends at the kept solution's error",
        False: "no: the lowest final error is kept",
        None: "only one start ran" + (" (above: why the others did not)" if d["starts_skipped"] else ""),
    }
    lines.append(f"starts_agree: {agree[d['starts_agree']]}")
    fits = f"{d['beyond_chi2']} of {d['measurements']} measurements beyond the 99.99% chi-square bound"
    if d["fallback"] is None:
        lines.append(f"fit: {fits}")
    elif d["fallback_ran"]:
        lines.append(
            f"{d['fallback']}: ran, because the best of the starts above left more than {d['beyond_limit']}"
            f" measurements beyond the 99.99% chi-square bound; now {fits}"
        )
    else:
        lines.append(
            f"{d['fallback']}: not run, the kept solution fits the measurements ({fits}; more than "
            f"{d['beyond_limit']} would run it)"
        )
    return lines


def _solve_text(d: dict) -> str:
    lines = [
        f"{k}: {v}"
        for k, v in d.items()
        if k
        not in (
            "starts",
            "starts_skipped",
            "starts_agree",
            "beyond_chi2",
            "measurements",
            "beyond_limit",
            "fallback",
            "fallback_ran",
            "candidates",
        )
    ]
    if "starts" in d:
        lines.append("starts:")
        lines += _starts_lines(d)
    return "\n".join(lines)


def cmd_plan(a: argparse.Namespace) -> int:
    from holoslam.run_jobs import plan_to_object

    route = plan_to_object(a.run, a.to, from_xy=a.from_xy)
    if a.json:
        print(_json(route))
    else:
        print(route["text"])
    return EXIT_OK


def cmd_export(a: argparse.Namespace) -> int:
    from holoslam.run_jobs import export_run

    if a.run.is_file():  # a map store: the merged map, every session's trajectory, the objects
        from holoslam.io.store_export import write_store_export
        from holoslam.lifelong.export import store_export

        if a.to is None:
            raise ConfigError(f"{a.run} is a map store: name the folder to export it into with --to DIR")
        print("\n".join(str(p) for p in write_store_export(store_export(a.run), a.to)))
        return EXIT_OK
    written = export_run(a.run, a.to, formats=a.formats)
    print("\n".join(str(p) for p in written))
    return EXIT_OK


def cmd_datasets(a: argparse.Namespace) -> int:
    from holoslam.jobs import list_datasets

    rows = list_datasets()
    if a.json:
        print(_json(rows))
        return EXIT_OK
    for r in rows:
        where = r.get("path") or f"not found here; {r.get('source') or 'see datasets/manifest.yaml'}"
        print(f"{r['name']:<20} {r.get('kind', ''):<9} {where}")
    print("(external datasets are looked up in the folders of $HOLOSLAM_DATA)")
    return EXIT_OK


def cmd_tags(a: argparse.Namespace) -> int:
    from holoslam.jobs import decode_tags

    failed = 0
    for item in decode_tags(a.images):
        if "payload" not in item:
            failed += 1
            _err(item["error"])
            continue
        if a.json:
            print(_json(item, indent=None))
        else:
            what = (
                f"label {item['label']['id']} ({item['label']['type']})" if item.get("label") else "foreign"
            )
            corners = "corners refined" if item.get("refined") else "corners as decoded"
            print(f"{item['image']}: {what}: {item['payload']!r} [{item['decoder']}, {corners}]")
    return EXIT_FAILED if failed and failed == len(a.images) else EXIT_OK


def _topology_config(a: argparse.Namespace):
    """(topology, holographic, robot) sections for ``holoslam topology``: the run configuration's (``--config``;
    without one the run's defaults, read without loading a run's whole configuration, and no robot: no objects
    to reach) with the topology options given on the command line: one set of defaults for ``holoslam run``
    and ``holoslam topology``."""
    import dataclasses

    if a.config is not None:
        from holoslam.config import load_run_config

        cfg = load_run_config(a.config)
        tc, hc, robot = cfg.topology, cfg.holographic, cfg.robot
    else:
        from holoslam.maps.settings import HolographicConfig, TopologyConfig

        tc, hc, robot = TopologyConfig(), HolographicConfig(), None
    cleaning = tc.cleaning
    over = {
        k: v
        for k, v in (
            ("min_free_area_m2", a.min_free_area),
            ("min_obstacle_area_m2", a.min_obstacle_area),
            ("unknown_islands", a.unknown_islands),
        )
        if v is not None
    }
    if over:
        cleaning = dataclasses.replace(cleaning, **over)
    top = {k: v for k, v in (("close_cells", a.close_cells), ("erode_cells", a.erode_cells)) if v is not None}
    return dataclasses.replace(tc, cleaning=cleaning, **top), hc, robot


def cmd_topology(a: argparse.Namespace) -> int:
    from holoslam.jobs import map_topology

    topology, holographic, robot = _topology_config(a)
    result = map_topology(
        a.map, a.output, topology=topology, holographic=holographic, robot=robot, rooms_png=a.rooms, png=a.png
    )
    print(_json(result.to_dict()) if a.json else result.to_text())
    return EXIT_OK


def cmd_evaluate(a: argparse.Namespace) -> int:
    from holoslam.jobs import evaluate_trajectory

    ev = evaluate_trajectory(
        a.target, relations=a.relations, truth=a.truth, max_dt_s=a.max_dt, rpe_delta_s=a.rpe_delta, frame=a.frame
    )
    if a.json:
        print(json.dumps(ev.to_dict(), indent=2))
    else:
        lines = [f"{ev.trajectory} ({ev.poses} poses) against {ev.reference}"]
        for result in (ev.relations, ev.truth):
            if result is not None:
                lines.append(result.to_text())
        print("\n".join(lines))
    if not ev.ok:
        _err(
            f"no relation of {ev.reference} has a pose of {ev.trajectory} within {a.max_dt:g} s of both "
            "stamps; write the trajectory at the scan stamps (holoslam run does) or raise --max-dt"
        )
        return EXIT_FAILED
    return EXIT_OK


def cmd_config(a: argparse.Namespace) -> int:
    from holoslam.config import dump_run_config, load_run_config

    if not a.dump:
        _err("say what to do with the configuration: --dump writes every setting as YAML")
        return EXIT_BAD_INPUT
    text = dump_run_config(load_run_config(a.config))
    if a.output is None:
        sys.stdout.write(text)
        return EXIT_OK
    try:
        a.output.write_text(text, encoding="utf-8")
    except OSError as e:
        _err(f"cannot write {a.output}: {e.strerror or e}")
        return EXIT_BAD_INPUT
    return EXIT_OK


# ---------------------------------------------------------------------------------------------- parser


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
                   "a different start each day, the truth in days.json (holoslam.sim.days)")
    s.add_argument("--building", action="store_true",
                   help="a large building instead of the household: a 350 m floor of long corridors and 300+ rooms, "
                   "a 1.4 Hz 180-beam laser, 80 minutes unless --duration (holoslam.sim.building)")
    s.add_argument("--changes", type=int, nargs=2, default=[5, 10], metavar=("LO", "HI"),
                   help="with --days: changes per day, drawn from LO..HI (default 5 10)")
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


def main(argv: Sequence[str] | None = None) -> int:
    # holoslam reports bad images itself; OpenCV's own log lines would only repeat it
    os.environ.setdefault("OPENCV_LOG_LEVEL", "OFF")
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except PlanningError as e:
        _err(str(e))
        return EXIT_FAILED
    except HoloslamError as e:
        _err(str(e))
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        _err("interrupted")
        return 130
    except BrokenPipeError:
        return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
