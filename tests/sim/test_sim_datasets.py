"""The dataset manifest and lookup (holoslam.io.datasets) and the ROS 2 message definitions (ros2defs)."""

from __future__ import annotations

import shutil

import pytest

from holoslam.errors import IngestError
from holoslam.io import datasets
from holoslam.io.ros2defs import MSG_TYPES, dependencies, msgdef


def test_manifest_lists_the_bundled_log_and_public_datasets():
    m = datasets.load_manifest()
    assert m["household_small"].where == "bundled" and len(m["household_small"].sha256) == 64
    assert "holoslam simulate" in m["household_small"].extra["cli_equivalent"]
    assert {"victoria_park", "w10000"} <= {n for n, e in m.items() if e.where == "gtsam"}
    bench = {"intel", "CSAIL", "M3500", "city10000", "MITb", "FR079", "FRH", "manhattan", "ais2klinik"}
    assert bench <= {n for n, e in m.items() if e.where == "external"}
    for e in m.values():
        assert e.licence, e.name


def test_bundled_log_is_found_and_verified():
    p = datasets.bundled_household_log()
    assert p.is_file() and p.stat().st_size <= 4 * 1024 * 1024
    assert datasets.sha256_of(p) == datasets.load_manifest()["household_small"].sha256


def test_a_modified_bundled_log_is_refused(tmp_path, monkeypatch):
    src = datasets.datasets_dir()
    (tmp_path / "datasets").mkdir()
    shutil.copy(src / "manifest.yaml", tmp_path / "datasets" / "manifest.yaml")
    data = (src / "household_small.mcap").read_bytes()
    (tmp_path / "datasets" / "household_small.mcap").write_bytes(data[: len(data) // 2])
    monkeypatch.setattr(datasets, "datasets_dir", lambda: tmp_path / "datasets")
    with pytest.raises(IngestError, match="sha256"):
        datasets.bundled_household_log()
    (tmp_path / "datasets" / "household_small.mcap").unlink()
    with pytest.raises(IngestError, match="not found"):
        datasets.bundled_household_log()


def test_find_dataset_in_the_gtsam_wheel_and_in_holoslam_data(tmp_path, monkeypatch):
    vp = datasets.find_dataset("victoria_park")
    assert vp is not None and vp.name == "victoria_park.txt" and vp.is_file()
    monkeypatch.setenv(datasets.DATA_ENV, "")
    assert datasets.find_dataset("intel") is None
    (tmp_path / "intel.g2o").write_text("VERTEX_SE2 0 0 0 0\n")
    monkeypatch.setenv(datasets.DATA_ENV, str(tmp_path))
    assert datasets.find_dataset("intel") == tmp_path / "intel.g2o"
    assert datasets.find_dataset("no_such_dataset") is None


def test_malformed_manifest_says_what(tmp_path):
    p = tmp_path / "manifest.yaml"
    p.write_text("datasets:\n  - name: x\n    where: somewhere\n    file: x.bin\n")
    with pytest.raises(IngestError, match="where='somewhere'"):
        datasets.load_manifest(p)
    with pytest.raises(IngestError, match="cannot be read"):
        datasets.load_manifest(tmp_path / "missing.yaml")


def test_msgdefs_have_ros2msg_dependency_sections():
    text = msgdef("nav_msgs/msg/Odometry")
    assert text.startswith("std_msgs/Header header\n")
    for dep in (
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/Quaternion",
        "geometry_msgs/TwistWithCovariance",
        "geometry_msgs/Vector3",
    ):
        assert f"{'=' * 80}\nMSG: {dep}\n" in text
    assert dependencies("std_msgs/msg/String") == []
    with pytest.raises(KeyError, match="no ROS 2 definition"):
        msgdef("foo_msgs/msg/Bar")


def test_every_definition_round_trips_through_mcap_ros2(tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from mcap_ros2.writer import Writer

    assert {"sensor_msgs/msg/MagneticField", "geometry_msgs/msg/PoseWithCovarianceStamped"} <= set(MSG_TYPES)
    path = tmp_path / "defs.mcap"
    samples = {
        "sensor_msgs/msg/MagneticField": {
            "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "mag"},
            "magnetic_field": {"x": 2e-5, "y": 0.0, "z": -4e-5},
            "magnetic_field_covariance": [1e-12] + [0.0] * 8,
        },
        "geometry_msgs/msg/PoseWithCovarianceStamped": {
            "header": {"stamp": {"sec": 3, "nanosec": 4}, "frame_id": "map"},
            "pose": {
                "pose": {
                    "position": {"x": 1.5, "y": -2.0, "z": 0.0},
                    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                },
                "covariance": [0.1] + [0.0] * 35,
            },
        },
    }
    with open(path, "wb") as f:
        w = Writer(f)
        for i, t in enumerate(MSG_TYPES):
            schema = w.register_msgdef(t, msgdef(t))
            w.write_message(f"/t{i}", schema, samples.get(t, {}), log_time=i, publish_time=i)
        w.finish()
    with open(path, "rb") as f:
        got = {
            s.name: m
            for s, _, _, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()
        }
    assert set(got) == set(MSG_TYPES)
    assert got["sensor_msgs/msg/MagneticField"].magnetic_field.z == -4e-5
    p = got["geometry_msgs/msg/PoseWithCovarianceStamped"]
    assert p.pose.pose.position.y == -2.0 and p.pose.covariance[0] == 0.1 and p.header.frame_id == "map"
