"""The light commands import only what their job uses: ``holoslam --help`` neither numpy nor gtsam, ``holoslam
solve`` no part of the pipeline (front end, vision, maps, numba kernels, OpenCV, the simulator), and inspect,
tags, topology, evaluate and datasets not the pipeline either. Each case runs in a fresh interpreter."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

PIPELINE = ("holoslam.pipeline", "holoslam.submaps", "holoslam.sim", "holoslam.planning", "holoslam.batch")


def _modules(argv: list[str]) -> set[str]:
    code = (
        "import io, json, sys, contextlib\n"
        "from holoslam.cli import main\n"
        "out = io.StringIO()\n"
        "with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):\n"
        "    try:\n"
        f"        main({argv!r})\n"
        "    except SystemExit:\n"
        "        pass\n"
        "print(json.dumps(sorted(sys.modules)))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return set(json.loads(r.stdout.strip().splitlines()[-1]))


def _loaded(mods: set[str], prefixes: tuple[str, ...]) -> list[str]:
    return sorted(m for m in mods if any(m == p or m.startswith(p + ".") for p in prefixes))


def test_help_imports_neither_numpy_nor_gtsam():
    mods = _modules(["--help"])
    assert not _loaded(mods, ("numpy", "gtsam", "holoslam.jobs", *PIPELINE))


def test_solve_imports_no_part_of_the_pipeline(tmp_path):
    g = tmp_path / "g.g2o"
    g.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n")
    mods = _modules(["solve", str(g), "-o", str(tmp_path / "o.g2o")])
    assert "gtsam" in mods and "holoslam.solve" in mods
    heavy = ("numba", "cv2", "scipy", "matplotlib", "networkx", "yaml", "mcap", "numpy.random")
    assert not _loaded(mods, (*PIPELINE, "holoslam.vision", "holoslam.maps", "holoslam.io.mcap", *heavy))


@pytest.mark.parametrize("command", ["inspect", "evaluate", "datasets", "tags", "topology"])
def test_light_commands_do_not_import_the_pipeline(command, tmp_path):
    from holoslam.io.datasets import bundled_household_log

    tum = tmp_path / "a.tum"
    tum.write_text("0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n")
    (tmp_path / "map.pgm").write_bytes(b"P5\n4 4\n255\n" + bytes([254] * 16))
    (tmp_path / "map.yaml").write_text(
        "image: map.pgm\nresolution: 0.1\norigin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.196\nnegate: 0\n"
    )
    argv = {
        "inspect": ["inspect", str(bundled_household_log())],
        "evaluate": ["evaluate", str(tum), "--truth", str(tum)],
        "datasets": ["datasets"],
        "tags": ["tags", str(tum)],  # not an image: an error line, the command still ran
        "topology": ["topology", str(tmp_path / "map.yaml"), "-o", str(tmp_path / "t.graphml")],
    }[command]
    mods = _modules(argv)
    assert "holoslam.jobs" in mods
    assert not _loaded(mods, PIPELINE)
    if command in ("inspect", "evaluate", "tags", "topology"):
        assert not _loaded(mods, ("gtsam", "holoslam.solve", "holoslam.graph"))


def test_cli_module_runs_as_a_script():
    r = subprocess.run(
        [sys.executable, "-m", "holoslam.cli", "solve", "--help"], capture_output=True, text=True
    )
    assert r.returncode == 0 and "--init" in r.stdout and "chordal" in r.stdout
    assert Path(sys.executable).exists()


def test_the_program_returns_the_commands_code_and_skips_the_last_collection(monkeypatch):
    import gc

    import holoslam.cli as cli

    frozen = []
    monkeypatch.setattr(cli, "main", lambda argv=None: 2)
    monkeypatch.setattr(gc, "freeze", lambda: frozen.append(True))
    assert cli.console() == 2 and frozen == [True]
