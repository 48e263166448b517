"""A run's output folder: writing every file of SPEC §6 and loading a saved run back.

Files (all under the folder the caller names; nothing is written elsewhere)::

    trajectory.tum          optimised base trajectory (TUM: stamp s, x y z qx qy qz qw)
    dead_reckoning.tum      dead reckoning, same stamps
    anchors.csv             submap anchors: stamp_ns, x, y, theta and the 3x3 covariance (body frame, row-major)
    objects.csv             objects: id, type, x, y, z, the 2x2 xy covariance (world frame), payload, sightings
    graph.g2o               the pose graph (anchors, relative-pose edges, object points and sightings)
    map.pgm + map.yaml      occupancy grid (ROS map_server), map.png picture
    topology.graphml/.json  thinning topology (edge paths simplified to the map's resolution)
    holographic.graphml/.json  holographic graph (kind = environment | object; objects keyed by id; passages
                            simplified to the map's resolution)
    rooms.png               room label image: 16-bit PNG the map's size (rows as map.pgm), 0 = not a room,
                            k = the room node room:<k> (its room_id) of the holographic graph
    planning.json           two-layer planning graph (layer 2; layer 1's blocks in planning_layer1.npz)
    report.json, report.txt the run report
    results.mcap            Foxglove view of the results
    trajectory.png, map_topology.png, holographic.png, planning.png   pictures
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from holoslam.errors import ConfigError, IngestError
from holoslam.io.jsonsafe import dumps

__all__ = [
    "SavedRun",
    "write_run",
    "load_run",
    "export_saved",
    "prepare_output_folder",
    "prepare_run_folder",
    "RUN_FILES",
]

RUN_FILES = (
    "trajectory.tum",
    "graph.g2o",
    "map.pgm",
    "map.yaml",
    "map.png",
    "topology.graphml",
    "holographic.graphml",
    "holographic.json",
    "planning.json",
    "planning_layer1.npz",
    "report.json",
    "report.txt",
)


def prepare_output_folder(out_dir: str | Path) -> Path:
    """Create ``out_dir`` (and its parents) and check a file can be written in it, so a run finds out before
    its work, not after. Raises ``ConfigError`` (one line: which folder, why, what to do)."""
    from holoslam.io.atomic_folder import check_writable

    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"output {out} exists and is not a folder; name a folder for the run's files")
    check_writable(out, out)
    return out



def _anchors_csv(stamps: np.ndarray, wTa: np.ndarray, cov: np.ndarray | None) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["stamp_ns", "x", "y", "theta"] + [f"cov_{r}{c}" for r in "xyt" for c in "xyt"])
    for k, (s, T) in enumerate(zip(stamps, wTa, strict=True)):
        c = np.full(9, np.nan) if cov is None else np.asarray(cov[k]).reshape(9)
        w.writerow([int(s)] + [repr(float(v)) for v in T] + [repr(float(v)) for v in c])
    return buf.getvalue()


def _objects_csv(objects: Sequence[Any]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["id", "type", "x", "y", "z", "cov_xx", "cov_xy", "cov_yy", "payload", "sightings"])
    for o in objects:
        c = o.cov_w_position
        w.writerow(
            [o.object_id, o.object_type]
            + [repr(float(v)) for v in o.w_position]
            + [repr(float(c[0, 0])), repr(float(c[0, 1])), repr(float(c[1, 1])), o.payload, int(o.sightings)]
        )
    return buf.getvalue()


def _graph_g2o(result: Any) -> Any:
    """The run's pose graph as a G2oGraph: anchors 0..K-1, objects numbered K.. in order of their ids."""
    from holoslam.io.g2o import G2oGraph

    p, sol = result.problem, result.solution
    ids = list(sol.landmark_ids)
    num = {oid: len(sol.wTa) + k for k, oid in enumerate(ids)}
    lm = p.landmarks
    keep = [k for k, name in enumerate(lm.landmark) if name in num] if lm is not None else []
    return G2oGraph(
        vertex_ids=np.arange(len(sol.wTa)),
        vertex_poses=sol.wTa,
        point_ids=np.array([num[i] for i in ids], dtype=np.int64),
        point_positions=sol.w_landmarks.reshape(-1, 2),
        edge_i=p.relative.i,
        edge_j=p.relative.j,
        edge_measured=p.relative.iTj,
        edge_cov=p.relative.cov_iTj,
        landmark_pose=lm.i[keep] if keep else np.zeros(0, np.int64),
        landmark_id=np.array([num[lm.landmark[k]] for k in keep], dtype=np.int64),
        landmark_measured=lm.a_position[keep] if keep else np.zeros((0, 2)),
        landmark_cov=lm.cov_a_position[keep] if keep else np.zeros((0, 2, 2)),
        fixed_ids=np.array([0], dtype=np.int64),
        source=str(result.source),
    )


def _scene(stamps, wTb, dr, wTa, grid, objects, topology, holographic):
    from holoslam.io.results_mcap import ResultsScene

    edges = []
    if topology is not None:
        segs = [
            [
                (topology.nodes[u]["x"], topology.nodes[u]["y"]),
                (topology.nodes[v]["x"], topology.nodes[v]["y"]),
            ]
            for u, v in topology.edges()
        ]
        edges.append(("topology", np.array(segs).reshape(-1, 2, 2)))
    if holographic is not None:
        segs = []
        for u, v in holographic.edges():
            a, b = holographic.nodes[u], holographic.nodes[v]
            if all(k in a for k in ("x", "y")) and all(k in b for k in ("x", "y")):
                segs.append([(a["x"], a["y"]), (b["x"], b["y"])])
        edges.append(("holographic", np.array(segs).reshape(-1, 2, 2)))
    return ResultsScene(
        stamps_ns=stamps,
        wTb=wTb,
        dead_reckoning_wTb=dr,
        wTa=wTa,
        grid=grid,
        object_ids=[o.object_id for o in objects],
        w_objects=np.array([o.w_position for o in objects]).reshape(-1, 3),
        edges=edges,
    )


def _pictures(
    out: Path, wTb, dr, wTa, cov_wTa, grid, topology, holographic, planning, gt=None, rooms=None
) -> list[Path]:
    from holoslam import viz
    from holoslam.timing import release_free_memory

    trajs = {"dead reckoning": dr, "optimised": wTb}
    if gt is not None:
        trajs["ground truth"] = gt

    def trajectory() -> Any:
        fig = viz.trajectory_figure(trajs, grid=grid, title="trajectory", every=max(1, len(wTb) // 60))
        if cov_wTa is not None and np.all(np.isfinite(cov_wTa)):
            viz.draw_trajectory(
                fig.axes[0], wTa, cov_wTa, every=1, colour="black", label="anchors (2-sigma ellipses)", points=True
            )
            fig.axes[0].legend(fontsize=7)
        return fig

    figures: tuple[tuple[str, Callable[[], Any]], ...] = (
        ("trajectory.png", trajectory),
        ("map_topology.png",
         lambda: viz.map_figure(grid, topology=topology, title="occupancy grid and thinning topology")),
        ("holographic.png",
         lambda: viz.map_figure(grid, holographic=holographic, rooms=rooms, title="holographic graph and rooms")),
        ("planning.png", lambda: viz.map_figure(grid, planning=planning, title="two-layer planning graph (regions)")),
    )  # fmt: skip
    written = []
    for name, make in figures:  # one figure alive at a time: each holds its pooled images and artists
        p = out / name
        fig = make()
        fig.savefig(p, dpi=110)
        fig.clf()
        del fig
        release_free_memory()
        written.append(p)
    return written


_OTHER_FILES = (
    "dead_reckoning.tum",
    "anchors.csv",
    "objects.csv",
    "topology.json",
    "rooms.png",
    "results.mcap",
    "trajectory.png",
    "map_topology.png",
    "holographic.png",
    "planning.png",
    "run.json",
)


def replaceable(folder: Path) -> str:
    """Why an existing folder must not be replaced by a run's folder ('' when it may): a run folder holds only
    the files a run writes; anything else (a user's folder named by mistake) is kept and the run refused."""
    known = set(RUN_FILES + _OTHER_FILES)
    try:
        foreign = sorted(p.name for p in folder.iterdir() if p.name not in known)
    except OSError:
        return ""
    if not foreign:
        return ""
    more = f" and {len(foreign) - 3} more" if len(foreign) > 3 else ""
    return (
        f"holds files a run does not write ({', '.join(foreign[:3])}{more}) and would be replaced by the run's "
        "folder; name a new folder (-o) or empty this one"
    )


def prepare_run_folder(out_dir: str | Path) -> Path:
    """Check before a run that ``out_dir`` can become its folder (see ``check_target``); nothing is created but
    the parent folders. Raises ``ConfigError`` (one line)."""
    from holoslam.io.atomic_folder import check_target

    return check_target(out_dir, replaceable)


def _write_files(result: Any, out: Path, pictures: bool, results_mcap: bool) -> None:
    """Every output file of a ``RunResult`` into ``out`` (a fresh folder), each step a checkpoint."""
    from holoslam.io.atomic_folder import _checkpoint
    from holoslam.io.g2o_write import write_g2o
    from holoslam.io.graphs import write_graph_files
    from holoslam.io.grid import write_grid, write_grid_png, write_label_png
    from holoslam.io.planning import write_planning
    from holoslam.io.results_mcap import write_results_mcap
    from holoslam.io.trajectory import write_tum
    from holoslam.maps.polyline import compact_paths
    from holoslam.maps.topology import to_graphml_ready

    steps: list[tuple[str, Callable[[], Any]]] = [
        ("trajectory.tum", lambda: write_tum(out / "trajectory.tum", result.stamps_ns, result.wTb)),
        ("dead_reckoning.tum",
         lambda: write_tum(out / "dead_reckoning.tum", result.stamps_ns, result.dead_reckoning_wTb)),
        ("anchors.csv", lambda: (out / "anchors.csv").write_text(
            _anchors_csv(result.anchor_stamps_ns, result.wTa, result.cov_wTa))),
        ("objects.csv", lambda: (out / "objects.csv").write_text(_objects_csv(result.objects))),
        ("graph.g2o", lambda: write_g2o(_graph_g2o(result), out / "graph.g2o")),
        ("map.yaml", lambda: write_grid(result.grid, out / "map.yaml")),
        ("map.png", lambda: write_grid_png(result.grid, out / "map.png")),
        # paths and passages simplified to the map's resolution (holoslam.maps.polyline)
        ("topology", lambda: write_graph_files(to_graphml_ready(compact_paths(result.topology)), out, "topology")),
        ("holographic", lambda: write_graph_files(compact_paths(result.holographic), out, "holographic")),
    ]  # fmt: skip
    if getattr(result, "rooms", None) is not None:
        steps.append(("rooms.png", lambda: write_label_png(result.rooms.labels, out / "rooms.png")))
    steps += [
        # planning.json and, beside it, planning_layer1.npz (layer 1's blocks)
        ("planning.json", lambda: write_planning(result.planning, out / "planning.json")),
        # strict JSON: NaN/inf -> null
        ("report.json", lambda: (out / "report.json").write_text(dumps(result.report.to_dict(), indent=2))),
        ("report.txt", lambda: (out / "report.txt").write_text(result.report.text() + "\n")),
    ]
    if results_mcap:
        steps.append(("results.mcap", lambda: write_results_mcap(_result_scene(result), out / "results.mcap")))
    if pictures:
        steps.append(("pictures", lambda: _pictures(
            out, result.wTb, result.dead_reckoning_wTb, result.wTa, result.cov_wTa, result.grid,
            result.topology, result.holographic, result.planning,
            rooms=None if getattr(result, "rooms", None) is None else result.rooms.labels,
        )))  # fmt: skip
    for name, step in steps:
        step()
        _checkpoint("file", name)


def _result_scene(result: Any) -> Any:
    return _scene(
        result.stamps_ns,
        result.wTb,
        result.dead_reckoning_wTb,
        result.wTa,
        result.grid,
        result.objects,
        result.topology,
        result.holographic,
    )


def write_run(
    result: Any,
    out_dir: str | Path,
    *,
    pictures: bool = True,
    results_mcap: bool = True,
    progress: Callable[..., None] | None = None,
    log_fingerprint: dict[str, Any] | None = None,
    config_hash: str | None = None,
) -> list[Path]:
    """Write every output file of a ``RunResult`` as the folder ``out_dir``, whole or not at all: the files go
    into a temporary sibling folder, are flushed, ``run.json`` (the manifest: ``log_fingerprint``,
    ``config_hash``, every file's size and sha256, the stage timings) is written last, and the folder is
    swapped into place (:mod:`holoslam.io.atomic_folder`). A previous folder of that name stays intact until
    the swap. Returns the paths of the files written. Raises ``OutputError`` when a file cannot be written
    (disk full, read-only), the previous folder unchanged."""
    from holoslam.io.atomic_folder import FolderWriter
    from holoslam.io.run_manifest import (
        build_manifest,
        complete,
        holoslam_version,
        input_fingerprint,
        write_manifest,
    )

    target = prepare_run_folder(out_dir)
    if progress:
        progress(f"writing {out_dir}")
    if log_fingerprint is None and getattr(result, "source", None) and Path(result.source).exists():
        log_fingerprint = input_fingerprint(result.source)
    writer = FolderWriter(target, valid=complete)
    with writer as tmp:
        _write_files(result, tmp, pictures, results_mcap)
        timings = getattr(getattr(result, "report", None), "timings_s", None)
        writer.commit(
            lambda folder: write_manifest(
                folder,
                build_manifest(
                    folder, version=holoslam_version(), log_fingerprint=log_fingerprint, config_hash=config_hash, timings_s=timings
                ),
            )
        )
    return sorted(p for p in target.iterdir() if p.is_file())


@dataclass(frozen=True, eq=False)
class SavedRun:
    """A run loaded back from its folder: numpy arrays, records and networkx graphs."""

    folder: Path
    stamps_ns: np.ndarray | None = None
    wTb: np.ndarray | None = None
    dead_reckoning_wTb: np.ndarray | None = None
    anchor_stamps_ns: np.ndarray | None = None
    wTa: np.ndarray | None = None
    cov_wTa: np.ndarray | None = None
    objects: tuple = ()
    grid: Any = None
    topology: Any = None
    holographic: Any = None
    planning: Any = None
    report: dict | None = None


def _need(folder: Path, name: str) -> Path:
    p = folder / name
    if not p.is_file():
        raise IngestError(
            f"{folder} has no {name}: is it a holoslam run folder? (make one with 'holoslam run LOG -o "
            f"{folder}')"
        )
    return p


def _read_anchors(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rows = list(csv.reader(path.read_text().splitlines()))
    if not rows or rows[0][:4] != ["stamp_ns", "x", "y", "theta"]:
        raise IngestError(f"{path}: not an anchors table (header stamp_ns,x,y,theta,cov_...)")
    try:
        stamps = np.array([int(r[0]) for r in rows[1:]], dtype=np.int64)
        vals = np.array([[float(v) for v in r[1:13]] for r in rows[1:]], dtype=np.float64).reshape(-1, 12)
    except (ValueError, IndexError) as e:
        raise IngestError(f"{path}: malformed row ({e})") from None
    return stamps, vals[:, :3], vals[:, 3:].reshape(-1, 3, 3)


def _read_objects(path: Path) -> tuple:
    from holoslam.maps.holographic import ObjectInfo
    from holoslam.vision.label import parse_label

    objs = []
    for k, r in enumerate(csv.DictReader(path.read_text().splitlines())):
        try:
            cov = np.full((3, 3), np.nan)
            cov[:2, :2] = [[float(r["cov_xx"]), float(r["cov_xy"])], [float(r["cov_xy"]), float(r["cov_yy"])]]
            try:
                attrs = parse_label(r["payload"]).attributes
            except Exception:
                attrs = ()
            objs.append(
                ObjectInfo(
                    r["id"],
                    r["type"],
                    np.array([float(r["x"]), float(r["y"]), float(r["z"])]),
                    cov,
                    attrs,
                    r["payload"],
                    sightings=int(r.get("sightings") or 0),  # absent in folders written before the column
                )
            )
        except (KeyError, ValueError, TypeError) as e:
            raise IngestError(f"{path}: malformed row {k + 2} ({e})") from None
    return tuple(objs)


_PARTS = ("trajectory", "anchors", "objects", "grid", "topology", "holographic", "planning", "report")


def load_run(folder: str | Path, parts: Sequence[str] = _PARTS) -> SavedRun:
    """Load a complete run folder back (only the ``parts`` asked for). Raises ``IngestError`` (one line) for a
    folder without a valid ``run.json`` (see :mod:`holoslam.io.run_manifest`) or naming a missing file."""
    from holoslam.io.graphs import read_graphml, read_node_link_json
    from holoslam.io.grid import read_grid
    from holoslam.io.planning import read_planning
    from holoslam.io.run_manifest import require_complete
    from holoslam.io.trajectory import read_tum

    f = Path(folder)
    require_complete(f)
    kw: dict[str, Any] = {"folder": f}
    if "trajectory" in parts:
        kw["stamps_ns"], kw["wTb"] = read_tum(_need(f, "trajectory.tum"))
        if (f / "dead_reckoning.tum").is_file():
            kw["dead_reckoning_wTb"] = read_tum(f / "dead_reckoning.tum")[1]
    if "anchors" in parts:
        kw["anchor_stamps_ns"], kw["wTa"], kw["cov_wTa"] = _read_anchors(_need(f, "anchors.csv"))
    if "objects" in parts:
        kw["objects"] = _read_objects(_need(f, "objects.csv"))
    if "grid" in parts:
        kw["grid"] = read_grid(_need(f, "map.yaml"))
    if "topology" in parts:
        kw["topology"] = read_graphml(_need(f, "topology.graphml"))
    if "holographic" in parts:
        kw["holographic"] = read_node_link_json(_need(f, "holographic.json"))
    if "planning" in parts:
        kw["planning"] = read_planning(_need(f, "planning.json"))
    if "report" in parts:
        try:
            kw["report"] = json.loads(_need(f, "report.json").read_text())
        except json.JSONDecodeError as e:
            raise IngestError(f"{f / 'report.json'} is not valid JSON ({e})") from None
    return SavedRun(**kw)


def export_saved(saved: SavedRun, to: Path, formats: set[str]) -> list[Path]:
    """Re-export a saved run into ``to``: ``pictures``, ``mcap`` (results MCAP), ``graphs`` (GraphML + JSON),
    ``tum``, or ``all``. Into the run folder itself, the folder is rewritten whole (a copy with the new files
    and a new manifest, swapped into place), so it stays complete; elsewhere the files are written as they are."""
    if saved.stamps_ns is None or saved.wTb is None:
        raise IngestError(
            f"{saved.folder}: the run was loaded without its trajectory; load it with the 'trajectory' part "
            "(load_run's default) to export it"
        )
    if Path(to).absolute() != Path(saved.folder).absolute():
        return _export_files(saved, prepare_output_folder(to), formats)
    from holoslam.io.atomic_folder import FolderWriter
    from holoslam.io.run_manifest import build_manifest, complete, require_complete, write_manifest

    old = require_complete(saved.folder)
    writer = FolderWriter(saved.folder, copy_from=saved.folder, valid=complete)
    with writer as tmp:
        names = [p.name for p in _export_files(saved, tmp, formats)]
        writer.commit(
            lambda folder: write_manifest(
                folder,
                build_manifest(
                    folder,
                    version=old["holoslam_version"],
                    log_fingerprint=old.get("input"),
                    config_hash=old.get("config_sha256"),
                    timings_s=old.get("timings_s"),
                ),
            )
        )
    return [Path(saved.folder) / n for n in names]


def _export_files(saved: SavedRun, out: Path, formats: set[str]) -> list[Path]:
    from holoslam.io.graphs import write_graph_files
    from holoslam.io.results_mcap import write_results_mcap
    from holoslam.io.trajectory import write_tum

    assert saved.stamps_ns is not None and saved.wTb is not None  # export_saved checked
    every = "all" in formats
    written: list[Path] = []
    dr = saved.dead_reckoning_wTb if saved.dead_reckoning_wTb is not None else saved.wTb
    if every or "tum" in formats:
        written.append(write_tum(out / "trajectory.tum", saved.stamps_ns, saved.wTb))
    if every or "graphs" in formats:
        written += list(write_graph_files(saved.holographic, out, "holographic"))
        written += list(write_graph_files(saved.topology, out, "topology"))
    if every or "mcap" in formats:
        scene = _scene(
            saved.stamps_ns,
            saved.wTb,
            dr,
            saved.wTa,
            saved.grid,
            saved.objects,
            saved.topology,
            saved.holographic,
        )
        written.append(write_results_mcap(scene, out / "results.mcap"))
    if every or "pictures" in formats:
        written += _pictures(
            out,
            saved.wTb,
            dr,
            saved.wTa,
            saved.cov_wTa,
            saved.grid,
            saved.topology,
            saved.holographic,
            saved.planning,
            rooms=_saved_rooms(saved.folder, saved.grid),
        )
    return written


def _saved_rooms(folder: Path, grid) -> np.ndarray | None:
    """The room label image of a saved run (``rooms.png``), None when it has none or it does not fit the map."""
    from holoslam.errors import MapError
    from holoslam.io.grid import read_label_png

    p = Path(folder) / "rooms.png"
    if not p.is_file():
        return None
    try:
        lab = read_label_png(p)
    except MapError:
        return None
    return lab if lab.shape == grid.shape else None
