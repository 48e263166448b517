import os
from pathlib import Path

import pytest

from holoslam.batch import collect_logs, run_many
from holoslam.errors import ConfigError, IngestError


def count_bytes(log: str, out_dir: str, *, fail_on: str = "") -> dict:
    """A job with a real, checkable result: the size of the log, written to its output folder."""
    if Path(log).name == fail_on:
        raise IngestError(f"{log}: simulated unreadable log")
    data = Path(log).read_bytes()
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    (Path(out_dir) / "size.txt").write_text(str(len(data)))
    return {"bytes": len(data), "pid": os.getpid()}


@pytest.fixture
def logs(tmp_path):
    d = tmp_path / "fleet"
    (d / "robot2").mkdir(parents=True)
    paths = []
    for i, sub in enumerate(["", "", "robot2"]):
        p = d / sub / f"log{i}.mcap"
        p.write_bytes(b"x" * (10 + i))
        paths.append(p)
    bag = d / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (bag / "bag_0.mcap").write_bytes(b"y")
    return d, paths, bag


def test_collect_expands_folders_and_keeps_bags_whole(logs):
    d, paths, bag = logs
    found = collect_logs([d])
    assert sorted(map(str, found)) == sorted(map(str, paths + [bag]))
    with pytest.raises(ConfigError, match="does not exist"):
        collect_logs([d / "nope"])


def test_local_pool_runs_all_and_isolates_a_failure(logs, tmp_path):
    _, paths, _ = logs
    seen = []
    items = run_many(
        count_bytes,
        paths,
        tmp_path / "out",
        workers=2,
        fail_on="log1.mcap",
        on_done=lambda item, done, total: seen.append((done, total)),
    )
    assert [i.ok for i in items] == [True, False, True]
    assert "simulated unreadable log" in items[1].error
    assert items[0].summary["bytes"] == 10 and items[2].summary["bytes"] == 12
    assert (Path(items[2].out_dir) / "size.txt").read_text() == "12"
    assert sorted(seen) == [(1, 3), (2, 3), (3, 3)]
    assert len({Path(i.out_dir) for i in items}) == 3


def test_real_dask_cluster(logs, tmp_path):
    distributed = pytest.importorskip("distributed")
    _, paths, _ = logs
    with distributed.LocalCluster(
        n_workers=2, processes=False, threads_per_worker=1, dashboard_address=None
    ) as c:
        items = run_many(
            count_bytes, paths, tmp_path / "out", scheduler=c.scheduler_address, fail_on="log0.mcap"
        )
    assert [i.ok for i in items] == [False, True, True]
    assert items[2].summary["bytes"] == 12


def test_unreachable_scheduler_is_a_clear_error(logs, tmp_path):
    pytest.importorskip("distributed")
    _, paths, _ = logs
    with pytest.raises(ConfigError, match="cannot reach the Dask scheduler"):
        run_many(count_bytes, paths, tmp_path / "out", scheduler="tcp://127.0.0.1:9", connect_timeout_s=1.0)
