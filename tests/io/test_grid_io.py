"""map_server PGM / PNG + YAML round trips and clear errors."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from holoslam.errors import MapError
from holoslam.io.grid import (
    decode_pgm,
    encode_pgm,
    grid_picture,
    read_grid,
    read_map_yaml,
    write_grid,
    write_grid_png,
)
from holoslam.maps.grid import OccupancyGrid

trinary = arrays(
    np.int8, st.tuples(st.integers(1, 12), st.integers(1, 12)), elements=st.sampled_from([-1, 0, 100])
)


@settings(max_examples=40, deadline=None)
@given(trinary, st.sampled_from(["pgm", "png"]), st.booleans())
def test_trinary_round_trip_is_lossless(tmp_path_factory, occ, fmt, negate):
    d = tmp_path_factory.mktemp("g")
    g = OccupancyGrid(occ, 0.05, -1.25, 3.5)
    write_grid(g, d / "map.yaml", image_format=fmt, negate=negate)
    back = read_grid(d / "map.yaml")
    assert np.array_equal(back.occupancy, g.occupancy)
    assert (back.resolution, back.origin_x, back.origin_y) == (0.05, -1.25, 3.5)


@settings(max_examples=30, deadline=None)
@given(arrays(np.int8, (5, 7), elements=st.integers(-1, 100)))
def test_raw_round_trip_keeps_every_value(tmp_path_factory, occ):
    d = tmp_path_factory.mktemp("r")
    g = OccupancyGrid(occ, 0.1, occupied_thresh=0.7, free_thresh=0.2)
    write_grid(g, d / "m.yaml", mode="raw")
    back = read_grid(d / "m.yaml")
    assert np.array_equal(back.occupancy, occ)
    assert (back.occupied_thresh, back.free_thresh) == (0.7, 0.2)


def test_pgm_top_row_is_max_y_and_values(tmp_path):
    occ = np.full((3, 4), 0, np.int8)
    occ[2, :] = 100  # row 2 = highest y
    occ[0, 0] = -1
    img_path = write_grid(OccupancyGrid(occ, 0.5), tmp_path / "m.yaml")
    data = img_path.read_bytes()
    assert data.startswith(b"P5")
    img = decode_pgm(data)
    assert (img[0] == 0).all()  # first image row: top = occupied
    assert img[2, 0] == 205 and img[2, 1] == 254
    text = (tmp_path / "m.yaml").read_text()
    assert "mode: trinary" in text and "image: m.pgm" in text


def test_reads_hand_written_map_with_comment_and_scale_mode(tmp_path):
    img = np.array([[0, 128, 255], [254, 205, 10]], np.uint8)
    pgm = b"P5\n# made by hand\n3 2\n255\n" + img.tobytes()
    (tmp_path / "a.pgm").write_bytes(pgm)
    (tmp_path / "a.yaml").write_text(
        "image: a.pgm\nresolution: 0.1\norigin: [1.0, 2.0, 0.0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\nmode: scale\n"
    )
    g = read_grid(tmp_path / "a.yaml")
    # bottom image row becomes grid row 0
    assert g.occupancy[1].tolist() == [100, 66, 0]  # p(128) = 0.498 -> 99 * (0.498 - 0.196) / 0.454 = 65.9
    assert g.occupancy[0].tolist() == [0, 0, 100]
    assert (g.origin_x, g.origin_y) == (1.0, 2.0)


def test_ascii_pgm_and_png_colour(tmp_path):
    assert decode_pgm(b"P2\n2 1\n255\n0 254\n").tolist() == [[0, 254]]
    import cv2

    colour = np.zeros((2, 2, 3), np.uint8)
    colour[0, 0] = 254
    cv2.imwrite(str(tmp_path / "c.png"), colour)
    (tmp_path / "c.yaml").write_text("image: c.png\nresolution: 1\norigin: [0, 0, 0]\n")
    g = read_grid(tmp_path / "c.yaml")
    assert g.occupancy[1, 0] == 0 and g.occupancy[0, 0] == 100


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("resolution: 0.1\norigin: [0, 0, 0]\n", "missing key"),
        ("image: a.pgm\nresolution: -0.1\norigin: [0, 0, 0]\n", "resolution must be positive"),
        ("image: a.pgm\nresolution: 0.1\norigin: [0, 0]\n", r"origin must be \[x, y, yaw\]"),
        ("image: a.pgm\nresolution: 0.1\norigin: [0, 0, 0.5]\n", "yaw"),
        ("image: a.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nmode: fancy\n", "mode must be"),
        ("image: a.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nfree_thresh: 0.9\n", "free_thresh < occupied"),
        ("image: a.pgm\nresolution: abc\norigin: [0, 0, 0]\n", "finite number"),
        ("- just\n- a list\n", "mapping"),
        ("image: [unclosed\n", "not valid YAML"),
        ("image: missing.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n", "cannot read map image"),
    ],
)
def test_nonsense_yaml_gives_clear_errors(tmp_path, text, match):
    (tmp_path / "a.pgm").write_bytes(encode_pgm(np.zeros((2, 2), np.uint8)))
    (tmp_path / "m.yaml").write_text(text)
    with pytest.raises(MapError, match=match):
        read_grid(tmp_path / "m.yaml")


def test_bad_images_and_outside_folder_note(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "x.pgm").write_bytes(encode_pgm(np.full((2, 3), 254, np.uint8)))
    (tmp_path / "sub" / "m.yaml").write_text("image: ../x.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n")
    meta = read_map_yaml(tmp_path / "sub" / "m.yaml")
    assert meta.notes and "outside" in meta.notes[0]
    assert read_grid(tmp_path / "sub" / "m.yaml").free.all()  # still read
    with pytest.raises(MapError, match="truncated|body has"):
        decode_pgm(b"P5\n4 4\n255\n\x00\x00")
    with pytest.raises(MapError, match="not a PGM"):
        decode_pgm(b"P6\n1 1\n255\n\x00\x00\x00")
    (tmp_path / "junk.png").write_bytes(b"not an image")
    (tmp_path / "j.yaml").write_text("image: junk.png\nresolution: 0.1\norigin: [0, 0, 0]\n")
    with pytest.raises(MapError, match="not a readable image"):
        read_grid(tmp_path / "j.yaml")


def test_picture(tmp_path):
    occ = np.array([[0, 100], [-1, 50]], np.int8)
    pic = grid_picture(OccupancyGrid(occ, 1.0), scale=3)
    assert pic.shape == (6, 6)
    assert pic[5, 0] == 255 and pic[5, 5] == 0 and pic[0, 0] == 160 and pic[0, 5] == 128
    p = write_grid_png(OccupancyGrid(occ, 1.0), tmp_path / "g.png", scale=2)
    assert p.read_bytes()[:4] == b"\x89PNG"
