"""The ingestion fast paths give exactly what the reference paths give: the memory-mapped file reader vs
buffered reads (on whole, truncated and damaged files), the scalar odometry covariance rotation vs the matrix
form, and the shared CameraInfo arrays when the intrinsics change mid-log."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from holoslam.io import mcap as mcap_io
from holoslam.io.mcap import container, convert, read_log, report_to_dict
from holoslam.io.mcap_write import example_records, write_ros2_log
from holoslam.types import CameraInfo, Odometry, Pose2


def _norm(v):
    """A value as plain comparable data, arrays by dtype, shape, bytes and writability; floats bitwise."""
    if isinstance(v, np.ndarray):
        return ("nd", v.dtype.str, v.shape, v.tobytes(), v.flags.writeable)
    if dataclasses.is_dataclass(v):
        return (type(v).__name__,) + tuple(
            _norm(getattr(v, f.name)) for f in dataclasses.fields(v) if f.name != "_decoder"
        )
    if isinstance(v, float):
        return ("f", np.float64(v).tobytes())
    if isinstance(v, (tuple, list)):
        return tuple(_norm(x) for x in v)
    return (type(v).__name__, v)


@pytest.fixture(scope="module")
def records():
    return example_records(seconds=6.0)


def _damaged(tmp_path, records, kind):
    full = write_ros2_log(tmp_path / "full.mcap", records, chunk_size=4096)
    raw = bytearray(full.read_bytes())
    if kind == "whole":
        return full
    if kind == "truncated":
        raw = raw[: int(len(raw) * 0.6)]
    else:  # a flipped byte in the middle of the data section: one chunk fails its CRC
        raw[len(raw) // 3] ^= 0xFF
    bad = tmp_path / f"{kind}.mcap"
    bad.write_bytes(bytes(raw))
    return bad


@pytest.mark.parametrize("kind", ["whole", "truncated", "flipped"])
def test_mapped_and_buffered_reads_give_identical_records_and_reports(tmp_path, records, monkeypatch, kind):
    path = _damaged(tmp_path, records, kind)
    mapped, rep_mapped = read_log(path)
    monkeypatch.setattr(container, "_open_mapped", lambda fh: fh)  # the buffered-read fallback
    buffered, rep_buffered = read_log(path)
    assert _norm(mapped) == _norm(buffered)
    assert report_to_dict(rep_mapped) == report_to_dict(rep_buffered)
    if kind == "flipped":
        assert rep_mapped.crc_errors == 1 and rep_mapped.lost
    if kind == "truncated":
        assert rep_mapped.truncated and len(mapped.odometry) < len(
            [r for r in records if isinstance(r, Odometry)]
        )


def test_scalar_covariance_rotation_is_bit_identical_to_the_matrix_form():
    rng = np.random.default_rng(3)
    for _ in range(200):
        a = rng.normal(size=(6, 6))
        c36 = tuple(float(x) for x in (a @ a.T * rng.uniform(1e-6, 10.0)).ravel())
        th = float(rng.uniform(-math.pi, math.pi))
        c = c36  # the (x, y, yaw) block of the 6x6, rotated into the body frame by the matrix form
        block = np.array([[c[0], c[1], c[5]], [c[6], c[7], c[11]], [c[30], c[31], c[35]]])
        want = mcap_io.rotate_cov_xy(block, -th)
        got = convert._cov36_to_body(c36, th)
        assert got.dtype == np.float64 and got.shape == (3, 3)
        assert np.array_equal(got, want)
    assert convert._cov36_to_body((0.0,) * 36, 0.3) is None
    assert convert._cov36_to_body((1.0,) * 35, 0.3) is None  # not a 6x6 covariance: unknown


def test_camera_info_records_follow_intrinsics_that_change_mid_log(tmp_path):
    t0 = 1_700_000_000_000_000_000
    K1 = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    K2 = np.array([[610.0, 0, 330], [0, 605.0, 250], [0, 0, 1]])
    Ks = [K1, K1, K2, K2, K1]
    Ds = [np.zeros(5), np.zeros(5), np.full(5, 0.01), np.arange(8.0) * 1e-3, np.zeros(5)]
    recs = [Odometry(t0 + i * 50_000_000, Pose2(0.01 * i, 0, 0), np.eye(3) * 1e-4, 0.1) for i in range(20)]
    recs += [
        CameraInfo(t0 + i * 200_000_000, "camera_optical", 640, 480, K, D)
        for i, (K, D) in enumerate(zip(Ks, Ds, strict=True))
    ]
    recs.sort(key=lambda r: r.stamp_ns)
    data, report = read_log(write_ros2_log(tmp_path / "ci.mcap", recs))
    assert report.channel("/camera/camera_info").decoder == "fast-cdr"
    assert len(data.camera_infos) == len(Ks)
    for ci, K, D in zip(data.camera_infos, Ks, Ds, strict=True):
        assert np.array_equal(ci.K, K) and np.array_equal(ci.D, D)
        assert ci.K.shape == (3, 3) and not ci.K.flags.writeable and not ci.D.flags.writeable
