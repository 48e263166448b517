"""The text form of the run report's records (report.txt, what ``holoslam run`` prints): one function per
record of :class:`holoslam.report.RunReport`, each a list of lines."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from holoslam.report_records import Accuracy, ObjectSummary, SubmapSummary


def _ingest_text(ing: Mapping[str, Any]) -> list[str]:
    chans = ing.get("channels", [])
    lines = [
        f"  ingest: {len(chans)} channels, {sum(c.get('decoded', 0) for c in chans)} messages decoded, "
        f"{sum(c.get('failed', 0) for c in chans)} failed, {sum(c.get('skipped', 0) for c in chans)} "
        f"skipped, {len(ing.get('warnings', []))} warnings"
        + (f", {len(ing['lost'])} damaged stretch(es) left out" if ing.get("lost") else "")
        + f"; base frame {ing.get('base_frame', '?')}"
    ]
    for c in ing.get("choices", []):
        lines.append(f"    {c['role']}: {c['topic']} used, not {', '.join(c['others'])} ({c['rule']})")
    lines.extend(f"    levelled: {m}" for m in ing.get("levelled", []))
    return lines + _ingest_problems(ing)


def _ingest_problems(ing: Mapping[str, Any]) -> list[str]:
    """The log's damage and doubts, each on a line (what, where, what was kept): the run goes on with every good
    record, and a user reading only the printed report must still learn what it did without."""
    lines = []
    t0 = ing.get("start_ns") or 0
    for x in ing.get("lost", []):
        start, end = x.get("start_ns") or 0, x.get("end_ns") or 0
        span = (f"{(start - t0) / 1e9:.1f}..{(end - t0) / 1e9:.1f} s into the log ({(end - start) / 1e9:.1f} s)"
                if end else "time range unknown")
        lines.append(f"    lost: {Path(x.get('file', '?')).name} byte {x.get('offset')}: {span}: {x.get('reason')}; "
                     "every record outside it is used")
    lines.extend(f"    missing transform: {m}" for m in ing.get("missing_transforms", []))
    lines.extend(f"    re-based: {m}" for m in ing.get("rebased", []))
    for c in ing.get("channels", []):
        if c.get("failed"):
            lines.append(f"    failed: {c['topic']}: {c['failed']} message(s) not decoded, kept out; first error: "
                         f"{c.get('first_error', '')}")
    lines.extend(f"    warning: {w}" for w in ing.get("warnings", []))
    if lines:
        lines.append(f"    (holoslam inspect {ing.get('source') or 'LOG'} lists every problem of the log by channel)")
    return lines


def _vision_text(v: Mapping[str, Any]) -> list[str]:
    if "skipped" in v:
        return [f"  vision: skipped ({v['skipped']})"]
    lines = [
        f"  vision: sightings from {v.get('source') or '?'}: {v['images']} images, {v['decodes']} codes "
        f"decoded, {v['tag_sightings']} robot sightings, {v['observations']} object observations (PnP), "
        f"{v['foreign']} foreign codes"
    ]
    if v.get("images") and "full_decodes" in v:  # the stream steps (holoslam.vision.stream): what was skipped
        lines.append(
            f"  frames: {v['images']} ({v.get('images_decoded', 0)} with codes): {v['full_decodes']} decoded in full, "
            f"skipped {v.get('skipped_no_code', 0)} without a code (quick look) and {v.get('skipped_same_view', 0)} "
            f"showing the view just decoded; {v.get('frames_per_s') or float('nan'):.0f} frames/s"
        )
    t = v.get("triangulation")
    if t:
        lines.append(
            f"  triangulation: {t['views']} views of {t['codes']} codes without a printed size or foreign "
            f"-> {t['points']} points ({t['views_unused']} views unused); {t.get('laser_ranged', 0)} views "
            "ranged by the laser instead"
        )
    return lines


def _gap_note(sm: SubmapSummary) -> str:
    """What the submaps made of a laser whose neighbouring returns lie farther apart than a cell."""
    if sm.bridged_returns:
        return " (wider than a cell: bridged in the submaps)"
    if sm.return_gap_m and sm.grid_cell_m and sm.return_gap_m > sm.grid_cell_m:
        return (f" (wider than the {100 * sm.grid_cell_m:.0f} cm cell: walls are dotted; "
                "frontend.local.grid.bridge_over_cells: 1 bridges them, README *Coarse beams*)")
    return ""


def _submaps_text(sm: SubmapSummary) -> list[str]:
    lines = [
        f"  submaps: {sm.count} ({', '.join(f'{k} {n}' for k, n in sm.split_reasons.items())}); "
        f"{sm.loops_tried} revisit registrations tried"
        + (f"; neighbouring returns {100 * sm.return_gap_m:.1f} cm apart at the median range" + _gap_note(sm)
           if sm.return_gap_m else "")
    ]
    if sm.nodes is not None:
        lines.append(
            f"  local SLAM: {sm.nodes} nodes matched into submaps, {sm.scans_localised_between_nodes} scans "
            f"localised between them; dead-reckoning covariance x{sm.dead_reckoning_inflation} (calibrated "
            f"against the scan matches; {sm.dead_reckoning_slips} slipped segments down-weighted), loop "
            f"closures between {sm.loop_pairs} anchor pairs (each pair's count as one)"
        )
    if sm.loop_search:
        lines.append("  loop search: " + ", ".join(f"{k} {v}" for k, v in sm.loop_search.items())
                     + (f"; the submaps began afresh {sm.breaks} time(s) (lost: a gap in the laser, or "
                        "scans that fit nowhere near the odometry: carried)" if sm.breaks else ""))
    if sm.keyframes_solved:
        lines.append(
            f"  keyframes: solved as poses against the old submaps they revisit, {sm.keyframe_matches} of "
            f"{sm.keyframe_matches_tried} matches into old submaps kept"
            + (f"; {sm.keyframes_disputed} placed apart by their two submaps beyond the stage's max_shift_m (a slip "
               "of local SLAM inside one): matched from both placements, placed by their matches"
               if sm.keyframes_disputed else "")
        )
    if sm.odometry_noise:
        lines.append(f"  odometry noise: {sm.odometry_noise['source']} ({sm.odometry_noise['reason']})")
    if sm.laser_mounting:
        from holoslam.submaps.mounting import mounting_text

        lines.extend(mounting_text(sm.laser_mounting))
    if sm.odometer:
        from holoslam.submaps.odometer import odometer_text

        lines.extend(odometer_text(sm.odometer))
    return lines


def _objects_text(o: ObjectSummary) -> list[str]:
    lines = [
        f"  objects: {o.count}; moved: {[m.id for m in o.moved] or 'none'}; "
        f"without a reach edge: {o.without_reach_edge or 'none'}; "
        f"unconfirmed (seen once): {o.unconfirmed or 'none'}"
    ]
    if o.located_by:
        ways = Counter(f"{d['source']} by {d['method']}" for d in o.located_by.values())
        lines.append("  objects located from: " + ", ".join(f"{k} {n}" for k, n in sorted(ways.items())))
    return lines


def _accuracy_text(acc: Accuracy) -> list[str]:
    a, d = acc.anchors, acc.anchors_dead_reckoning
    lines = [
        f"  accuracy vs ground truth: anchors {a.rmse_m:.3f} m RMSE (dead reckoning {d.rmse_m:.3f} m),"
        f" heading {a.heading_rmse_deg:.2f} deg, 95% ellipse coverage {a.coverage95}"
    ]
    if acc.objects is not None:
        ob = acc.objects
        lines.append(
            f"                            objects {ob.rmse_m:.3f} m RMSE (max {ob.max_m:.3f} m), "
            f"{ob.matched} matched, missing {ob.missing or 'none'}"
        )
    return lines
