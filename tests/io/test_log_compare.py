"""The content comparison of regenerated simulated logs (tests/log_compare.py): last-bit differences of a
regeneration on another machine pass, every real change of the content fails."""

from __future__ import annotations

import pytest
from log_compare import compare_logs, decode_log

from holoslam.sim import SimConfig, simulate_to_file

CFG = SimConfig(seed=2, duration_s=20.0, image_rate_hz=0.5)


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    path = tmp_path_factory.mktemp("cmp") / "short.mcap"
    simulate_to_file(path, CFG)
    return path


@pytest.fixture()
def ref(short):
    return decode_log(short)


@pytest.fixture()
def got(short):
    """A second decoding of the same file, to change (decoded messages do not deep-copy)."""
    return decode_log(short)


def _on(log, topic):
    return [m[4] for m in log.messages if m[0] == topic]


def test_a_regeneration_is_the_same_content(ref, tmp_path):
    simulate_to_file(tmp_path / "again.mcap", CFG)
    assert compare_logs(ref, decode_log(tmp_path / "again.mcap")) == []
    assert _on(ref, "/camera/image/compressed"), "the short log has images to compare"


def test_last_bit_differences_pass(ref, got):
    for m in _on(got, "/odom"):
        m.pose.pose.position.x *= 1 + 1e-12
        m.twist.twist.angular.z += 1e-9  # the sqrt-amplified size measured across machines
    for m in _on(got, "/scan")[:3]:
        m.ranges[5] = round(m.ranges[5] + 1e-3, 3) if m.ranges[5] < m.range_max - 0.01 else m.ranges[5]
    odo = _on(got, "/odom")[-1]
    mantissa, exponent = f"{odo.pose.covariance[0]:.1e}".split("e")
    odo.pose.covariance[0] = float(f"{float(mantissa) + 0.1:.1f}e{exponent}")  # the second digit flips
    assert compare_logs(ref, got) == []


def _shift_odometry(log):
    _on(log, "/odom")[50].pose.pose.position.y += 1e-4  # 0.1 mm


def _two_millimetres(log):
    _on(log, "/scan")[7].ranges[90] += 2e-3


def _lost_return(log):
    _on(log, "/scan")[7].ranges[90] = float("inf")


def _compass(log):
    _on(log, "/compass")[3].orientation.z += 1e-5


def _frame(log):
    _on(log, "/odom")[9].header.frame_id = "map"


def _stamp(log):
    _on(log, "/odom")[9].header.stamp.nanosec = 1


def _corner(log):
    _on(log, "/tags")[0].detections[0].corners[0] += 0.01  # px


def _dropped(log):
    log.messages.pop(100)


def _metadata(log):
    log.metadata["holoslam"]["seed"] = "3"


@pytest.mark.parametrize(
    "change, what",
    [
        (_shift_odometry, "position.y"),
        (_two_millimetres, "ranges"),
        (_lost_return, "non-finite"),
        (_compass, "orientation.z"),
        (_frame, "frame_id"),
        (_stamp, "nanosec"),
        (_corner, "corners"),
        (_dropped, "message counts"),
        (_metadata, "metadata"),
    ],
)
def test_real_changes_fail(ref, got, change, what):
    change(got)
    problems = compare_logs(ref, got)
    assert problems and what in problems[0], problems


def test_an_image_of_another_view_fails(ref, got):
    imgs = _on(got, "/camera/image/compressed")
    imgs[0].data, imgs[1].data = imgs[1].data, imgs[0].data
    problems = compare_logs(ref, got)
    assert problems and "grey levels" in problems[0]


def test_another_odometer_model_fails(ref, tmp_path):
    other = tmp_path / "other.mcap"
    simulate_to_file(other, SimConfig(seed=2, duration_s=20.0, image_rate_hz=0.5, odom_scale=0.016))
    problems = compare_logs(ref, decode_log(other))
    assert any("metadata" in p for p in problems)  # the config is in the log's metadata
    assert any(p.startswith("/odom .pose.pose.position") for p in problems), problems
