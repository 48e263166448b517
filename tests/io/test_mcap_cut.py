"""Cutting a log-time window out of an MCAP log: exact messages, schemas and channels kept, static transforms
always kept, metadata copied, bad input; and a cut of a shared real log that holoslam reads."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from repo_paths import SHARED

from holoslam.errors import IngestError
from holoslam.io.mcap_cut import cut_log

REALDATA = SHARED / "realdata"
S = 1_000_000_000
T0 = 1_700_000_000 * S


def _write_log(path: Path) -> list[tuple[str, int, bytes]]:
    """A small log: /tf_static at its start and once after 9 s, /odom at 10 Hz, /scan at 2 Hz, a schemaless
    /note channel, metadata. Returns every message as (topic, log time, data)."""
    from mcap.writer import Writer

    msgs: list[tuple[str, int, bytes]] = []
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        s_tf = w.register_schema(
            "tf2_msgs/msg/TFMessage", "ros2msg", b"geometry_msgs/TransformStamped[] transforms"
        )
        s_odom = w.register_schema("nav_msgs/msg/Odometry", "ros2msg", b"std_msgs/Header header")
        s_scan = w.register_schema("sensor_msgs/msg/LaserScan", "ros2msg", b"float32[] ranges")
        ch = {
            "/tf_static": w.register_channel("/tf_static", "cdr", s_tf, {"offered_qos_profiles": "latched"}),
            "/odom": w.register_channel("/odom", "cdr", s_odom),
            "/scan": w.register_channel("/scan", "cdr", s_scan),
            "/note": w.register_channel("/note", "json", 0),
        }
        events = [("/tf_static", T0), ("/tf_static", T0 + 9 * S)]
        events += [("/odom", T0 + k * S // 10) for k in range(100)]
        events += [("/scan", T0 + k * S // 2 + 3) for k in range(20)]
        events += [("/note", T0 + 4 * S)]
        for seq, (topic, t) in enumerate(sorted(events, key=lambda e: e[1])):
            data = f"{topic}@{t}".encode()
            w.add_message(ch[topic], t, data, t + 1, seq)
            msgs.append((topic, t, data))
        w.add_metadata("robot", {"name": "test"})
        w.finish()
    return msgs


def _read(path: Path):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        r = make_reader(f)
        summary = r.get_summary()
        msgs = [(c.topic, m.log_time, m.data, m.publish_time, m.sequence) for _, c, m in r.iter_messages()]
        meta = [(md.name, dict(md.metadata)) for md in r.iter_metadata()]
        profile = r.get_header().profile
    return summary, msgs, meta, profile


def test_cut_copies_the_window_and_static_transforms_exactly(tmp_path):
    src = tmp_path / "src.mcap"
    every = _write_log(src)
    cut = cut_log(src, tmp_path / "cut.mcap", start_s=2.0, duration_s=3.0)
    assert (cut.source_start_ns, cut.start_ns, cut.end_ns) == (T0, T0 + 2 * S, T0 + 5 * S)
    summary, msgs, meta, profile = _read(cut.path)
    expected = [
        (topic, t, data) for topic, t, data in every if T0 + 2 * S <= t < T0 + 5 * S or topic == "/tf_static"
    ]
    assert [(m[0], m[1], m[2]) for m in msgs] == expected
    assert all(m[3] == m[1] + 1 for m in msgs)  # publish times kept
    assert [m[1] for m in msgs] == sorted(m[1] for m in msgs)
    counts = {topic: sum(1 for e in expected if e[0] == topic) for topic in {e[0] for e in expected}}
    assert cut.messages == counts
    assert (
        counts["/tf_static"] == 2 and counts["/odom"] == 30 and counts["/scan"] == 6 and counts["/note"] == 1
    )
    assert cut.n_messages == len(expected)
    # schemas and channels as in the source
    src_summary, _, _, _ = _read(src)
    assert [(s.name, s.encoding, s.data) for s in summary.schemas.values()] == [
        (s.name, s.encoding, s.data) for s in src_summary.schemas.values()
    ]

    def chans(sm):
        return sorted(
            (
                c.topic,
                c.message_encoding,
                sm.schemas[c.schema_id].name if c.schema_id else "",
                dict(c.metadata),
            )
            for c in sm.channels.values()
        )

    assert chans(summary) == chans(src_summary)
    assert meta == [("robot", {"name": "test"})]
    assert profile == "ros2"


def test_a_window_past_the_end_keeps_only_static_transforms(tmp_path):
    src = tmp_path / "src.mcap"
    _write_log(src)
    cut = cut_log(src, tmp_path / "cut.mcap", start_s=60.0, duration_s=10.0)
    summary, msgs, _, _ = _read(cut.path)
    assert [m[0] for m in msgs] == ["/tf_static", "/tf_static"]
    assert len(summary.channels) == 4  # every channel is still declared


def test_bad_input(tmp_path):
    src = tmp_path / "src.mcap"
    _write_log(src)
    with pytest.raises(ValueError, match="duration_s"):
        cut_log(src, tmp_path / "c.mcap", 0.0, 0.0)
    with pytest.raises(ValueError, match="start_s"):
        cut_log(src, tmp_path / "c.mcap", -1.0, 5.0)
    with pytest.raises(ValueError, match="source itself"):
        cut_log(src, src, 0.0, 5.0)
    with pytest.raises(IngestError, match="cannot be opened"):
        cut_log(tmp_path / "missing.mcap", tmp_path / "c.mcap", 0.0, 5.0)
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all" * 10)
    with pytest.raises(IngestError, match="not a readable MCAP log"):
        cut_log(junk, tmp_path / "c.mcap", 0.0, 5.0)
    with pytest.raises(IngestError, match="cannot be written"):
        cut_log(src, tmp_path / "no" / "such" / "c.mcap", 0.0, 5.0)


def test_a_cut_of_a_real_log_reads_back_with_its_relations(tmp_path):
    log_path = REALDATA / "fr079.mcap"
    if not (log_path.is_file() and (REALDATA / "fr079.relations").is_file()):
        pytest.skip(f"shared real data not here ({REALDATA})")
    from holoslam.io.mcap import read_log
    from holoslam.io.relations import cut_relations, read_relations

    cut = cut_log(log_path, tmp_path / "fr079_cut.mcap", start_s=30.0, duration_s=60.0)
    log, _ = read_log(cut.path, require=["odometry", "scan"])
    scans = np.array([s.stamp_ns for s in log.scans], dtype=np.int64)
    assert 200 < scans.size < 350  # 4.6 Hz for 60 s
    assert cut.messages["/scan"] == scans.size and cut.messages["/tf_static"] == 1
    # header stamps of these logs are their log times: the scans lie in the window
    assert scans.min() >= cut.start_ns - 50_000_000 and scans.max() < cut.end_ns + 50_000_000
    rel = cut_relations(read_relations(REALDATA / "fr079.relations"), int(scans.min()), int(scans.max()) + 1)
    assert len(rel) > 20
    assert np.isin(rel.t1_ns, scans).all() and np.isin(rel.t2_ns, scans).all()
    # the laser's mounting (base_link -> laser, x = 0.04 m) survives the cut though /tf_static is from before it
    laser = [t for t in log.transforms if t.static and t.child == "laser"]
    assert laser and laser[0].parent == "base_link"
    assert laser[0].translation[0] == pytest.approx(0.04)
