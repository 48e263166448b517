"""Ingestion throughput against the plain ``mcap`` reader over the same generated log, in one process.

    .venv/bin/python benchmarks/bench_ingest.py [--mb 100] [--repeats 3] [--no-images]

Generates (into a temp dir, deleted afterwards) a ROS 2 log at the reference household rates: odometry 20 Hz,
compass IMU 10 Hz, 181-beam LaserScan 5 Hz, 640x480 JPEG camera 10 Hz with CameraInfo and /tf, until it is
at least ``--mb`` MB. Prints medians of ``--repeats`` runs of

- plain read: ``mcap.reader.make_reader(f).iter_messages()`` (no decoding, and no CRC check: the reader's
  default), messages/s and MB/s; and the same with ``validate_crcs=True``, the like-for-like reference, since
  ``iter_records`` always validates chunk CRCs (zlib.crc32 of every decompressed chunk, about a third of the
  plain read's time on this log);
- holoslam: ``iter_records`` (every used channel decoded into records, CRCs validated), messages/s, MB/s and
  the ratio to the plain read (goal <= 2);
- LaserScan decoding on one core: fast CDR path vs the generic ``mcap_ros2`` decoder, scans/s (goal >= 20,000);
- peak Python heap while streaming the whole file (tracemalloc), against the largest chunk.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np


def generate(path: Path, target_mb: float, images: bool = True) -> tuple[int, list[bytes]]:
    import cv2
    from mcap_ros2.writer import Writer

    from holoslam.io.mcap_write import MSGDEFS, ros2_message
    from holoslam.types import CameraInfo, Heading, Image, Odometry, Pose2, Scan, Transform

    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:480, 0:640]
    jpegs = []
    for k in range(8):
        img = ((xx * (k + 1) + yy * 3) % 256).astype(np.uint8)
        img = np.dstack([img, np.roll(img, 40 * k, axis=1), 255 - img])
        img = np.clip(img + rng.normal(0, 12, img.shape), 0, 255).astype(np.uint8)
        jpegs.append(cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 85])[1].tobytes())
    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    t0 = 1_700_000_000_000_000_000
    scan_msgs: list[bytes] = []
    n = 0
    with open(path, "wb") as f:
        w = Writer(f)
        sch = {t: w.register_msgdef(t, MSGDEFS[t]) for t in MSGDEFS}

        def put(topic, typ, rec, stamp):
            nonlocal n
            w.write_message(topic, sch[typ], ros2_message(rec), log_time=stamp, publish_time=stamp)
            n += 1

        put(
            "/tf_static",
            "tf2_msgs/msg/TFMessage",
            Transform(t0, "base_link", "laser", (0.15, 0, 0.3), (0, 0, 0, 1), static=True),
            t0,
        )
        i = 0
        while f.tell() < target_mb * 1e6:
            t = t0 + i * 50_000_000
            put(
                "/odom",
                "nav_msgs/msg/Odometry",
                Odometry(t, Pose2(0.01 * i, 0, 0.001 * i), np.eye(3) * 1e-4, 0.3),
                t,
            )
            if i % 2 == 0:
                put("/compass", "sensor_msgs/msg/Imu", Heading(t, 0.001 * i, 0.02), t)
                if images:
                    put(
                        "/camera/image/compressed",
                        "sensor_msgs/msg/CompressedImage",
                        Image(t, "camera_optical", "jpeg", jpegs[(i // 2) % len(jpegs)]),
                        t,
                    )
                put(
                    "/camera/camera_info",
                    "sensor_msgs/msg/CameraInfo",
                    CameraInfo(t, "camera_optical", 640, 480, K, np.zeros(5)),
                    t,
                )
                q = (0.0, 0.0, math.sin(0.01 * i), math.cos(0.01 * i))
                put(
                    "/tf",
                    "tf2_msgs/msg/TFMessage",
                    Transform(t, "ptz_base", "camera_optical", (0, 0, 0.1), q),
                    t,
                )
            if i % 4 == 0:
                r = (0.5 + 7 * rng.random(181)).astype(np.float32)
                r[rng.random(181) < 0.1] = np.inf
                put(
                    "/scan",
                    "sensor_msgs/msg/LaserScan",
                    Scan(t, "laser", -math.pi / 2, math.pi / 180, 0.05, 8.0, r, np.isfinite(r)),
                    t,
                )
            i += 1
        w.finish()
    return n, scan_msgs


def plain_read(path: Path) -> int:
    from mcap.reader import make_reader

    k = 0
    with open(path, "rb") as f:
        for _ in make_reader(f).iter_messages():
            k += 1
    return k


def plain_read_crc(path: Path) -> int:
    """The plain read with chunk CRCs validated, as ``iter_records`` always does: the like-for-like
    reference (``make_reader`` defaults to ``validate_crcs=False``)."""
    from mcap.reader import make_reader

    k = 0
    with open(path, "rb") as f:
        for _ in make_reader(f, validate_crcs=True).iter_messages():
            k += 1
    return k


def holoslam_read(path: Path) -> int:
    from holoslam.io.mcap import iter_records

    k = 0
    for _ in iter_records(path):
        k += 1
    return k


def scan_payloads(path: Path, limit: int = 3000) -> list[bytes]:
    from mcap.reader import make_reader

    out = []
    with open(path, "rb") as f:
        for _s, _c, m in make_reader(f).iter_messages(topics=["/scan"]):
            out.append(m.data)
            if len(out) >= limit:
                break
    return out


def median_time(fn, repeats: int) -> tuple[float, object]:
    ts, res = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        res = fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts), res


def interleaved(fns, repeats: int) -> list[tuple[float, object]]:
    times: list[list[float]] = [[] for _ in fns]
    res: list[object] = [None] * len(fns)
    for _ in range(repeats):
        for k, fn in enumerate(fns):
            t = time.perf_counter()
            res[k] = fn()
            times[k].append(time.perf_counter() - t)
    return [(statistics.median(ts), r) for ts, r in zip(times, res, strict=True)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mb", type=float, default=100.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-images", action="store_true", help="a message-heavy log: everything but the camera")
    a = ap.parse_args(argv)

    from mcap.reader import make_reader

    from holoslam.io import cdr
    from holoslam.io.mcap import LogReader
    from holoslam.io.mcap_write import MSGDEFS
    from holoslam.types import Scan

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "bench.mcap"
        t = time.perf_counter()
        n_written, _ = generate(path, a.mb, images=not a.no_images)
        size_mb = os.path.getsize(path) / 1e6
        print(
            f"generated {path.name}: {size_mb:.1f} MB, {n_written} messages in {time.perf_counter() - t:.1f} s"
        )

        # interleaved repeats, so load from other processes hits both readers alike
        (t_plain, n_plain), (t_crc, n_crc), (t_holo, n_rec) = interleaved(
            [lambda: plain_read(path), lambda: plain_read_crc(path), lambda: holoslam_read(path)], a.repeats
        )
        assert n_crc == n_plain, (n_crc, n_plain)
        reader = LogReader(path)
        for _ in reader:
            pass
        rep = reader.report()
        decoded = sum(c.decoded for c in rep.channels)
        assert decoded == n_plain, (decoded, n_plain)

        print()
        print(f"{'reader':<34}{'median s':>10}{'msgs/s':>12}{'MB/s':>10}{'ratio':>8}")
        print(
            f"{'mcap iter_messages (no decode)':<34}{t_plain:>10.3f}{n_plain / t_plain:>12,.0f}"
            f"{size_mb / t_plain:>10.1f}{1.0:>8.2f}"
        )
        print(
            f"{'mcap iter_messages (CRCs checked)':<34}{t_crc:>10.3f}{n_plain / t_crc:>12,.0f}"
            f"{size_mb / t_crc:>10.1f}{t_crc / t_plain:>8.2f}"
        )
        print(
            f"{'holoslam iter_records (decoded)':<34}{t_holo:>10.3f}{n_plain / t_holo:>12,.0f}"
            f"{size_mb / t_holo:>10.1f}{t_holo / t_plain:>8.2f}"
        )
        print(
            f"  holoslam / plain: {t_holo / t_plain:.2f} (goal <= 2); like for like, both validating chunk "
            f"CRCs: {t_holo / t_crc:.2f}"
        )
        print(
            f"  ({n_plain} messages -> {n_rec} records; decoders: "
            + ", ".join(f"{c.topic}={c.decoder}" for c in rep.channels)
            + ")"
        )

        scans = scan_payloads(path)
        gen = cdr.generic_decoder("sensor_msgs/msg/LaserScan", MSGDEFS["sensor_msgs/msg/LaserScan"])

        def fast_all():
            for b in scans:
                m = cdr.decode_laser_scan(b)
                r = m["ranges"]
                Scan(
                    m["stamp_ns"],
                    m["frame_id"],
                    m["angle_min"],
                    m["angle_increment"],
                    m["range_min"],
                    m["range_max"],
                    r,
                    np.isfinite(r) & (r >= m["range_min"]) & (r <= m["range_max"]),
                )

        def generic_all():
            for b in scans:
                m = gen(b)
                r = np.asarray(m.ranges, dtype=np.float32)
                Scan(
                    m.header.stamp.sec,
                    m.header.frame_id,
                    m.angle_min,
                    m.angle_increment,
                    m.range_min,
                    m.range_max,
                    r,
                    np.isfinite(r) & (r >= m.range_min) & (r <= m.range_max),
                )

        t_fast, _ = median_time(fast_all, a.repeats)
        t_gen, _ = median_time(generic_all, a.repeats)
        print()
        print(f"{'LaserScan (181 beams) -> Scan':<34}{'scans/s':>12}{'ratio':>8}")
        print(f"{'generic mcap_ros2 decoder':<34}{len(scans) / t_gen:>12,.0f}{1.0:>8.2f}")
        print(f"{'holoslam fast CDR path':<34}{len(scans) / t_fast:>12,.0f}{t_gen / t_fast:>8.1f}")

        with open(path, "rb") as f:
            chunks = make_reader(f).get_summary().chunk_indexes
        biggest = max(c.uncompressed_size for c in chunks) / 1e6
        tracemalloc.start()
        holoslam_read(path)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        print()
        print(
            f"peak Python heap while streaming {size_mb:.0f} MB: {peak / 1e6:.1f} MB "
            f"(largest chunk {biggest:.1f} MB uncompressed, {len(chunks)} chunks)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
