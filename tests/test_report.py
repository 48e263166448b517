"""holoslam.report: the typed run report, its JSON form (report.json) and its text form (report.txt); and the
stage clock the run times its stages with (holoslam.timing)."""

from __future__ import annotations

import copy
import json

import pytest

from holoslam.report import Accuracy, RunReport, format_run_report
from holoslam.timing import StageClock


def _errors(rmse: float, coverage: float | None) -> dict:
    return {"rmse_m": rmse, "max_m": 2 * rmse, "heading_rmse_deg": 0.2, "n": 43, "coverage95": coverage}


# the shape of the bundled run's report.json (values shortened)
REPORT = {
    "source": "household_small.mcap",
    "inputs_absent": [],
    "ingest": {"channels": [{"topic": "/odom", "decoded": 10001, "failed": 0, "skipped": 0}], "warnings": [],
               "base_frame": "base_link"},
    "vision": {"images": 104, "decodes": 104, "foreign": 0, "tag_sightings": 0, "observations": 104,
               "source": "images", "problems": []},
    "submaps": {"count": 43, "split_reasons": {"scans": 43}, "loops_tried": 1597,
                "observations_before_first_anchor": 0, "nodes": 1916, "scans_localised_between_nodes": 584,
                "dead_reckoning_inflation": 1.288, "odometry_noise": {"source": "log", "reason": "propagated"},
                "loop_pairs": 151, "dead_reckoning_slips": 3, "keyframes_solved": True, "keyframe_matches": 2960,
                "keyframe_matches_tried": 3834, "keyframes_disputed": 0,
                "laser_mounting": {"laser_x_m": -0.018, "laser_x_std_m": 0.0007, "pairs": 4932, "turns": 2895,
                                   "tf_laser_x_m": 0.04, "centre_in_base_x_m": 0.058, "base_off_centre": True,
                                   "base_frame": "base_link", "laser_frame": "laser"},
                "odometer": {"scale": 0.9926, "scale_std": 0.0013, "yaw_deg_per_m": -0.916, "yaw_std": 0.072,
                             "stretches": 62, "distance_m": 122.7, "off": True},
                "loop_search": {"global searches": 12, "global: accepted (consistent)": 2, "windowed searches": 1585},
                "breaks": 1, "return_gap_m": 0.0817, "bridged_returns": True, "grid_cell_m": 0.05},
    "factors": {"relative_pose/dead_reckoning": 42, "relative_pose/loop": 497, "compass_heading": 42,
                "object_landmark": 104},
    "solver": {"method": "batch", "iterations": 9, "rounds": 3, "initial_error": 794.4, "final_error": 101.4,
               "rejected_measurements": 9, "compass_bias_deg": 3.124, "seconds": 0.044},
    "objects": {"count": 2, "ids": ["O01", "O22"],
                "moved": [{"id": "O01", "before": [1.0, 2.0, 0.5], "after": [1.5, 2.0, 0.5], "distance_m": 0.5}],
                "without_reach_edge": ["O22"], "unconfirmed": [],
                "located_by": {"O01": {"source": "images", "method": "pnp"},
                               "O22": {"source": "images", "method": "pnp"}}},
    "map": {"shape": [232, 214], "resolution_m": 0.05, "origin": [-3.6, -5.35], "free_cells": 28474,
            "occupied_cells": 2460},
    "topology": {"nodes": 48, "edges": 50, "spurs_pruned": 12, "spur_depth_m": 0.52},
    "holographic": {"environment_nodes": 26, "places": {"room": 7, "doorway": 6, "dead_end": 13}, "object_nodes": 2,
                    "object_edges": 1, "objects_with_edge": 1, "edges": 59, "connected": True},
    "planning": {"layer1_blocks": 2692, "layer2_regions": 228},
    "timings_s": {"ingest": 0.6, "vision": 1.2, "total": 24.0},
    "accuracy": {
        "anchors": _errors(0.0078, 0.977),
        "anchors_dead_reckoning": _errors(0.089, None),
        "trajectory": _errors(0.0082, None),
        "trajectory_dead_reckoning": _errors(0.09, None),
        "anchor_improvement_over_dead_reckoning": 11.41,
        "objects": {"rmse_m": 0.0088, "max_m": 0.021, "matched": 2, "missing": [], "unexpected": [],
                    "coverage95": 0.914, "per_object_m": {"O01": 0.005, "O22": 0.011}},
    },
    "frames": {"base": "base_link", "poses": {"laser": [0.04, 0.0, 0.0]}},
}


def test_the_json_form_reads_back_to_the_same_keys_order_and_values():
    report = RunReport.from_dict(REPORT)
    assert report.solver.final_error == 101.4 and report.objects.moved[0].distance_m == 0.5
    assert report.accuracy is not None and report.accuracy.objects is not None
    assert report.accuracy.objects.per_object_m["O22"] == 0.011
    out = report.to_dict()
    assert json.dumps(out) == json.dumps(REPORT)  # same keys, same order, same values
    assert RunReport.from_dict(out) == report


def test_absent_sections_stay_absent():
    """No world description: no object errors; exact anchors: no improvement ratio; no ground truth: no
    accuracy. Each is left out of the JSON form, as report.json always wrote it."""
    d = copy.deepcopy(REPORT)
    del d["accuracy"]["objects"], d["accuracy"]["anchor_improvement_over_dead_reckoning"]
    acc = Accuracy.from_dict(d["accuracy"])
    assert acc.objects is None and acc.anchor_improvement_over_dead_reckoning is None
    assert list(acc.to_dict()) == ["anchors", "anchors_dead_reckoning", "trajectory", "trajectory_dead_reckoning"]
    d["accuracy"] = None
    report = RunReport.from_dict(d)
    assert report.accuracy is None and report.to_dict()["accuracy"] is None
    assert "accuracy vs ground truth" not in report.text()


def test_a_report_from_another_version_reads():
    """Keys a section does not know are ignored; sections an older run lacks take their defaults."""
    d = copy.deepcopy(REPORT)
    d["solver"]["future_field"] = 1
    for k in ("nodes", "loop_pairs", "dead_reckoning_slips", "odometry_noise"):
        del d["submaps"][k]
    report = RunReport.from_dict(d)
    assert report.submaps.nodes is None and report.submaps.loop_pairs == 0
    assert "local SLAM" not in report.text() and "odometry noise" not in report.text()


def test_the_text_form_names_every_stage():
    text = RunReport.from_dict(REPORT).text()
    assert format_run_report(REPORT) == text == format_run_report(RunReport.from_dict(REPORT))
    lines = text.splitlines()
    assert lines[0] == "holoslam run of household_small.mcap"
    for start in ("  ingest: 1 channels, 10001 messages decoded", "  vision: sightings from images: 104 images",
                  "  submaps: 43 (scans 43); 1597 revisit", "  local SLAM: 1916 nodes", "  odometry noise: log",
                  "  factors: relative_pose/dead_reckoning 42", "  solver: batch, 9 iterations in 3 rounds, error 794.4",
                  "  objects: 2; moved: ['O01']; without a reach edge: ['O22']; unconfirmed (seen once): none",
                  "  objects located from: images by pnp 2", "  holographic graph: 26 environment nodes (room 7",
                  "  map: 214 x 232 cells at 0.05 m; topology 48 nodes / 50 edges (12 dead-end branches pruned: "
                  "less than 0.52 m beyond their junction's clearance); planning 2692 blocks",
                  "  accuracy vs ground truth: anchors 0.008 m RMSE (dead reckoning 0.089 m)",
                  "                            objects 0.009 m RMSE (max 0.021 m), 2 matched, missing none",
                  "  timings (s): ingest 0.60, vision 1.20, total 24.00"):
        assert sum(line.startswith(start) for line in lines) == 1, start
    (mounting,) = [line for line in lines if line.startswith("  laser mounting:")]
    assert "puts laser 0.018 m behind the point it turns about" in mounting
    assert "0.040 m ahead of base_link, so base_link is 0.058 m behind the turning centre" in mounting
    (fix,) = [line for line in lines if "if base_link should be the turning centre" in line]
    assert "xyz: [-0.018, Y, Z]" in fix


def test_a_skipped_vision_stage_says_why():
    d = copy.deepcopy(REPORT)
    d["vision"] = {"skipped": "the log has no images and no tag sightings"}
    assert "  vision: skipped (the log has no images and no tag sightings)" in RunReport.from_dict(d).text()


def test_the_stage_clock_times_stages_in_order_and_reports_progress():
    calls = []
    clock = StageClock(lambda *a: calls.append(a))
    with clock.stage("first"):
        clock.progress_of("first")(1, 2)
    with pytest.raises(ValueError), clock.stage("second"):
        raise ValueError("a failing stage is timed too")
    timings = clock.total()
    assert list(timings) == ["first", "second", "total"]
    assert all(v >= 0 for v in timings.values()) and timings["total"] >= timings["first"]
    assert calls == [("first",), ("first", 1, 2), ("second",)]


def test_a_background_clock_times_into_the_same_timings_and_announces_stages_without_progress():
    """The run's vision stages run in a thread beside the front end (``pipeline.slam_stages``): their stages are
    announced and timed in the run's timings, but their ``(done, total)`` progress would fight the front end's
    progress line, so it is dropped."""
    calls = []
    clock = StageClock(lambda *a: calls.append(a))
    bg = clock.background()
    with bg.stage("vision"):
        bg.progress_of("vision")(3, 10)
    with clock.stage("front end"):
        clock.progress_of("front end")(1, 2)
    assert list(clock.total()) == ["vision", "front end", "total"]
    assert calls == [("vision",), ("front end",), ("front end", 1, 2)]


def test_each_stage_gives_its_freed_memory_back(monkeypatch):
    """Issue 26: at the end of every stage the C heap's free pages go back to the OS (glibc malloc_trim): an
    80-minute building log's front end left 0.63 GB of freed heap resident otherwise."""
    from holoslam import timing

    calls: list[int] = []
    monkeypatch.setattr(timing, "_TRIM", calls.append)
    clock = timing.StageClock()
    with clock.stage("a"):
        pass
    with pytest.raises(RuntimeError), clock.stage("b"):
        raise RuntimeError("a failing stage gives its memory back too")
    assert calls == [0, 0] and set(clock.timings) == {"a", "b"}


def test_the_text_says_how_far_apart_the_lasers_returns_lie_and_what_the_submaps_made_of_it():
    """Neighbouring returns closer than a cell: the gap alone; farther apart and bridged: so; farther apart and not
    bridged (the default): that the walls are dotted and which setting bridges them."""
    import copy

    def submaps_line(**fields):
        r = copy.deepcopy(REPORT)
        r["submaps"].update(fields)
        (line,) = [t for t in RunReport.from_dict(r).text().splitlines() if t.startswith("  submaps:")]
        return line

    fine = submaps_line(return_gap_m=0.0325, bridged_returns=False)
    assert fine.endswith("neighbouring returns 3.2 cm apart at the median range")
    assert submaps_line(return_gap_m=0.0817, bridged_returns=True).endswith(
        "8.2 cm apart at the median range (wider than a cell: bridged in the submaps)")
    dotted = submaps_line(return_gap_m=0.0817, bridged_returns=False)
    assert "wider than the 5 cm cell: walls are dotted" in dotted and "bridge_over_cells: 1" in dotted
    assert "apart" not in submaps_line(return_gap_m=None)


def test_the_keyframes_line_says_how_many_were_disputed_only_when_some_were():
    """A slip of local SLAM inside a submap (``revisits.disputed_nodes``): the keyframes line counts the nodes placed
    apart by their two submaps; none, and the line is as before."""
    def keyframes_line(disputed: int) -> str:
        r = copy.deepcopy(REPORT)
        r["submaps"]["keyframes_disputed"] = disputed
        (line,) = [t for t in RunReport.from_dict(r).text().splitlines() if t.startswith("  keyframes:")]
        return line

    assert keyframes_line(0).endswith("2960 of 3834 matches into old submaps kept")
    assert "; 88 placed apart by their two submaps" in keyframes_line(88)
    assert "matched from both placements" in keyframes_line(88)
