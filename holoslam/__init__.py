"""holoslam: a factor-graph SLAM backend for household service robots, built on GTSAM.

Importing this package is cheap and has no side effects: heavy modules (gtsam, OpenCV, mcap, matplotlib) are
imported by the functions that need them. The public API is reached through lazy attributes, each imported on
first use::

    import holoslam

    result = holoslam.run(holoslam.bundled_household_log(), holoslam.RunConfig())   # RunResult
    print(result.report.text())                                                     # RunReport
    saved = holoslam.load_run("out/household")                                       # SavedRun
    sim = holoslam.simulate_household(holoslam.SimConfig(seed=2, duration_s=60))     # SimulatedRun
    fig = holoslam.viz.map_figure(result.grid, topology=result.topology)             # submodules, lazily

Names (see each one's docstring): the main job ``run``, ``RunConfig``, ``RunResult``, ``run_log_to_folder``,
``format_run_report``, ``load_run_config``; saved runs ``load_run``, ``SavedRun``; logs ``read_log``,
``bundled_household_log``, ``find_dataset``; simulation ``simulate_household``, ``simulate_to_file``,
``SimConfig``; graphs ``read_g2o``, ``solve_g2o_file``; and the submodules listed in ``SUBMODULES``.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

# public name -> module that defines it (imported on first access)
_LAZY: dict[str, str] = {
    "run": "holoslam.pipeline",
    "RunConfig": "holoslam.config",
    "RunResult": "holoslam.pipeline",
    "run_log_to_folder": "holoslam.run_jobs",
    "run_logs": "holoslam.run_jobs",
    "format_run_report": "holoslam.report",
    "load_run_config": "holoslam.config",
    "load_run": "holoslam.io.run_folder",
    "SavedRun": "holoslam.io.run_folder",
    "write_run": "holoslam.io.run_folder",
    "read_log": "holoslam.io.mcap",
    "bundled_household_log": "holoslam.io.datasets",
    "find_dataset": "holoslam.io.datasets",
    "simulate_household": "holoslam.sim",
    "simulate_to_file": "holoslam.sim",
    "SimConfig": "holoslam.sim",
    "SimulatedRun": "holoslam.sim",
    "read_g2o": "holoslam.io.g2o",
    "solve_g2o_file": "holoslam.jobs",
}

# submodules reachable as attributes (``holoslam.viz``) without an explicit ``import holoslam.viz``
SUBMODULES: tuple[str, ...] = (
    "batch",
    "cli",
    "config",
    "errors",
    "evaluate",
    "frames",
    "geometry",
    "graph",
    "io",
    "maps",
    "pipeline",
    "planning",
    "sim",
    "solve",
    "submaps",
    "types",
    "viz",
    "vision",
)

__all__ = [  # the names of _LAZY, spelled out for linters and ``from holoslam import *``
    "__version__",
    "SUBMODULES",
    "run",
    "RunConfig",
    "RunResult",
    "run_log_to_folder",
    "run_logs",
    "format_run_report",
    "load_run_config",
    "load_run",
    "SavedRun",
    "write_run",
    "read_log",
    "bundled_household_log",
    "find_dataset",
    "simulate_household",
    "simulate_to_file",
    "SimConfig",
    "SimulatedRun",
    "read_g2o",
    "solve_g2o_file",
]

if TYPE_CHECKING:  # for type checkers and IDEs only; nothing is imported at run time
    from holoslam.config import RunConfig, load_run_config
    from holoslam.io.datasets import bundled_household_log, find_dataset
    from holoslam.io.g2o import read_g2o
    from holoslam.io.mcap import read_log
    from holoslam.io.run_folder import SavedRun, load_run, write_run
    from holoslam.jobs import solve_g2o_file
    from holoslam.pipeline import RunResult, run
    from holoslam.report import format_run_report
    from holoslam.run_jobs import run_log_to_folder, run_logs
    from holoslam.sim import SimConfig, SimulatedRun, simulate_household, simulate_to_file


def __getattr__(name: str) -> Any:
    """Import a public name or a submodule on first access (PEP 562) and cache it in the package namespace.

    ``holoslam.solve`` is the submodule (the optimiser module); ``solve_g2o_file`` (from ``holoslam.jobs``) is a top-level name.
    """
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
    elif name in SUBMODULES:
        value = importlib.import_module(f"holoslam.{name}")
    else:
        raise AttributeError(
            f"module 'holoslam' has no attribute {name!r}; public names: {', '.join(sorted(_LAZY))}; "
            f"submodules: {', '.join(SUBMODULES)}"
        )
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY) | set(SUBMODULES))
