"""A run folder is complete or absent: a run killed while it writes, a full disk or a read-only file system
leave the previous folder (or nothing), never a mixture of two runs; readers refuse a folder without a valid
run.json in one line."""

from __future__ import annotations

import errno
import json
import os
import pickle
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fault_logs import fast_config, write_short_logs

from holoslam.cli import main
from holoslam.io.run_manifest import MANIFEST, require_complete
from holoslam.io.trajectory import read_tum

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    """Two short logs and the complete folder of each (the previous run A, the new run B)."""
    root = tmp_path_factory.mktemp("atomic")
    log_a, log_b = write_short_logs(root / "logs", 2)
    cfg = fast_config(root)
    for log, name in ((log_a, "A"), (log_b, "B")):
        assert main(["run", str(log), "-o", str(root / name), "--config", str(cfg), "-q"]) == 0
    from holoslam.config import load_run_config
    from holoslam.pipeline import run

    with open(root / "B.pickle", "wb") as f:  # run B's result, for writers that only write
        pickle.dump(run(log_b, load_run_config(cfg)), f)
    return root, log_a, log_b, cfg


def _trajectory(folder: Path) -> np.ndarray:
    return read_tum(folder / "trajectory.tum")[1]


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.parent.iterdir() if p.name.startswith(f".{folder.name}.holoslam-"))


def _results(manifest: dict) -> dict:
    """The files of a manifest but the report's (which holds the run's timings, different at every run)."""
    return {k: v for k, v in manifest["files"].items() if not k.startswith("report.")}


def _which(folder: Path, root: Path) -> str:
    """'A' or 'B': which run the complete ``folder`` is (every file as its manifest says, and that run's)."""
    man = require_complete(folder)  # every file's size and sha256 as the manifest lists them
    assert set(man["files"]) == {p.name for p in folder.iterdir() if p.name != MANIFEST}
    for name in ("A", "B"):
        if _results(json.loads((root / name / MANIFEST).read_text())) == _results(man):
            return name
    raise AssertionError(f"{folder} is complete but neither run A nor run B")


def test_the_manifest_lists_every_file_the_input_and_the_configuration(two_runs):
    root, log_a, _, _ = two_runs
    man = json.loads((root / "A" / MANIFEST).read_text())
    files = {p.name for p in (root / "A").iterdir() if p.name != MANIFEST}
    assert set(man["files"]) == files and "trajectory.tum" in files
    assert man["input"]["size"] == log_a.stat().st_size and len(man["input"]["sha256"]) == 64
    assert len(man["config_sha256"]) == 64 and man["timings_s"]["total"] > 0
    assert man["format"] == "holoslam-run/1" and man["holoslam_version"]
    assert not _leftovers(root / "A")


def test_a_new_run_replaces_the_previous_folder_whole(two_runs, tmp_path):
    root, _, log_b, cfg = two_runs
    out = tmp_path / "run"
    shutil.copytree(root / "A", out)
    (out / "map.png").unlink()  # an extra file of the previous run must not survive into the new folder
    shutil.copy(root / "A" / "map.png", out / "map.png")
    assert main(["run", str(log_b), "-o", str(out), "--config", str(cfg), "-q"]) == 0
    assert _which(out, root) == "B" and not _leftovers(out)
    assert np.array_equal(_trajectory(out), _trajectory(root / "B"))


def test_a_folder_holding_other_files_is_not_replaced(two_runs, tmp_path, capsys):
    root, log_a, _, cfg = two_runs
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("precious\n")
    assert main(["run", str(log_a), "-o", str(mine), "--config", str(cfg), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "thesis.tex" in err
    assert (mine / "thesis.tex").read_text() == "precious\n"


def _one_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.startswith("holoslam: ") and err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize(
    ("module", "name", "code"),
    [
        ("holoslam.io.planning", "write_planning", errno.ENOSPC),  # disk full mid-write
        ("holoslam.io.grid", "write_grid_png", errno.EROFS),  # the file system turned read-only
        ("holoslam.io.run_manifest", "write_manifest", errno.ENOSPC),  # full when the manifest is written
        ("os", "fsync", errno.EIO),  # the disk failed at the flush
    ],
)
def test_disk_full_or_read_only_mid_write_keeps_the_previous_folder(
    two_runs, tmp_path, capsys, monkeypatch, module, name, code
):
    """Root ignores permissions (tests run as root here), so the failing write is an injected OSError."""
    import importlib

    root, _, log_b, cfg = two_runs
    out = tmp_path / "run"
    shutil.copytree(root / "A", out)
    mod = importlib.import_module(module)
    real = getattr(mod, name)
    calls = []

    def failing(*a, **k):
        calls.append(a)
        if name == "fsync" and len(calls) < 3:
            return real(*a, **k)
        raise OSError(code, os.strerror(code), str(out / "x" / "planning.json"))

    monkeypatch.setattr(mod, name, failing)
    assert main(["run", str(log_b), "-o", str(out), "--config", str(cfg), "-q"]) == 2
    err = _one_line(capsys)
    assert os.strerror(code) in err and "previous folder is unchanged" in err and str(out) in err
    monkeypatch.undo()
    assert _which(out, root) == "A" and not _leftovers(out)
    # nothing before: the failed run leaves no folder at all
    fresh = tmp_path / "fresh"
    monkeypatch.setattr(mod, name, failing)
    assert main(["run", str(log_b), "-o", str(fresh), "--config", str(cfg), "-q"]) == 2
    assert "nothing was written" in _one_line(capsys)
    monkeypatch.undo()
    assert not fresh.exists() and not _leftovers(fresh)


_CHILD = """
import os, pickle, signal, sys
import holoslam.io.atomic_folder as af
from holoslam.io.run_folder import write_run
stage, name, result, out = sys.argv[1:]
def checkpoint(s, n=""):
    if s == stage and n == name:
        os.kill(os.getpid(), signal.SIGKILL)
af._checkpoint = checkpoint
with open(result, "rb") as f:
    write_run(pickle.load(f), out, pictures=False, results_mcap=False)
"""

# (stage, file): after the third file, after the last file, after the manifest (before any rename), between the
# two renames of the swap (the previous folder aside, the new one not yet in), after the new folder went in
# (the previous one not yet removed); and the run's outcome at each: the previous folder or the new one
KILLS = [
    (("file", "anchors.csv"), "A"),
    (("file", "report.txt"), "A"),
    (("manifest", ""), "A"),
    (("aside", ""), "B"),
    (("in", ""), "B"),
]


def test_sigkill_at_five_moments_leaves_the_previous_or_the_new_folder(two_runs, tmp_path, capsys):
    root = two_runs[0]
    env = {**os.environ, "PYTHONPATH": f"{REPO}:{REPO / 'tests'}"}
    children = []
    for k, ((stage, name), _) in enumerate(KILLS):
        out = tmp_path / f"run{k}"
        shutil.copytree(root / "A", out)
        argv = [sys.executable, "-c", _CHILD, stage, name, str(root / "B.pickle"), str(out)]
        children.append((out, subprocess.Popen(argv, env=env, stderr=subprocess.DEVNULL)))
    for (out, child), ((stage, name), expected) in zip(children, KILLS, strict=True):
        assert child.wait(timeout=120) == -signal.SIGKILL, (stage, name)
        if stage == "aside":  # killed inside the swap: the name is empty until a reader or writer settles it
            assert not out.exists() and len(_leftovers(out)) == 2
        assert _which(out, root) == expected, (stage, name)  # require_complete settles first
        assert not _leftovers(out), (stage, name, _leftovers(out))
        assert np.array_equal(_trajectory(out), _trajectory(root / expected))
        assert main(["evaluate", str(out), "--truth", str(root / "A" / "trajectory.tum")]) == 0
        capsys.readouterr()


def test_readers_refuse_a_folder_without_a_valid_manifest(two_runs, tmp_path, capsys):
    root, _, _, _ = two_runs
    old = tmp_path / "old"  # as a holoslam before run manifests wrote it
    shutil.copytree(root / "A", old)
    (old / MANIFEST).unlink()
    mixed = tmp_path / "mixed"  # a trajectory of run B beside the rest of run A
    shutil.copytree(root / "A", mixed)
    shutil.copy(root / "B" / "trajectory.tum", mixed / "trajectory.tum")
    for folder, says in ((old, "has no run.json"), (mixed, "trajectory.tum is not the file the run wrote")):
        for argv in (
            ["evaluate", str(folder), "--truth", str(root / "A" / "trajectory.tum")],
            ["plan", str(folder), "--to", "O01"],
            ["export", str(folder), "--to", str(tmp_path / "x")],
        ):
            assert main(argv) == 2, argv
            err = _one_line(capsys)
            assert says in err and "re-run" in err, err


def test_export_into_the_run_folder_keeps_it_complete(two_runs, tmp_path, capsys):
    root, _, _, _ = two_runs
    out = tmp_path / "run"
    shutil.copytree(root / "A", out)
    assert main(["export", str(out), "--formats", "tum", "graphs"]) == 0
    capsys.readouterr()
    man = require_complete(out)
    assert "holographic.graphml" in man["files"] and not _leftovers(out)
    assert np.allclose(_trajectory(out), _trajectory(root / "A"), atol=1e-9, rtol=0)
