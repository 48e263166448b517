"""TUM trajectory text round trips."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from holoslam.errors import IngestError
from holoslam.io.trajectory import parse_tum, read_tum, to_tum_text, write_tum


def test_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    stamps = np.cumsum(rng.integers(1, 10**9, 50)).astype(np.int64) + 1_700_000_000_123_456_789
    wTb = np.column_stack([rng.normal(size=50), rng.normal(size=50), rng.uniform(-np.pi, np.pi, 50)])
    s, p = read_tum(write_tum(tmp_path / "t.tum", stamps, wTb))
    assert np.array_equal(s, stamps)
    assert np.allclose(p[:, :2], wTb[:, :2], atol=0)
    assert np.allclose(np.angle(np.exp(1j * (p[:, 2] - wTb[:, 2]))), 0, atol=1e-12)


@given(st.integers(0, 4 * 10**18), st.floats(-np.pi, np.pi, exclude_max=True))
def test_stamps_and_yaw_exact(stamp, yaw):
    s, p = parse_tum(to_tum_text(np.array([stamp]), np.array([[1.0, 2.0, yaw]])))
    assert int(s[0]) == stamp
    assert abs(np.angle(np.exp(1j * (p[0, 2] - yaw)))) < 1e-12


def test_general_quaternion_yaw_and_errors():
    s, p = parse_tum("1.5 1 2 3 0 0 0.7071067811865476 0.7071067811865476\n")
    assert s[0] == 1_500_000_000 and np.isclose(p[0, 2], np.pi / 2)
    with pytest.raises(IngestError, match=":1: a TUM line has 8 fields"):
        parse_tum("1.0 2 3\n", source="x.tum")
