"""Short simulated logs for the fault tests (atomic run folders, resumable batches, cluster faults).

A 6 s drive of the reference household without a camera: simulated in ~0.45 s and run in ~0.4 s in a warm
process (measured 2026-12-03), different seeds giving different trajectories."""

from __future__ import annotations

from pathlib import Path

FAST_CONFIG = "pictures: false\nresults_mcap: false\n"
"""A run configuration without pictures and results MCAP (matplotlib would be most of a short log's run)."""

DURATION_S = 6.0


def write_short_logs(folder: Path, n: int, first_seed: int = 100) -> list[Path]:
    """``n`` short simulated logs ``log00.mcap``.. (seeds ``first_seed``..) in ``folder``."""
    from holoslam.sim import SimConfig, simulate_to_file

    folder.mkdir(parents=True, exist_ok=True)
    logs = []
    for k in range(n):
        path = folder / f"log{k:02d}.mcap"
        simulate_to_file(path, SimConfig(seed=first_seed + k, duration_s=DURATION_S, image_rate_hz=0.0))
        logs.append(path)
    return logs


def fast_config(folder: Path) -> Path:
    """A YAML run configuration file holding ``FAST_CONFIG``."""
    path = folder / "fast.yaml"
    path.write_text(FAST_CONFIG)
    return path
