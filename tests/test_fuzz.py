"""Fuzzing the readers: random damage to every input must give a HoloslamError (with a message naming where),
never a traceback from inside a library. Good inputs next to the damage are kept (the readers' own tests check
that in detail; here the damaged MCAP log must still read or raise a HoloslamError)."""

from __future__ import annotations

import math
import os
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from holoslam.errors import G2oFormatError, HoloslamError
from holoslam.io.g2o import TextNoise, parse_g2o, read_g2o

FUZZ = settings(
    deadline=None,
    max_examples=int(os.environ.get("HOLOSLAM_FUZZ_EXAMPLES", "60")),  # raise it for a long fuzzing run
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    derandomize=os.environ.get("HOLOSLAM_FUZZ_EXAMPLES") is None,
)

# --------------------------------------------------------------------------------------------- g2o text

VALID_G2O = [
    "VERTEX_SE2 0 0 0 0",
    "VERTEX_SE2 1 1 0 0.1",
    "VERTEX_SE2 2 2 0.1 0.2",
    "EDGE_SE2 0 1 1 0 0.1 500 0 0 500 0 500",
    "EDGE_SE2 1 2 1 0.1 0.1 500 0 0 500 0 500",
    "EDGE2 2 0 -2 0 -0.3 0.01 0 0.01 0.001 0 0",
    "VERTEX_XY 10 1 1",
    "EDGE_SE2_XY 1 10 0 1 100 0 100",
    "LANDMARK 2 10 -1 1 0.01 0 0.01",
    "BR 0 10 0.78 1.41 0.01 0.02",
    "FIX 0",
    "EQUIV 0 0",
]

TOKENS = st.sampled_from(
    [
        "nan",
        "inf",
        "-inf",
        "1e309",
        "-1",
        "-5",
        "1.5",
        "abc",
        "0x10",
        "",
        "\x00",
        "9" * 30,
        "1e-300",
        "0",
        "-0",
        "VERTEX_SE2",
        "vertex_se2",
        "#",
        "1#2",
        "\u00e9",
        "\ufeff",
        "1_000",
        "+3",
        " ",
        "\t",
    ]
)


@st.composite
def damaged_g2o(draw):
    lines = [ln.split() for ln in draw(st.lists(st.sampled_from(VALID_G2O), min_size=1, max_size=12))]
    for _ in range(draw(st.integers(1, 4))):
        k = draw(st.integers(0, len(lines) - 1))
        op = draw(st.sampled_from(["replace", "drop", "extra", "tag", "dup"]))
        toks = lines[k]
        if op == "replace":
            toks[draw(st.integers(0, len(toks) - 1))] = draw(TOKENS | st.text(max_size=6))
        elif op == "drop" and len(toks) > 1:
            toks.pop(draw(st.integers(1, len(toks) - 1)))
        elif op == "extra":
            toks.append(draw(TOKENS))
        elif op == "tag":
            toks[0] = draw(st.sampled_from(["VERTEX_SE3:QUAT", "EDGE_SE3", "FOO", "vertex2", "Edge2", "#x"]))
        else:
            lines.append(list(toks))
    sep = draw(st.sampled_from(["\n", "\r\n", "\r", "\n\n"]))
    return sep.join(" ".join(t) for t in lines)


def _check_g2o_error(e: HoloslamError, source: str) -> None:
    msg = str(e)
    assert msg and source in msg, msg


@FUZZ
@given(text=damaged_g2o(), noise=st.sampled_from(list(TextNoise)), strict=st.booleans())
def test_g2o_text_damage_is_a_g2o_error(text, noise, strict):
    try:
        g = parse_g2o(text, source="fuzz.g2o", noise=noise, strict=strict)
    except G2oFormatError as e:
        _check_g2o_error(e, "fuzz.g2o")
        assert re.search(r"fuzz\.g2o:\d+: ", str(e)), str(e)  # file:line: what
        return
    assert np.all(np.isfinite(g.edge_cov)) and np.all(np.isfinite(g.landmark_cov))
    from holoslam.graph.problem import problem_from_g2o

    try:
        problem_from_g2o(g)
    except HoloslamError as e:
        assert str(e)


@FUZZ
@given(text=damaged_g2o(), junk=st.binary(min_size=1, max_size=8), at=st.integers(0, 400))
def test_g2o_file_with_bytes_damage(tmp_path_factory, text, junk, at):
    p = tmp_path_factory.mktemp("g2o") / "bytes.g2o"
    raw = text.encode("utf-8")
    at = min(at, len(raw))
    p.write_bytes(raw[:at] + junk + raw[at:])
    try:
        read_g2o(p)
    except G2oFormatError as e:
        _check_g2o_error(e, str(p))


SOLVE_G2O = [
    "VERTEX_SE2 0 0 0 0",
    "VERTEX_SE2 1 1 0 0",
    "VERTEX_SE2 2 2 0 0",
    "VERTEX_SE2 5 9 9 0",
    "EDGE_SE2 0 1 1 0 0 500 0 0 500 0 500",
    "EDGE_SE2 1 2 1 0 0 500 0 0 500 0 500",
    "EDGE_SE2 0 1 1 0 0 -500 0 0 500 0 500",  # not positive definite
    "EDGE_SE2 1 2 1 0 0 1 2 0 1 0 1",  # indefinite
    "EDGE_SE2 1 2 1 0 0 1e-300 0 0 1e-300 0 1e-300",  # near singular
    "EDGE_SE2 1 1 0 0 0 500 0 0 500 0 500",  # self loop
    "EDGE_SE2 7 8 1 0 0 500 0 0 500 0 500",  # disconnected component
    "EDGE_SE2_XY 2 10 1 0 100 0 100",
    "EDGE_SE2_XY 2 10 1 0 1e12 0 1e12",
    "VERTEX_XY 10 3 0",
    "VERTEX_XY 10 4 0",  # duplicate
    "VERTEX_SE2 1 1.5 0 0",  # duplicate
    "FIX 0",
    "FIX 99",
    "LANDMARK 2 11 1 1 0 0 0",
    "BR 1 12 0 1 0.1 0.1",
]


@FUZZ
@given(lines=st.lists(st.sampled_from(SOLVE_G2O), min_size=1, max_size=10))
def test_solve_g2o_file_on_what_parses(tmp_path_factory, lines):
    from holoslam.jobs import solve_g2o_file

    p = tmp_path_factory.mktemp("solve") / "g.g2o"
    p.write_text("\n".join(lines) + "\n")
    try:
        _, sol = solve_g2o_file(p, out_path=p.with_suffix(".out.g2o"))
    except HoloslamError as e:
        assert str(e)
        return
    assert np.all(np.isfinite(sol.wTa))


# ---------------------------------------------------------------------------------------- YAML / mapping

_leaf = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.floats(),
    st.text(max_size=8),
    st.sampled_from(["batch", "isam2", "odometry", "scan", "/odom", "rad", "deg", "m"]),
)
KEYS = st.sampled_from(
    [
        "mapping",
        "vision",
        "frontend",
        "solver",
        "grid",
        "topology",
        "holographic",
        "planning",
        "pictures",
        "results_mcap",
        "method",
        "resolution",
        "topics",
        "role",
        "fields",
        "units",
        "x",
        "yaw",
        "bogus",
    ]
) | st.text(max_size=5)
structures = st.recursive(
    _leaf, lambda ch: st.lists(ch, max_size=4) | st.dictionaries(KEYS, ch, max_size=4), max_leaves=12
)


def _dump(data) -> str:
    import yaml

    return yaml.safe_dump(data, allow_unicode=True)


YAML_NASTY = [
    "!!python/object/apply:os.system ['echo pwned']\n",
    "solver: !!python/object:holoslam.pipeline.RunConfig {}\n",
    "a: &x [*x]\n",
    "solver: [1, 2\n",
    "? [1, 2]\n: 3\n",
    "topics: {? [a]: odometry}\n",
    "topics:\n  /odom: {role: odometry, units: {x: [m]}}\n",
    "topics:\n  /odom: {role: odometry, fields: {[1]: x}}\n",
    "topics:\n  1: odometry\n",
    "topics:\n  /odom: {role: [odometry]}\n",
    "solver: {max_iterations: 1e400}\n",
    "\x00\x01binary",
    "grid: {resolution: .nan}\n",
    "grid: {resolution: -1}\n",
    "frontend: 7\n",
    "--- a\n--- b\n",
]


@FUZZ
@given(
    data=structures | st.dictionaries(KEYS, structures, max_size=4),
    raw=st.sampled_from(YAML_NASTY) | st.none(),
)
def test_run_config_rejects_nonsense_with_a_config_error(tmp_path_factory, data, raw):
    from holoslam.pipeline import load_run_config

    p = tmp_path_factory.mktemp("cfg") / "run.yaml"
    if raw is None:
        p.write_text(_dump(data), encoding="utf-8")
    else:
        p.write_bytes(raw.encode("utf-8", "surrogatepass"))
    try:
        load_run_config(p)
    except HoloslamError as e:
        assert "run.yaml" in str(e), str(e)


def test_run_config_refuses_python_tags(tmp_path):
    from holoslam.errors import ConfigError
    from holoslam.pipeline import load_run_config

    p = tmp_path / "evil.yaml"
    p.write_text("!!python/object/apply:os.system ['echo pwned']\n")
    with pytest.raises(ConfigError, match="evil.yaml"):
        load_run_config(p)


@pytest.fixture(scope="module")
def small_log(tmp_path_factory):
    from holoslam.io.mcap_write import example_records, write_ros2_log

    p = tmp_path_factory.mktemp("log") / "small.mcap"
    return write_ros2_log(p, example_records(seconds=1.0), chunk_size=2048)


def _mapping_structures():
    spec = st.one_of(
        _leaf,
        st.dictionaries(
            st.sampled_from(["role", "fields", "units", "extra"]),
            _leaf
            | st.dictionaries(
                st.sampled_from(["x", "y", "yaw", "stamp", "ranges", "q"]),
                _leaf | st.lists(_leaf, max_size=2),
                max_size=3,
            ),
            max_size=3,
        ),
    )
    return st.one_of(
        structures,
        st.fixed_dictionaries(
            {
                "topics": st.dictionaries(
                    st.sampled_from(["/odom", "/scan", "/x", ""]) | st.integers(), spec, max_size=3
                )
            }
        ),
    )


@FUZZ
@given(data=_mapping_structures(), raw=st.sampled_from(YAML_NASTY) | st.none())
def test_mapping_rejects_nonsense(tmp_path_factory, small_log, data, raw):
    from holoslam.io.mcap import load_mapping, read_log

    p = tmp_path_factory.mktemp("map") / "mapping.yaml"
    if raw is None:
        p.write_text(_dump(data), encoding="utf-8")
    else:
        p.write_bytes(raw.encode("utf-8", "surrogatepass"))
    try:
        load_mapping(p)
    except HoloslamError as e:
        assert "mapping.yaml" in str(e), str(e)
        return
    try:
        read_log(small_log, mapping=p)
    except HoloslamError as e:
        assert str(e)


@FUZZ
@given(data=_mapping_structures())
def test_mapping_dict_rejects_nonsense(data):
    from holoslam.io.mcap import load_mapping

    try:
        load_mapping(data if isinstance(data, dict) else {"topics": data})
    except HoloslamError as e:
        assert str(e)


# ------------------------------------------------------------------------------------------------- labels


@FUZZ
@given(
    text=st.text(max_size=80)
    | st.builds(lambda a, b: "HL1;" + a + ";" + b, st.text(max_size=20), st.text(max_size=30))
    | st.builds(lambda r: "HL1;O07;cup;" + r, st.text(alphabet="abcgmfs=,.;_-0123456789\x00é", max_size=40))
)
def test_label_payload_damage(text):
    from holoslam.errors import PayloadError
    from holoslam.vision.label import encode_label, parse_label

    try:
        lab = parse_label(text)
    except PayloadError as e:
        assert str(e)
        return
    assert parse_label(encode_label(lab)) == lab
    size = lab.size_m
    assert size is None or isinstance(size, float)


# ---------------------------------------------------------------------------------------------------- MCAP


@FUZZ
@given(
    ops=st.lists(
        st.tuples(
            st.sampled_from(["flip", "truncate", "insert", "zero"]),
            st.floats(0, 1),
            st.binary(min_size=1, max_size=16),
        ),
        min_size=1,
        max_size=3,
    )
)
def test_mcap_damage_reads_or_raises_an_ingest_error(tmp_path_factory, small_log, ops):
    from holoslam.io.mcap import format_report, format_summary, inspect_log, read_log

    raw = bytearray(small_log.read_bytes())
    for op, where, junk in ops:
        at = int(where * max(len(raw) - 1, 0))
        if op == "flip" and raw:
            raw[at] ^= junk[0] or 0xFF
        elif op == "truncate":
            del raw[at:]
        elif op == "insert":
            raw[at:at] = junk
        elif op == "zero":
            raw[at : at + 64] = bytes(len(raw[at : at + 64]))
    p = tmp_path_factory.mktemp("mcap") / "damaged.mcap"
    p.write_bytes(bytes(raw))
    try:
        _, rep = read_log(p)
        format_report(rep)
    except HoloslamError as e:
        assert "damaged.mcap" in str(e), str(e)
    try:
        format_summary(inspect_log(p))
    except HoloslamError as e:
        assert "damaged.mcap" in str(e), str(e)


# -------------------------------------------------------------------------------------------------- images


def _png_bytes() -> bytes:
    import cv2

    img = (np.arange(32 * 24 * 3) % 251).astype(np.uint8).reshape(24, 32, 3)
    ok, buf = cv2.imencode(".png", img)
    assert ok
    return buf.tobytes()


def _jpg_bytes() -> bytes:
    import cv2

    img = (np.arange(32 * 24 * 3) % 251).astype(np.uint8).reshape(24, 32, 3)
    ok, buf = cv2.imencode(".jpg", img)
    assert ok
    return buf.tobytes()


@FUZZ
@given(
    kind=st.sampled_from(["png", "jpg", "random"]),
    cut=st.floats(0, 1),
    junk=st.binary(max_size=64),
    encoding=st.sampled_from(
        ["png", "jpeg", "mono8", "rgb8", "bgra8", "16UC1", "32FC1", "yuv422", "", "PNG "]
    ),
    hw=st.tuples(st.integers(-2, 40), st.integers(-2, 40), st.integers(-1, 200)),
)
def test_image_damage_is_an_image_decode_error(tmp_path_factory, kind, cut, junk, encoding, hw):
    from holoslam.errors import ImageDecodeError
    from holoslam.io.images import decode_image, read_image_file
    from holoslam.types import Image
    from holoslam.vision.qr import decode_image_file

    good = {"png": _png_bytes, "jpg": _jpg_bytes, "random": lambda: b""}[kind]()
    data = good[: int(cut * len(good))] + junk
    p = tmp_path_factory.mktemp("img") / f"bad.{kind}"
    p.write_bytes(data)
    for fn in (read_image_file, decode_image_file):
        try:
            fn(p)
        except ImageDecodeError as e:
            assert "bad." in str(e), str(e)
    h, w, step = hw
    try:
        decode_image(
            Image(stamp_ns=1, frame_id="cam", encoding=encoding, data=data, height=h, width=w, step=step)
        )
    except ImageDecodeError as e:
        assert "cam" in str(e)


@pytest.mark.parametrize("size", [0, 1, 8, 100])
def test_truncated_png_names_the_file(tmp_path, size):
    from holoslam.errors import ImageDecodeError
    from holoslam.io.images import read_image_file

    p = tmp_path / "cut.png"
    p.write_bytes(_png_bytes()[:size])
    with pytest.raises(ImageDecodeError, match="cut.png"):
        read_image_file(p)


def test_nan_token_names_the_line():
    with pytest.raises(G2oFormatError, match=r"x\.g2o:2: "):
        parse_g2o("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 nan 0 0\n", source="x.g2o")
    assert math.isfinite(parse_g2o("VERTEX_SE2 0 1e300 0 0").vertex_poses[0, 0])


@pytest.fixture(scope="module")
def uncompressed_log_without_crc(tmp_path_factory):
    """An uncompressed log whose chunk CRCs are set to 0 ("not checked"), so byte damage reaches the message
    decoders instead of being caught by the chunk CRC."""
    from mcap.reader import make_reader

    from holoslam.io.mcap_write import example_records, write_ros2_log

    p = write_ros2_log(
        tmp_path_factory.mktemp("nocrc") / "plain.mcap",
        example_records(seconds=1.0),
        chunk_size=2048,
        compression="none",
    )
    with open(p, "rb") as f:
        offsets = [ci.chunk_start_offset for ci in make_reader(f).get_summary().chunk_indexes]
    raw = bytearray(p.read_bytes())
    for o in offsets:
        raw[o + 9 + 24 : o + 9 + 28] = bytes(4)
    p.write_bytes(bytes(raw))
    return p, len(offsets)


@FUZZ
@given(flips=st.lists(st.tuples(st.floats(0.02, 0.9), st.integers(1, 255)), min_size=1, max_size=6))
def test_mcap_damage_inside_unchecked_chunks(tmp_path_factory, uncompressed_log_without_crc, flips):
    from holoslam.io.mcap import format_report, inspect_log, read_log

    good, _ = uncompressed_log_without_crc
    raw = bytearray(good.read_bytes())
    for where, x in flips:
        raw[int(where * len(raw))] ^= x
    p = tmp_path_factory.mktemp("nocrc_dmg") / "damaged.mcap"
    p.write_bytes(bytes(raw))
    try:
        data, rep = read_log(p)
        format_report(rep)
    except HoloslamError as e:
        assert "damaged.mcap" in str(e), str(e)
    try:
        inspect_log(p)
    except HoloslamError as e:
        assert "damaged.mcap" in str(e), str(e)


def _png_header_only(w: int, h: int) -> bytes:
    import struct
    import zlib

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))

    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(bytes(10)))
        + chunk(b"IEND", b"")
    )


def test_png_declaring_a_huge_image_is_an_image_decode_error(tmp_path):
    """OpenCV raises cv2.error (not None) for a header over CV_IO_MAX_IMAGE_PIXELS."""
    from holoslam.errors import ImageDecodeError
    from holoslam.io.images import decode_image, read_image_file
    from holoslam.types import Image
    from holoslam.vision.qr import decode_image_file

    p = tmp_path / "huge.png"
    p.write_bytes(_png_header_only(100_000, 100_000))
    for fn in (read_image_file, decode_image_file):
        with pytest.raises(ImageDecodeError, match="huge.png.*too large"):
            fn(p)
    with pytest.raises(ImageDecodeError, match="frame 'cam'.*too large"):
        decode_image(Image(stamp_ns=1, frame_id="cam", encoding="png", data=p.read_bytes()))


@pytest.mark.parametrize("shape", [(0, 0), (0, 5), (4, 0, 3)])
def test_detect_qr_on_an_empty_image_is_a_vision_error(shape):
    from holoslam.errors import VisionError
    from holoslam.vision.qr import detect_qr

    with pytest.raises(VisionError, match="no pixels"):
        detect_qr(np.zeros(shape, np.uint8))


def test_g2o_path_that_is_a_directory(tmp_path):
    with pytest.raises(G2oFormatError, match="cannot read the file"):
        read_g2o(tmp_path)


def test_mapping_file_that_is_not_utf8(tmp_path):
    from holoslam.errors import ConfigError
    from holoslam.io.mcap import load_mapping

    p = tmp_path / "latin.yaml"
    p.write_bytes(b"topics:\n  /o\xff: odometry\n")
    with pytest.raises(ConfigError, match=r"latin\.yaml is not UTF-8 text \(byte 12\)"):
        load_mapping(p)


def test_run_config_empty_mapping_path(tmp_path):
    from holoslam.errors import ConfigError
    from holoslam.pipeline import load_run_config

    p = tmp_path / "run.yaml"
    p.write_text("mapping: ''\n")
    with pytest.raises(ConfigError, match=r"run\.yaml\.mapping: the path is empty"):
        load_run_config(p)
