"""Eq. 13 object features: texture, dominant colours, SIFT, crops, JSON summary."""

from __future__ import annotations

import json

import numpy as np
import pytest

from holoslam.errors import VisionError
from holoslam.vision.features import crop_around_label, dominant_colours, lbp_histogram, object_features


def test_lbp_flat_vs_textured():
    flat = np.full((40, 40), 120, np.uint8)
    h = lbp_histogram(flat)
    assert h.shape == (10,) and h.sum() == pytest.approx(1.0) and h[8] == 1.0  # all neighbours >= centre
    noise = (np.random.default_rng(0).random((60, 60)) * 255).astype(np.uint8)
    hn = lbp_histogram(noise)
    assert hn[9] > 0.3  # random texture: many non-uniform patterns
    assert np.allclose(lbp_histogram(np.rot90(noise)), hn, atol=0.02)  # rotation invariant (up to sampling)


def test_dominant_colours_recovers_two_colours():
    img = np.zeros((50, 100, 3), np.uint8)
    img[:, :70] = (0, 0, 255)  # red (BGR), 70 %
    img[:, 70:] = (255, 255, 255)  # white, 30 %
    c, w = dominant_colours([img], k=2)
    assert np.allclose(w, [0.7, 0.3], atol=1e-6)
    assert c[0, 1] > 50 and abs(c[1, 1]) < 2 and c[1, 0] > 95  # red has large a*, white is L~100, a~0


def test_object_features_summary_is_json():
    rng = np.random.default_rng(1)
    crops = [(rng.random((80, 80, 3)) * 255).astype(np.uint8) for _ in range(2)]
    f = object_features("O01", crops, size_m=0.06, ranges_m=[1.0, 2.0])
    s = f.to_summary()
    json.dumps(s)
    assert s["n_crops"] == 2 and s["size_m"] == 0.06 and s["range_m"] == 1.5
    assert f.keypoints.shape[1] == 5 and f.descriptors.shape == (f.keypoints.shape[0], 128)
    assert f.keypoints.shape[0] > 0 and not f.texture.flags.writeable
    with pytest.raises(VisionError):
        object_features("O02", [])


def test_crop_around_label():
    img = np.zeros((100, 200), np.uint8)
    c = np.array([[90, 40], [110, 40], [110, 60], [90, 60]], float)
    assert crop_around_label(img, c, 3.0).shape == (61, 61)  # centre +- 30 px, inclusive
    with pytest.raises(VisionError):
        crop_around_label(img, c + 1000)
