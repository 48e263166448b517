"""The jobs around runs, one library call per command: run logs into output folders (one, or many in parallel),
write a simulated log, and route in or re-export a saved run folder. Each writes only through ``holoslam.io``
and only under the folder the caller named; the run itself is ``holoslam.pipeline.run``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from holoslam.errors import ConfigError, IngestError, PlanningError
from holoslam.timing import Progress

if TYPE_CHECKING:
    from holoslam.config import RunConfig

__all__ = ["run_log_to_folder", "run_config_hash", "run_logs", "run_session_to_folder", "run_demo", "DEMO_OUTPUT",
           "simulate", "simulate_days", "plan_to_object", "export_run"]

DEMO_OUTPUT = "holoslam-demo"  # ``holoslam demo``'s output folder, relative to the current folder


def _noop(*_a: Any, **_k: Any) -> None:
    return None


def run_config_hash(config: RunConfig | None) -> str:
    """The hash a run folder's manifest records for its configuration (every setting and the mapping file's
    bytes): two runs with equal hashes ran with the same settings."""
    from holoslam.config import RunConfig, to_mapping
    from holoslam.io.run_manifest import config_sha256

    cfg = config if config is not None else RunConfig()
    return config_sha256(to_mapping(cfg), cfg.mapping)


def run_log_to_folder(
    log: str, out_dir: str, config: RunConfig | None = None, progress: Progress | None = None
) -> dict[str, Any]:
    """Run one log and write its output folder, whole or not at all (a previous folder of that name stays until
    the new one is complete; see :func:`holoslam.io.run_folder.write_run`); returns a short summary (for the
    batch runner)."""
    from holoslam.io.run_folder import prepare_run_folder, write_run
    from holoslam.io.run_manifest import input_fingerprint
    from holoslam.pipeline import run

    prepare_run_folder(out_dir)  # an unwritable folder is a one-line error before the run, not after it
    fingerprint = input_fingerprint(log) if Path(log).exists() else None  # before the run: what it read
    result = run(log, config, progress)
    written = write_run(
        result,
        out_dir,
        pictures=result.config.pictures,
        results_mcap=result.config.results_mcap,
        progress=progress,
        log_fingerprint=fingerprint,
        config_hash=run_config_hash(result.config),
    )
    acc = result.report.accuracy
    return {
        "log": log,
        "out_dir": out_dir,
        "files": len(written),
        "anchors": int(len(result.wTa)),
        "objects": len(result.objects),
        "anchor_rmse_m": acc.anchors.rmse_m if acc is not None else None,
        "object_rmse_m": acc.objects.rmse_m if acc is not None and acc.objects is not None else None,
        "seconds": result.report.timings_s["total"],
        "text": result.report.text(),
    }


def run_session_to_folder(
    log: str | Path, out_dir: str | Path, store: str | Path, config: RunConfig | None = None,
    progress: Progress | None = None
) -> dict[str, Any]:
    """Run one log as a new session of the map store ``store`` (created when absent;
    ``holoslam.lifelong.session.run_session``) and write its run folder, in the store's world frame when the
    session was joined. Returns the summary ``run_logs`` returns, with the report's ``session`` object."""
    from holoslam.io.run_folder import prepare_output_folder, write_run
    from holoslam.lifelong.session import run_session

    prepare_output_folder(out_dir)
    done = run_session(log, store, config, progress=progress)
    result = done.run
    written = write_run(result, out_dir, pictures=result.config.pictures, results_mcap=result.config.results_mcap,
                        progress=progress)
    text = result.report.text() + f"\n  output: {out_dir}"
    return {"ok": True, "logs": [{"log": str(log), "out_dir": str(out_dir), "files": len(written),
                                  "anchors": int(len(result.wTa)), "objects": len(result.objects),
                                  "seconds": result.report.timings_s["total"],
                                  "session": done.summary.to_dict()}], "text": text}


def run_logs(
    logs: Sequence[Path],
    out_root: str | Path,
    config: RunConfig,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Progress | None = None,
    force: bool = False,
) -> dict[str, Any]:
    """Run one or many logs. One log writes straight into ``out_root`` (always run). Many logs (or any on a
    cluster) get one sub-folder each, processed in parallel (local processes, or a Dask cluster given its
    scheduler address); a log whose folder is complete for the same input and configuration is skipped as up
    to date unless ``force`` (:func:`holoslam.batch_resume.run_batch`: the table, ``batch.json``)."""
    from holoslam.batch_resume import run_batch
    from holoslam.io.run_folder import prepare_output_folder

    progress = progress or _noop
    if len(logs) == 1 and scheduler is None:
        try:
            summary = run_log_to_folder(str(logs[0]), str(out_root), config, progress)
        except IngestError as e:  # name the log, once
            msg = str(e)
            raise IngestError(msg if msg.startswith(str(logs[0])) else f"{logs[0]}: {msg}") from None
        return {"ok": True, "logs": [summary], "text": summary["text"] + f"\n  output: {out_root}"}
    prepare_output_folder(out_root)  # once, before any log is dispatched
    return run_batch(
        run_log_to_folder,
        logs,
        out_root,
        config,
        run_config_hash(config),
        force=force,
        workers=workers,
        scheduler=scheduler,
        progress=progress,
    )


def run_demo(
    out_dir: str | Path = DEMO_OUTPUT, config: RunConfig | None = None, progress: Progress | None = None
) -> dict[str, Any]:
    """``holoslam demo``: the main job (``run_logs``) on the bundled household log (found inside the installed
    package or the checkout's ``datasets/``, its sha256 checked), written to ``out_dir``."""
    from holoslam.config import RunConfig
    from holoslam.io.datasets import bundled_household_log

    log = bundled_household_log()
    return run_logs([log], out_dir, config or RunConfig(), progress=progress)


def simulate(
    output: str | Path,
    seed: int = 0,
    duration_s: float | None = None,
    image_rate_hz: float | None = None,
    noise_scale: float = 1.0,
    wall_codes: int = 0,
    sizeless_labels: int = 0,
    profile: str = "default",
    camera_rate_hz: float = 0.0,
    exposure_ms: float | None = None,
) -> dict[str, Any]:
    """Write a simulated reference-household log (``holoslam.sim``) to ``output``; ``wall_codes`` foreign QR codes
    on walls and ``sizeless_labels`` labels without a printed size can be added (``holoslam.sim.world``).
    ``profile``: the robot (``holoslam.sim.profiles``: default, noisy, skid-steer), ``noise_scale`` on top.
    ``camera_rate_hz`` > 0: a camera stream, every frame at that rate with motion blur over ``exposure_ms``
    (``holoslam.sim.stream``)."""
    from holoslam.sim import simulate_to_file
    from holoslam.sim.profiles import profile_config

    if noise_scale < 0 or not np.isfinite(noise_scale):
        raise ConfigError(f"--noise-scale must be a non-negative number, got {noise_scale}")
    if duration_s is not None and not duration_s > 0:
        raise ConfigError(f"--duration must be a positive number of seconds, got {duration_s}")
    if image_rate_hz is not None and not image_rate_hz >= 0:
        raise ConfigError(f"--image-rate must be >= 0 snapshots per second, got {image_rate_hz}")
    kw: dict[str, Any] = {"seed": seed, "wall_codes": wall_codes, "sizeless_labels": sizeless_labels}
    if duration_s is not None:
        kw["duration_s"] = duration_s
    if image_rate_hz is not None:
        kw["image_rate_hz"] = image_rate_hz
    if camera_rate_hz:
        kw["camera_rate_hz"] = camera_rate_hz
    if exposure_ms is not None:
        kw["camera_exposure_ms"] = exposure_ms
    cfg = profile_config(profile, **kw)
    if noise_scale != 1.0:
        cfg = cfg.with_noise_scale(noise_scale)
    out = Path(output)
    if out.parent and not out.parent.exists():
        raise ConfigError(f"folder {out.parent} does not exist; create it first")
    return simulate_to_file(out, cfg)


def simulate_building(output: str | Path, seed: int = 26, duration_s: float | None = None) -> dict[str, Any]:
    """A simulated drive through a large building (``holoslam.sim.building``: a 350 m floor, long corridors,
    many rooms, the sparse laser of a hospital's log) written to ``output``; ``duration_s`` default 80 minutes."""
    from holoslam.sim.building import simulate_building_to_file

    if duration_s is not None and not duration_s > 0:
        raise ConfigError(f"--duration must be a positive number of seconds, got {duration_s}")
    summary = simulate_building_to_file(output, duration_s=4800.0 if duration_s is None else duration_s, seed=seed)
    del summary["plan"]
    return summary


def simulate_days(output: str | Path, days: int, seed: int = 0, duration_s: float | None = None,
                  changes: tuple[int, ...] = (5, 10), furniture: tuple[int, ...] | None = None) -> dict[str, Any]:
    """``days`` simulated days of the household into the folder ``output`` (``holoslam.sim.days``); ``furniture``
    (lo, hi): pieces of furniture moved per day (None: ``days.FURNITURE_MOVES``)."""
    from holoslam.sim.days import FURNITURE_MOVES
    from holoslam.sim.days import simulate_days as _days

    if not 1 <= days <= 1000:
        raise ConfigError(f"--days must be 1..1000, got {days}")
    if len(changes) != 2 or not 0 <= changes[0] <= changes[1] <= 20:
        raise ConfigError(f"--changes LO HI must satisfy 0 <= LO <= HI <= 20, got {list(changes)}")
    if duration_s is not None and not duration_s > 0:
        raise ConfigError(f"--duration must be a positive number of seconds, got {duration_s}")
    furniture = FURNITURE_MOVES if furniture is None else furniture
    if len(furniture) != 2 or not 0 <= furniture[0] <= furniture[1] <= 5:
        raise ConfigError(f"--furniture LO HI must satisfy 0 <= LO <= HI <= 5, got {list(furniture)}")
    return _days(output, days, seed=seed, duration_s=duration_s, changes=(int(changes[0]), int(changes[1])),
                 furniture=(int(furniture[0]), int(furniture[1])))


def plan_to_object(
    run_dir: str | Path, object_id: str, from_xy: tuple[float, float] | None = None
) -> dict[str, Any]:
    """Route from a pose (default: the run's last pose) to an object in a saved run."""
    from holoslam.io.run_folder import load_run
    from holoslam.maps.holographic import CONFIRMING_SIGHTINGS
    from holoslam.planning.routes import plan_to_object as _plan

    saved = load_run(run_dir, parts=("trajectory", "holographic", "planning", "grid"))
    oid = _resolve_object(saved.holographic, object_id)
    if from_xy is not None:
        start = np.asarray(from_xy, dtype=np.float64)
    elif saved.wTb is not None and len(saved.wTb):
        start = np.asarray(saved.wTb[-1, :2], dtype=np.float64)
    else:
        raise PlanningError(f"{run_dir}: the run's trajectory is empty; give the start with --from x,y")
    route = _plan(saved.planning, saved.holographic, saved.grid, oid, start)
    obj = saved.holographic.nodes[oid]
    wp = np.asarray(route.waypoints)
    text = [
        f"route to {oid} ({obj.get('object_type', obj.get('type', '?'))}) at "
        f"({obj.get('x', float('nan')):.2f}, {obj.get('y', float('nan')):.2f}) from ({start[0]:.2f}, {start[1]:.2f})",
        "  places: " + " -> ".join(str(p) for p in route.places),
        f"  handled from: {route.goal_place}",
        "  waypoints: " + " ".join(f"({x:.2f},{y:.2f})" for x, y in wp),
        f"  length: {route.length:.2f} m",
    ]
    sightings = int(obj.get("sightings", 0))
    if 0 < sightings < CONFIRMING_SIGHTINGS:
        text.append(f"  note: {oid} was seen once (unconfirmed): its label may have been misread")
    return {
        "object": oid,
        "sightings": sightings,
        "from": [float(start[0]), float(start[1])],
        "places": [str(p) for p in route.places],
        "goal_place": route.goal_place,
        "waypoints": wp.round(4).tolist(),
        "length_m": round(float(route.length), 4),
        "text": "\n".join(text),
    }


def _resolve_object(holo: Any, id_or_type: str) -> str:
    from holoslam.maps.holographic import where_is

    if id_or_type in holo and holo.nodes[id_or_type].get("kind") == "object":
        return id_or_type
    found = where_is(holo, id_or_type) if id_or_type else []
    if not found:
        ids = sorted(n for n, d in holo.nodes(data=True) if d.get("kind") == "object")
        raise PlanningError(f"no object {id_or_type!r} in this run; known objects: {', '.join(ids)}")
    return str(found[0].get("id", found[0].get("object_id")))


def export_run(
    run_dir: str | Path, to: str | Path | None = None, formats: Sequence[str] = ("all",)
) -> list[Path]:
    """Re-export a saved run (pictures, results MCAP, graphs, TUM) into ``to`` (default: the run folder)."""
    from holoslam.io.run_folder import export_saved, load_run

    saved = load_run(run_dir)
    return export_saved(saved, Path(to) if to is not None else Path(run_dir), set(formats))
