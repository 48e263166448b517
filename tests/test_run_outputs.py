"""What a run writes and how it fails: an output folder that cannot be made is a one-line error before the
run's work; report.json and every --json print are strict JSON (no NaN / Infinity); no numpy overflow warning
from a submap grid of a robot that stood still."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from holoslam.cli import main


def _strict(text: str):
    def refuse(name):
        raise ValueError(f"{name} is not JSON")

    return json.loads(text, parse_constant=refuse)


@pytest.fixture(scope="module")
def log_without_objects(tmp_path_factory) -> Path:
    """A simulated log with ground truth (the world and its 35 objects) but no camera: no object is seen."""
    from holoslam.sim import SimConfig, simulate_to_file

    path = tmp_path_factory.mktemp("logs") / "no_camera.mcap"
    simulate_to_file(path, SimConfig(seed=7, duration_s=60.0, image_rate_hz=0.0))
    return path


@pytest.fixture()
def no_run(monkeypatch):
    """Any start of the pipeline's work fails the test: the output folder must be checked before it."""
    import holoslam.batch
    import holoslam.pipeline

    def started(*_a, **_k):
        raise AssertionError("the run started before the output folder was checked")

    monkeypatch.setattr(holoslam.pipeline, "run", started)
    monkeypatch.setattr(holoslam.batch, "run_many", started)


def _unwritable(tmp_path: Path) -> list[Path]:
    a_file = tmp_path / "a_file"
    a_file.write_text("not a folder\n")
    out = [a_file / "out", a_file / "deeper" / "out", a_file]
    if Path("/proc/self").is_dir():  # Linux: /proc refuses new folders, even to root
        out.append(Path("/proc/holoslam-out"))
    return out


def test_an_output_folder_that_cannot_be_made_is_exit_2_before_the_run(
    log_without_objects, tmp_path, capsys, no_run
):
    for out in _unwritable(tmp_path):
        assert main(["run", str(log_without_objects), "-o", str(out)]) == 2, out
        err = capsys.readouterr().err
        assert err.startswith("holoslam: ") and err.count("\n") == 1, err
        assert str(out) in err and "Traceback" not in err


def test_many_logs_into_an_unwritable_folder_is_one_error_before_any_log(
    log_without_objects, tmp_path, capsys, no_run
):
    fleet = tmp_path / "fleet"
    fleet.mkdir()
    for name in ("a.mcap", "b.mcap"):
        (fleet / name).write_bytes(log_without_objects.read_bytes())
    for out in _unwritable(tmp_path):
        assert main(["run", str(fleet), "-o", str(out), "--json"]) == 2, out
        captured = capsys.readouterr()
        assert captured.out == "" and captured.err.count("\n") == 1 and str(out) in captured.err


def test_a_failed_run_leaves_no_empty_output_folder(tmp_path, capsys):
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 20)
    out = tmp_path / "out"
    assert main(["run", str(broken), "-o", str(out)]) == 2
    assert not out.exists()


@pytest.mark.slow
def test_report_and_json_output_are_strict_json_when_a_statistic_is_undefined(
    log_without_objects, tmp_path, capsys
):
    """Ground truth lists 35 objects, none is seen: their RMSE is undefined, written as null (not NaN)."""
    out = tmp_path / "run"
    assert main(["run", str(log_without_objects), "-o", str(out), "--json"]) == 0
    printed = _strict(capsys.readouterr().out)
    report = _strict((out / "report.json").read_text())
    objects = report["accuracy"]["objects"]
    assert objects["matched"] == 0 and len(objects["missing"]) == 35
    assert objects["rmse_m"] is None and objects["max_m"] is None
    assert printed["logs"][0]["object_rmse_m"] is None
    from holoslam.io.run_folder import load_run

    assert load_run(out).report["accuracy"]["objects"]["rmse_m"] is None


def test_strict_json_of_numpy_and_non_finite_values():
    from holoslam.io.jsonsafe import dumps

    v = {
        "nan": float("nan"),
        "inf": np.float64(np.inf),
        "ninf": -math.inf,
        "arr": np.array([1.0, np.nan]),
        "i": np.int64(3),
        "b": np.bool_(True),
        "nested": [{"x": np.float32(0.5)}, (np.nan,)],
        "path": Path("a/b"),
    }
    assert _strict(dumps(v)) == {
        "nan": None,
        "inf": None,
        "ninf": None,
        "arr": [1.0, None],
        "i": 3,
        "b": True,
        "nested": [{"x": 0.5}, [None]],
        "path": "a/b",
    }


def test_submap_grid_of_a_robot_that_stood_still_does_not_overflow():
    """2000 identical scans: the free cells' log-odds fall below -709, where exp(-L) overflows float64."""
    from holoslam.submaps.segment import local_grid

    angles = np.radians(np.arange(-90.0, 91.0))
    ranges = np.full(angles.size, 2.0)
    n = 2000
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        grid = local_grid(np.zeros((n, 3)), [ranges] * n, [angles] * n, resolution=0.05)
    occ = grid.occupancy
    assert (occ == 0).sum() > 100 and (occ == 100).sum() > 50 and set(np.unique(occ)) <= {-1, 0, 100}
