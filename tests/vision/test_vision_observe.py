"""Wiring a log's images and tag sightings into object observations; landmark acceptance; the bundled
household log (when present) decodes to its ground-truth object set."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from repo_paths import REPO

from holoslam.errors import VisionError
from holoslam.sim.label_views import LabelInView, look_at_label, render_labels_view
from holoslam.types import CameraInfo, Image, LogData, TagSighting, Transform
from holoslam.vision.camera import OPTICAL_IN_BODY
from holoslam.vision.label import foreign_code_id
from holoslam.vision.observe import accept_landmarks, locate_from_log, observations_from_log

K = np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]])


def _quat_from_R(R: np.ndarray) -> tuple[float, float, float, float]:
    w = math.sqrt(max(0.0, 1 + np.trace(R))) / 2
    if w > 1e-6:
        return (
            (R[2, 1] - R[1, 2]) / (4 * w),
            (R[0, 2] - R[2, 0]) / (4 * w),
            (R[1, 0] - R[0, 1]) / (4 * w),
            w,
        )
    x = math.sqrt(max(0.0, 1 + R[0, 0] - R[1, 1] - R[2, 2])) / 2
    return (x, (R[0, 1] + R[1, 0]) / (4 * x), (R[0, 2] + R[2, 0]) / (4 * x), (R[2, 1] - R[1, 2]) / (4 * x))


def _log(tmp_stamps=(1_000, 2_000, 3_000)):
    import cv2

    labs = [
        LabelInView("HL1;O01;tv;s=120", 0.12, look_at_label(1.0, 20, offset_xy=(-0.2, 0.0))),
        LabelInView("HL1;O02;cup;g=handle,s=60", 0.06, look_at_label(0.5, -10, offset_xy=(0.1, 0.05))),
        LabelInView("hello world", 0.08, look_at_label(0.6, 0, offset_xy=(0.15, -0.12))),
    ]
    img, truths = render_labels_view(labs, K, seed=1)
    ok, png = cv2.imencode(".png", img)
    t0, t1, t2 = tmp_stamps
    images = (
        Image(t0, "camera_optical", "png", png.tobytes()),
        Image(t1, "camera_optical", "jpeg", b"\xff\xd8 corrupt"),
        Image(t2, "camera_optical", "png", png.tobytes()),
    )
    infos = tuple(CameraInfo(t, "camera_optical", 640, 480, K, np.zeros(5)) for t in (t0, t1, t2))
    # base -> ptz_base static (0.1 forward, 1.0 up), ptz_base -> camera_optical (pan 0.3) per image
    pan = 0.3
    R = (
        np.array([[math.cos(pan), -math.sin(pan), 0], [math.sin(pan), math.cos(pan), 0], [0, 0, 1]])
        @ OPTICAL_IN_BODY
    )
    tfs = [Transform(0, "base_link", "ptz_base", (0.1, 0.0, 1.0), (0, 0, 0, 1), static=True)]
    tfs += [
        Transform(t, "ptz_base", "camera_optical", (0.0, 0.0, 0.0), _quat_from_R(R)) for t in (t0, t1, t2)
    ]
    bTc = np.eye(4)
    bTc[:3, :3] = R
    bTc[:3, 3] = (0.1, 0.0, 1.0)
    tags = (
        TagSighting(t2, "camera_optical", labs[1].payload, truths[1]),
        TagSighting(t2, "camera_optical", "HL1;bad id;cup", truths[1]),
    )
    log = LogData("test", images=images, camera_infos=infos, transforms=tuple(tfs), tags=tags)
    truth_b = {lab.payload.split(";")[1]: (bTc @ np.r_[lab.cTo[:3, 3], 1])[:3] for lab in labs[:2]}
    # the labels' outward normals (their z axes) in the base frame
    truth_b.update({lab.payload.split(";")[1] + "/normal": bTc[:3, :3] @ lab.cTo[:3, 2] for lab in labs[:2]})
    return log, truth_b


def _deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(float(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


def test_observations_from_log_images_and_tags():
    log, truth_b = _log()
    obs, rep = observations_from_log(log, source="both")
    assert rep.source == "both" and rep.images == 3 and rep.corrupt_images == 1 and rep.images_decoded == 2
    assert rep.decodes == 6 and rep.foreign == 2 and rep.foreign_payloads == ("hello world",)
    assert rep.tag_sightings == 2 and rep.rejected_payloads == 1
    assert rep.duplicates_skipped == 1  # O02 at t2 came from /tags; its image decode is not counted twice
    assert rep.observations == len(obs) == 4 and rep.object_ids == ("O01", "O02")
    assert any(p.startswith("image 1 ") for p in rep.problems)
    for o in obs:
        err = np.linalg.norm(o.b_position - truth_b[o.object_id])
        assert err < 0.02 * np.linalg.norm(truth_b[o.object_id]), (o.object_id, err)
        assert np.all(np.linalg.eigvalsh(o.cov_b_position) > 0)
        # the label's normal from its decoded corners: measured 0.21 deg (O01, 20 deg off frontal at 1 m) and
        # 0.65 deg (O02, 10 deg at 0.5 m); their sigmas 4.5 and 6.4 deg (f = 600 px, no zoom)
        assert o.b_normal is not None
        n_err = _deg(o.b_normal, truth_b[o.object_id + "/normal"])
        assert n_err < 1.0 and 2.0 < math.degrees(o.normal_sigma_rad) < 10.0, (o.object_id, n_err)
    assert "observations of 2 objects" in rep.summary()


def test_pixels_first_the_tag_topic_when_asked_or_without_images():
    log, _ = _log()
    obs, rep = observations_from_log(log)  # auto: the log has images, its tag topic is not used
    assert rep.source == "images" and rep.tag_sightings == 0 and rep.rejected_payloads == 0
    assert rep.observations == len(obs) == 4 and rep.duplicates_skipped == 0
    obs, rep = observations_from_log(log, source="tags")
    assert rep.source == "tags" and rep.images == 0 and [o.object_id for o in obs] == ["O02"]
    no_images = LogData("x", camera_infos=log.camera_infos, transforms=log.transforms, tags=log.tags)
    obs, rep = observations_from_log(no_images)
    assert rep.source == "tags" and len(obs) == 1


def test_labels_without_size_and_foreign_codes_become_views_to_triangulate():
    log, truth = _log()
    r = locate_from_log(log)
    assert r.views == () and r.report.foreign == 2  # foreign codes are counted, not kept, by default
    r = locate_from_log(log, foreign=True)
    assert [v.object_id for v in r.views] == [foreign_code_id("hello world")] * 2
    assert r.report.foreign_views == 2 and r.report.sizeless == 0 and all(v.foreign for v in r.views)
    assert {s.object_id for s in r.sightings} == {"O01", "O02"}  # label sightings, for object features
    unsized = LogData("x", camera_infos=log.camera_infos, transforms=log.transforms,
                      tags=(TagSighting(3_000, "camera_optical", "HL1;O09;cup", log.tags[0].corners),))
    r = locate_from_log(unsized)
    (v,) = r.views
    assert v.object_id == "O09" and v.source == "tags" and r.report.sizeless == 1 and r.observations == ()
    assert np.allclose(v.centre_px, np.mean(log.tags[0].corners, axis=0), atol=1.0) and v.side_px > 10
    # a label without a size still gives its normal (the tag's corners are O02's, rendered without noise)
    assert v.b_normal is not None and _deg(v.b_normal, truth[("O02/normal")]) < 1.0


def test_missing_calibration_and_transform_are_reported():
    log, _ = _log()
    no_info = LogData("x", images=log.images[:1], transforms=log.transforms)
    obs, rep = observations_from_log(no_info)
    assert obs == () and rep.missing_camera_info == 2 and "CameraInfo" in rep.problems[0]
    no_tf = LogData("x", images=log.images[:1], camera_infos=log.camera_infos)
    obs, rep = observations_from_log(no_tf)
    assert obs == () and rep.missing_transform == 2
    unsized = LogData("x", tags=(TagSighting(5, "camera_optical", "HL1;O09;cup", np.zeros((4, 2))),))
    obs, rep = observations_from_log(unsized)
    assert obs == () and rep.missing_size == 1 and "printed size" in rep.problems[0]


def test_accept_landmarks_needs_consistent_decodes():
    rng = np.random.default_rng(0)
    ids = ["A"] * 3 + ["B"] * 2 + ["C"] * 4
    P = np.vstack(
        [
            rng.normal([1, 1, 0.5], 0.02, (3, 3)),
            rng.normal([5, 0, 1], 0.02, (2, 3)),
            [[0, 0, 0], [3, 0, 0], [0, 3, 0], [3, 3, 0]],
        ]
    )
    acc = accept_landmarks(ids, P, min_decodes=3, radius_m=0.3)
    assert set(acc) == {"A"}  # B has too few decodes, C's decodes disagree
    assert acc["A"].n_consistent == 3 and np.allclose(acc["A"].position, [1, 1, 0.5], atol=0.05)
    P2 = np.vstack([P, rng.normal([5, 0, 1], 0.02, (1, 3))])
    assert set(accept_landmarks(ids + ["B"], P2)) == {"A", "B"}
    with pytest.raises(VisionError):
        accept_landmarks(["A"], np.zeros((2, 3)))


BUNDLED = REPO / "datasets" / "household_small.mcap"


@pytest.mark.slow
@pytest.mark.skipif(not BUNDLED.exists(), reason="datasets/household_small.mcap not written yet")
def test_bundled_household_log_gives_ground_truth_object_set():
    from holoslam.io.mcap import read_log

    log, _ = read_log(BUNDLED)
    world = json.loads(log.world_json)
    objects = {o["id"]: o for o in world["objects"]}
    calls: list[tuple[int, int]] = []
    obs, rep = observations_from_log(log, source="images", progress=lambda d, n: calls.append((d, n)))
    assert rep.corrupt_images == 0 and rep.rejected_payloads == 0
    # progress followed the decoding: from 0, increasing, at most 50 calls, all against the image count
    done = [d for d, _ in calls]
    assert done[0] == 0 and done == sorted(set(done)) and 20 <= len(calls) <= 50
    assert {n for _, n in calls} == {len(log.images)}
    seen = set(rep.object_ids)
    assert seen <= set(objects)
    # every object the images show is found, positions agree with ground truth in the world frame
    gt_stamps, gt = log.ground_truth_arrays()
    ids, pos = [], []
    for o in obs:
        i = int(np.clip(np.searchsorted(gt_stamps, o.stamp_ns), 0, len(gt_stamps) - 1))
        x, y, th = gt[i]
        p = o.b_position
        pos.append(
            [
                x + math.cos(th) * p[0] - math.sin(th) * p[1],
                y + math.sin(th) * p[0] + math.cos(th) * p[1],
                p[2],
            ]
        )
        ids.append(o.object_id)
    tag_ids = {t.payload.split(";")[1] for t in log.tags}  # what the simulator says was readable
    assert seen == tag_ids
    acc = accept_landmarks(ids, np.array(pos), min_decodes=1, radius_m=0.3)
    assert set(acc) == seen
    for oid, lm in acc.items():
        truth = np.asarray(objects[oid]["position"], float)
        assert np.linalg.norm(lm.position[:2] - truth[:2]) < 0.3, oid
