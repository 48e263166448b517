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


# ------------------------------------------------------------------ wiring on the bundled household log


@pytest.fixture(scope="module")
def household():
    from holoslam.io.datasets import bundled_household_log
    from holoslam.io.mcap import read_log
    from holoslam.vision.locate import base_to_submap
    from holoslam.vision.observe import accept_landmarks, observations_from_log

    log, _ = read_log(bundled_household_log())
    obs, _report = observations_from_log(log)
    stamps, wTb = log.ground_truth_arrays()
    idx = np.abs(stamps[None, :] - np.array([o.stamp_ns for o in obs])[:, None]).argmin(axis=1)
    w_pos = np.array(
        [base_to_submap(wTb[i], o.b_position, o.cov_b_position)[0] for i, o in zip(idx, obs, strict=True)]
    )
    accepted = accept_landmarks([o.object_id for o in obs], w_pos)
    world = {o["id"]: o for o in json.loads(log.world_json)["objects"]}
    return log, obs, accepted, world


def test_object_features_from_household_log(household):
    from holoslam.vision.features import object_features_from_log

    log, obs, accepted, world = household
    assert len(accepted) >= 10
    feats = object_features_from_log(log, obs, accepted=accepted, max_crops=2, max_sift=50)
    assert set(feats) == set(accepted) and set(feats) <= set(world)
    image_stamps = {im.stamp_ns for im in log.images}
    for oid, f in feats.items():
        truth = world[oid]
        assert f.size_m == pytest.approx(truth["label_size"])  # from the label's s attribute
        assert 0.2 < f.range_m < 8.0
        assert 1 <= f.n_crops <= 2 and set(f.crop_stamps_ns) <= image_stamps
        assert f.texture.sum() == pytest.approx(1.0) and f.colour_weights.sum() == pytest.approx(1.0)
        s = json.loads(json.dumps(f.to_summary()))
        assert s["object_id"] == oid and s["n_crops"] == f.n_crops and len(s["texture_lbp"]) == 10
    # the same objects and features whether the robot's tag sightings or the observations are given
    from_tags = object_features_from_log(log, log.tags, accepted=accepted, max_crops=2, max_sift=50)
    assert set(from_tags) == set(feats)
    for oid in feats:
        assert np.allclose(from_tags[oid].texture, feats[oid].texture)
        assert np.allclose(from_tags[oid].colours_lab, feats[oid].colours_lab, atol=1e-6)


def test_object_crops_mask_the_label_and_report_problems(household):
    from holoslam.types import ObjectObservation
    from holoslam.vision.features import dominant_colours, object_crops_from_log

    log, obs, accepted, _world = household
    oid = sorted(accepted)[0]
    mine = [o for o in obs if o.object_id == oid]
    lost = ObjectObservation(1, oid, mine[0].payload, mine[0].b_position, mine[0].cov_b_position)
    crops, problems = object_crops_from_log(log, [*mine, lost])
    assert set(crops) == {oid} and len(crops[oid]) == len({o.stamp_ns for o in mine})
    assert len(problems) == 1 and "no image within" in problems[0] and oid in problems[0]
    c = next(c for c in crops[oid] if c.crop.shape[0] == c.crop.shape[1])  # a crop not clipped by the image
    assert c.mask is not None and c.mask.shape == c.crop.shape[:2] and max(c.crop.shape) <= 256
    # the crop is centred on the label: its centre is masked out, the crop's corner (object) is kept
    h, w = c.mask.shape
    assert c.mask[h // 2, w // 2] == 0 and c.mask[0, 0] == 255
    # the code's black ink is a dominant colour of the bare crop but gone once the label is masked
    bare, _ = dominant_colours([c.crop], k=3)
    masked, _ = dominant_colours([c.crop], k=3, masks=[c.mask])
    assert bare[:, 0].min() < 30 and masked[:, 0].min() > 30


def test_lbp_mask_selects_pixels():
    img = np.zeros((40, 40), np.uint8)
    img[:, 20:] = (np.random.default_rng(2).random((40, 20)) * 255).astype(np.uint8)
    mask = np.zeros((40, 40), np.uint8)
    mask[:, :15] = 255
    assert lbp_histogram(img, mask)[8] == 1.0  # only the flat half
    with pytest.raises(VisionError):
        lbp_histogram(img, np.zeros((40, 40), np.uint8))
