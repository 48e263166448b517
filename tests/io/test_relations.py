"""Reading .relations files (Freiburg SLAM benchmark): exact nanosecond stamps, bad input, round trip, cut."""

from __future__ import annotations

import numpy as np
import pytest
from repo_paths import SHARED

from holoslam.errors import IngestError
from holoslam.io.relations import (
    Relations,
    cut_relations,
    parse_relations,
    read_relations,
    to_relations_text,
    write_relations,
)

REALDATA = SHARED / "realdata"


def test_stamps_are_exact_nanoseconds_not_float_seconds():
    r = parse_relations("976052905.167303 976052911.885496 -0.056990 -0.128430 0 0 0 -1.682210\n")
    assert r.t1_ns.dtype == np.int64
    assert int(r.t1_ns[0]) == 976052905_167303000
    assert int(r.t2_ns[0]) == 976052911_885496000
    # the float64 path would not give the scan's header stamp
    assert int(round(float("976052905.167303") * 1e9)) != 976052905_167303000
    np.testing.assert_allclose(r.T, [[-0.05699, -0.12843, -1.68221]])


def test_comments_blank_lines_commas_and_yaw_wrap():
    text = (
        "# t1 t2 x y z roll pitch yaw\n\n90.2 90.7, 0.4 0.1 9 9 9 4.0  # trailing\n1 2 0 0 0 0 0 -3.14159\n"
    )
    r = parse_relations(text)
    assert len(r) == 2
    assert r.t1_ns.tolist() == [90_200_000_000, 1_000_000_000]
    assert r.T[0, 2] == pytest.approx(4.0 - 2 * np.pi)  # yaw wrapped to [-pi, pi); z/roll/pitch ignored
    assert r.T[0, :2].tolist() == [0.4, 0.1]
    assert -np.pi <= r.T[:, 2].min() and r.T[:, 2].max() < np.pi


def test_sub_nanosecond_digits_round_and_exponents_are_exact():
    r = parse_relations("1.0000000005 2.5e0 0 0 0 0 0 0\n0.0000000015 3 0 0 0 0 0 0")
    assert r.t1_ns.tolist() == [1_000_000_000, 2]  # half-even below a nanosecond
    assert r.t2_ns.tolist() == [2_500_000_000, 3_000_000_000]


def test_record_is_immutable():
    r = parse_relations("1 2 0 0 0 0 0 0")
    with pytest.raises(ValueError):
        r.t1_ns[0] = 5
    with pytest.raises(ValueError):
        r.T[0, 0] = 1.0


@pytest.mark.parametrize(
    ("text", "where", "what"),
    [
        ("1 2 0 0 0 0 0 0\n1 2 3\n", ":2:", "8 fields"),
        ("1 2 0 0 0 0 0 0\n\n1 2 0 0 0 0 0 0 7\n", ":3:", "8 fields"),
        ("abc 2 0 0 0 0 0 0\n", ":1:", "decimal seconds"),
        ("1 inf 0 0 0 0 0 0\n", ":1:", "not a finite number"),
        ("1 2 x 0 0 0 0 0\n", ":1:", "not a number"),
        ("1 2 0 nan 0 0 0 0\n", ":1:", "non-finite"),
        ("1 1e30 0 0 0 0 0 0\n", ":1:", "out of range"),
        ("# only a comment\n\n", "rel.relations", "no relation"),
    ],
)
def test_malformed_lines_say_where_what_and_how(tmp_path, text, where, what):
    p = tmp_path / "rel.relations"
    p.write_text(text)
    with pytest.raises(IngestError) as e:
        read_relations(p)
    msg = str(e.value)
    assert str(p) in msg and where in msg and what in msg
    assert "\n" not in msg


def test_unreadable_files(tmp_path):
    with pytest.raises(IngestError, match="no such file"):
        read_relations(tmp_path / "missing.relations")
    with pytest.raises(IngestError, match="is a folder"):
        read_relations(tmp_path)
    b = tmp_path / "binary.relations"
    b.write_bytes(b"\xff\xfe\x00\x81" * 10)
    with pytest.raises(IngestError, match="not a text file"):
        read_relations(b)


def test_text_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    t1 = rng.integers(0, 2_000_000_000_000_000_000, 50)
    r = Relations(t1, t1 + rng.integers(1, 10**10, 50), rng.normal(size=(50, 3)))
    back = read_relations(write_relations(tmp_path / "x.relations", r))
    assert np.array_equal(back.t1_ns, r.t1_ns) and np.array_equal(back.t2_ns, r.t2_ns)
    assert np.array_equal(back.T, r.T)
    assert to_relations_text(back) == to_relations_text(r)


def test_cut_keeps_relations_with_both_stamps_in_the_half_open_window():
    r = Relations([1, 5, 9, 5, 3], [4, 9, 12, 10, 10], np.arange(15.0).reshape(5, 3) / 10)
    c = cut_relations(r, 3, 10)
    assert c.t1_ns.tolist() == [5] and c.t2_ns.tolist() == [9]
    np.testing.assert_array_equal(c.T, r.T[[1]])
    assert len(r) == 5  # input unchanged
    assert len(cut_relations(r, 100, 200)) == 0


@pytest.mark.parametrize("name", ["aces", "fr079", "intel"])
def test_every_relation_stamp_of_the_shared_logs_is_a_scan_stamp(name):
    log_path, rel_path = REALDATA / f"{name}.mcap", REALDATA / f"{name}.relations"
    if not (log_path.is_file() and rel_path.is_file()):
        pytest.skip(f"shared real data not here ({REALDATA})")
    from holoslam.io.mcap import read_log

    log, _ = read_log(log_path, require=["scan"])
    scans = np.array([s.stamp_ns for s in log.scans], dtype=np.int64)
    rel = read_relations(rel_path)
    assert len(rel) > 1000
    assert np.isin(rel.t1_ns, scans).all() and np.isin(rel.t2_ns, scans).all()
