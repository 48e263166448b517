"""The commands of ``holoslam``: each calls one library function, prints its result (text or ``--json``) and
returns the exit code (:mod:`holoslam.cli_output`). The arguments are :mod:`holoslam.cli_parser`'s."""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from typing import Any

from holoslam.cli_output import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK, Progress, _err, _json
from holoslam.errors import ConfigError


def cmd_simulate(a: argparse.Namespace) -> int:
    from holoslam.run_jobs import simulate, simulate_building, simulate_days

    if a.building:
        summary = simulate_building(a.output, seed=a.seed, duration_s=a.duration)
        print(_json(summary) if a.json else "\n".join(f"{k}: {v}" for k, v in summary.items()))
        return EXIT_OK

    if a.days is not None:
        days = simulate_days(a.output, a.days, seed=a.seed, duration_s=a.duration, changes=tuple(a.changes),
                             furniture=None if a.furniture is None else tuple(a.furniture))
        print(_json(days) if a.json else "\n".join(
            f"day {d['day']}: {a.output / d['log']}, start {d['start_pose']}, changes: "
            + (", ".join(f"{c['id']} {c['change']}" for c in d["changes"]) or "none")
            + "".join(f"; {m['name']} moved {m['shift_m']:.2f} m, turned {m['turn_deg']:.0f} deg"
                      for m in d["furniture"]) for d in days["days"]))
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
    if a.map is not None:
        return _compiled_run(a, lambda progress: _run_into_store(a, logs, config, progress))
    return _compiled_run(a, lambda progress: run_logs(logs, a.output, config, workers=a.workers,
                                                      scheduler=a.scheduler, progress=progress, force=a.force))


def cmd_demo(a: argparse.Namespace) -> int:
    from holoslam.config import load_run_config
    from holoslam.run_jobs import run_demo

    config = load_run_config(a.config)
    return _compiled_run(a, lambda progress: run_demo(a.output, config, progress=progress))


def _compiled_run(a: argparse.Namespace, job: Callable[[Progress], dict]) -> int:
    """Run ``job`` (its outcome: ``ok``, ``text``) with the kernels compiling beside it when numba's cache lacks
    them (``_compile_kernels_first``), then print the outcome as ``--json`` / ``--quiet`` ask."""
    compiling = _compile_kernels_first(a.quiet or a.json)
    try:
        outcome = job(Progress(quiet=a.quiet or a.json))
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
