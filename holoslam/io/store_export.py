"""Writing a map store's export (``holoslam export STORE --to DIR``): the merged map (map_server PGM + YAML and a
PNG), its topology (GraphML + JSON), one TUM file per session (``session_<id>.tum`` in the world,
``session_<id>_unjoined.tum`` in its own frame), the objects now (``objects.csv``) and their history
(``objects_history.csv``), the holographic graph of the merged map with the objects where they are now
(``holographic.graphml``/``.json``: ``holoslam.maps.holographic.where_is`` answers "where is X now") and its
planning graph (``planning.json``), and a picture of it all (``store.png``)."""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

__all__ = ["write_store_export"]


def _states_csv(states: Any, with_session: bool) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow((["session"] if with_session else []) + ["id", "type", "status", "x", "y", "z", "cov_xx", "cov_xy",
                                                        "cov_yy", "dx", "dy", "sightings", "placement", "payload"])
    for o in states:
        xy = ["", ""] if o.w_xy is None else [repr(float(v)) for v in o.w_xy]
        c = ["", "", ""] if o.cov_w_xy is None else [repr(float(o.cov_w_xy[0, 0])), repr(float(o.cov_w_xy[0, 1])),
                                                      repr(float(o.cov_w_xy[1, 1]))]
        d = ["", ""] if o.displacement is None else [repr(float(v)) for v in o.displacement]
        w.writerow(([o.session_id] if with_session else []) + [o.object_id, o.kind, o.status] + xy +
                   [repr(float(o.z))] + c + d + [o.sightings, o.placement, o.payload])
    return buf.getvalue()


def write_store_export(ex: Any, to: str | Path, pictures: bool = True, follow: tuple[str, ...] = ()) -> list[Path]:
    """Write a ``holoslam.lifelong.export.StoreExport`` into the folder ``to`` (created); returns the paths. With
    ``pictures``, ``store.png``: the merged map, the sessions' trajectories, the objects and the history of the
    objects in ``follow`` (default: the one that moved most often)."""
    from holoslam.io.graphs import write_graph_files
    from holoslam.io.grid import write_grid, write_grid_png
    from holoslam.io.run_folder import prepare_output_folder
    from holoslam.io.trajectory import write_tum
    from holoslam.maps.topology import to_graphml_ready

    out = prepare_output_folder(to)
    written = [write_grid(ex.grid, out / "map.yaml"), out / "map.yaml", write_grid_png(ex.grid, out / "map.png")]
    written += list(write_graph_files(to_graphml_ready(ex.topology), out, "topology"))
    if ex.holographic is not None:
        from holoslam.io.planning import write_planning
        from holoslam.maps.polyline import compact_paths

        written += list(write_graph_files(compact_paths(ex.holographic), out, "holographic"))
        written.append(write_planning(ex.planning, out / "planning.json"))
    for sid, (stamps, wTb, joined) in sorted(ex.trajectories.items()):
        written.append(write_tum(out / (f"session_{sid}.tum" if joined else f"session_{sid}_unjoined.tum"), stamps,
                                 wTb))
    (out / "objects.csv").write_text(_states_csv(ex.objects_now, True))
    (out / "objects_history.csv").write_text(_states_csv(ex.history, True))
    written += [out / "objects.csv", out / "objects_history.csv"]
    if pictures:
        from collections import Counter

        from holoslam import viz

        moves = Counter(o.object_id for o in ex.history if o.status == "moved")
        ids = follow or tuple(k for k, _n in moves.most_common(1))
        viz.store_figure(ex, ids, title=f"{Path(ex.store).name}: {len(ex.trajectories)} sessions").savefig(
            out / "store.png", dpi=130)
        written.append(out / "store.png")
    return written
