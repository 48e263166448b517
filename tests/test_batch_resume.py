"""A batch resumes: restarted after an interruption it runs only the logs whose folders are not complete, says
"up to date" for the others, ends with a table and batch.json; --force runs every log again."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from holoslam.cli import main
from holoslam.io.run_manifest import complete

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture()
def count_runs(monkeypatch):
    """The logs the pipeline runs in this process (a batch with --workers 1 runs them here)."""
    import holoslam.pipeline

    ran: list[str] = []
    real = holoslam.pipeline.run

    def counting(log, *a, **k):
        ran.append(Path(log).name)
        return real(log, *a, **k)

    monkeypatch.setattr(holoslam.pipeline, "run", counting)
    return ran


def _complete(out: Path) -> set[str]:
    return {p.name for p in out.iterdir() if p.is_dir() and not p.name.startswith(".") and complete(p)}


def test_an_interrupted_batch_of_20_logs_restarted_runs_only_the_logs_not_done(
    twenty_short_logs, tmp_path, capsys, count_runs
):
    folder, logs, cfg = twenty_short_logs
    out = tmp_path / "out"
    argv = ["run", str(folder), "-o", str(out), "--config", str(cfg), "--workers", "1"]
    # the batch in another process, killed (SIGKILL: no clean-up of any kind) once 7 folders are complete
    child = subprocess.Popen(
        [sys.executable, "-m", "holoslam.cli", *argv, "-q"],
        env={**os.environ, "PYTHONPATH": str(REPO)},
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and child.poll() is None:
        # folders in place (not the hidden one a log is being written into, which holds run.json before its swap)
        if out.is_dir() and sum(not p.name.startswith(".") and (p / "run.json").is_file() for p in out.iterdir()) >= 7:
            break
        time.sleep(0.02)
    os.kill(child.pid, signal.SIGKILL)
    child.wait()
    done_before = _complete(out)
    assert 7 <= len(done_before) < 20, len(done_before)
    assert not (out / "batch.json").exists()  # the batch never finished

    assert main([*argv, "--json"]) == 0
    outcome = json.loads(capsys.readouterr().out)
    assert sorted(count_runs) == sorted(f"{p.name}.mcap" for p in out.iterdir() if p.name not in done_before
                                        and p.is_dir() and not p.name.startswith("."))
    assert len(count_runs) == 20 - len(done_before)  # only the logs not done ran
    status = {Path(r["log"]).stem: r["status"] for r in outcome["logs"]}
    assert {k for k, v in status.items() if v == "up to date"} == done_before
    assert outcome["counts"] == {"done": 20 - len(done_before), "up to date": len(done_before), "failed": 0}
    assert _complete(out) == {p.stem for p in logs}
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")]  # the killed log's temporary folder
    batch = json.loads((out / "batch.json").read_text())
    assert batch["counts"] == outcome["counts"] and len(batch["logs"]) == 20

    count_runs.clear()  # again: nothing to do, said per log and in the table
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert count_runs == []
    assert "20 logs into" in captured.out and "0 done, 20 up to date, 0 failed" in captured.out
    assert captured.err.count("up to date") == 20


def test_a_changed_log_or_configuration_or_force_runs_again(twenty_short_logs, tmp_path, capsys, count_runs):
    folder, logs, cfg = twenty_short_logs
    two = tmp_path / "two"
    two.mkdir()
    for p in logs[:2]:
        (two / p.name).write_bytes(p.read_bytes())
    out = tmp_path / "out"
    argv = ["run", str(two), "-o", str(out), "--config", str(cfg), "--workers", "1", "-q"]
    assert main(argv) == 0 and len(count_runs) == 2
    assert main(argv) == 0 and len(count_runs) == 2  # up to date
    assert main([*argv, "--force"]) == 0 and len(count_runs) == 4
    (two / logs[0].name).write_bytes(logs[5].read_bytes())  # another drive under the same name
    assert main(argv) == 0 and count_runs[4:] == [logs[0].name]
    other = tmp_path / "other.yaml"
    other.write_text(cfg.read_text() + "grid:\n  resolution: 0.1\n")
    assert main([*argv[:4], "--config", str(other), *argv[6:]]) == 0 and len(count_runs) == 7
