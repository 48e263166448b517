"""Logs other robots write, end to end: a cut of a real log (../shared/realdata, not in the repository)
rewritten three ways that keep the same drive (issue 13 item 4), and a simulated log with raw and compressed
images, each mapped by ``holoslam.pipeline.run`` to the same trajectory as the unchanged log."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from repo_paths import SHARED

from holoslam.types import Image, Odometry, Scan, Transform

REALDATA = SHARED / "realdata"
TOLERANCE_M = 0.05  # trajectory RMS against the unchanged run (measured: 0, 0 and 1.3 mm upside down; before: 2.3 m)


def _rms(a, b) -> float:
    assert np.array_equal(a.stamps_ns, b.stamps_ns)
    d = a.wTb[:, :2] - b.wTb[:, :2]
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


def _base_footprint(topic, r):
    """The robot's base frame renamed base_footprint everywhere (odometry child, /tf, /tf_static): no base_link."""
    rename = lambda f: "base_footprint" if f == "base_link" else f  # noqa: E731
    if isinstance(r, Odometry):
        r = dataclasses.replace(r, child_frame_id=rename(r.child_frame_id))
    elif isinstance(r, Transform):
        r = dataclasses.replace(r, parent=rename(r.parent), child=rename(r.child))
    return [(topic, r)]


def _scan_filtered(topic, r):
    """A copy of every scan on /scan_filtered (as a laser filter chain publishes beside the raw scan)."""
    return [(topic, r), ("/scan_filtered", r)] if isinstance(r, Scan) else [(topic, r)]


def _upside_down(topic, r):
    """The laser rolled over (its static transform times a rotation of pi about x) and each scan's ranges
    reversed, so it sees the same world: beam angle a of the rolled laser points at -a in the base."""
    if isinstance(r, Transform) and r.static and r.child == "laser":
        x, y, z, w = r.rotation_xyzw  # q * (1, 0, 0, 0)
        r = dataclasses.replace(r, rotation_xyzw=(w, z, -y, -x))
    elif isinstance(r, Scan):
        n = r.ranges.shape[0]
        a_last = r.angle_min + r.angle_increment * (n - 1)
        r = Scan(
            r.stamp_ns,
            r.frame_id,
            -a_last,
            r.angle_increment,
            r.range_min,
            r.range_max,
            r.ranges[::-1].copy(),
            r.valid[::-1].copy(),
        )
    return [(topic, r)]


def _rewrite(src, dst, change):
    from holoslam.io.mcap import iter_records
    from holoslam.io.mcap_write import write_ros2_log

    return write_ros2_log(dst, [item for topic, rec in iter_records(src) for item in change(topic, rec)])


@pytest.fixture(scope="module")
def real_cut(tmp_path_factory):
    """90 s of Freiburg building 079 (its tf puts the laser 4 cm ahead of the base: the mounting matters) and its run."""
    if not (REALDATA / "fr079.mcap").exists():
        pytest.skip("../shared/realdata is not here")
    from holoslam.io.mcap_cut import cut_log
    from holoslam.pipeline import run

    path = tmp_path_factory.mktemp("fr079") / "cut.mcap"
    cut_log(REALDATA / "fr079.mcap", path, 0.0, 90.0)
    return path, run(path)


@pytest.mark.slow
@pytest.mark.parametrize("change", [_base_footprint, _scan_filtered, _upside_down], ids=lambda f: f.__name__)
def test_a_real_log_rewritten_maps_the_same_drive(real_cut, tmp_path, change):
    """Before issue 13 item 4: base_footprint and /scan_filtered stopped the run (exit 2); the upside-down laser
    ran with a mirrored scan, metres away from the original drive."""
    from holoslam.io.mcap import read_log
    from holoslam.pipeline import run

    src, unchanged = real_cut
    path = _rewrite(src, tmp_path / f"{change.__name__}.mcap", change)
    result = run(path)
    assert result.wTb.shape[0] > 500 and np.ptp(unchanged.wTb[:, 0]) + np.ptp(unchanged.wTb[:, 1]) > 5.0
    assert _rms(result, unchanged) < TOLERANCE_M
    _data, report = read_log(path)
    if change is _base_footprint:
        assert report.base_frame == "base_footprint" and not report.missing_transforms
    elif change is _scan_filtered:
        assert [(c.role, c.topic) for c in report.choices] == [("scan", "/scan")]
    else:
        assert report.levelled and "upside down" in report.levelled[0]


@pytest.mark.slow
@pytest.mark.slow
def test_the_mounting_check_finds_the_laser_behind_the_point_the_robot_turns_about(real_cut, tmp_path):
    """fr079's /tf_static puts the laser 0.04 m ahead of base_link; its motion puts the laser 0.018 m behind the
    point the robot turns about (the whole log: 0.018 +/- 0.001 m; this cut measured 0.019 +/- 0.004), which is
    where the benchmark's ground truth places the robot. The report says so and how to fix it; with the mapping
    it proposes, base_link is the turning centre and the check is quiet."""
    from holoslam.config import RunConfig
    from holoslam.pipeline import run

    src, result = real_cut
    m = result.report.submaps.laser_mounting
    assert -0.03 < m["laser_x_m"] < -0.008 and m["laser_x_std_m"] < 0.01 and m["tf_laser_x_m"] == pytest.approx(0.04)
    assert m["base_off_centre"] and "frames: {static: [{parent: base_link, child: laser" in result.report.text()
    mapping = f"frames: {{static: [{{parent: base_link, child: laser, xyz: [{m['laser_x_m']:.3f}, 0, 0]}}]}}"
    fixed = run(src, RunConfig(mapping=mapping)).report
    assert any("replaces the log's base_link->laser (x=+0.040" in w for w in fixed.ingest["warnings"])
    again = fixed.submaps.laser_mounting
    assert abs(again["centre_in_base_x_m"]) < 0.005 and not again["base_off_centre"]


@pytest.mark.slow
def test_the_odometer_check_reads_the_real_odometers_bias(real_cut):
    """fr079's odometer against its scans: the whole log reads -0.7 % and -0.92 deg/m (62 straight stretches);
    the first 90 s read the same within their standard errors, and a drift that size is flagged with what to check."""
    _src, result = real_cut
    m = result.report.submaps.odometer
    assert m is not None and m["stretches"] >= 10
    assert abs(m["scale"] - 0.993) < 3 * m["scale_std"] + 0.003 and m["scale_std"] < 0.01
    assert abs(m["yaw_deg_per_m"] + 0.92) < 3 * m["yaw_std"] + 0.05 and m["yaw_std"] < 0.2
    assert m["off"] and "turns 0.9" in result.report.text() and "wheel radii" in result.report.text()


def test_a_simulated_log_with_raw_and_compressed_images_runs(tmp_path):
    """``holoslam simulate``'s log plus every image again as a raw sensor_msgs/Image: the compressed one is used
    (reported), and the run maps the same drive and the same objects."""
    import cv2

    from holoslam.io.mcap import read_log
    from holoslam.pipeline import run
    from holoslam.run_jobs import simulate

    sim = tmp_path / "sim.mcap"
    simulate(sim, seed=1, duration_s=40.0)

    def add_raw(topic, r):
        if not isinstance(r, Image):
            return [(topic, r)]
        px = cv2.imdecode(np.frombuffer(r.data, np.uint8), cv2.IMREAD_COLOR)
        h, w = px.shape[:2]
        raw = Image(r.stamp_ns, r.frame_id, "bgr8", px.tobytes(), width=w, height=h, step=3 * w)
        return [(topic, r), ("/camera/image_raw", raw)]

    both = _rewrite(sim, tmp_path / "raw_and_compressed.mcap", add_raw)
    unchanged, result = run(sim), run(both)
    assert _rms(result, unchanged) < TOLERANCE_M
    assert sorted(o.object_id for o in result.objects) == sorted(o.object_id for o in unchanged.objects)
    assert len(result.objects) >= 5
    _data, report = read_log(both)
    assert [(c.role, c.topic) for c in report.choices] == [("image", "/camera/image/compressed")]
