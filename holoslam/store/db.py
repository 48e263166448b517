"""``MapStore``: the one place that opens a map store's SQLite database (standard library ``sqlite3``).

Every update is one transaction (``BEGIN IMMEDIATE`` ... ``COMMIT``, rollback journal with ``synchronous=FULL``):
a process killed anywhere inside ``add_session`` leaves the store as the last commit left it (SQLite rolls the
hot journal back on the next open). Reads see one committed state."""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from holoslam.errors import StoreError
from holoslam.store.codec import pack, pack_prob, unpack, unpack_prob
from holoslam.store.records import (
    ObjectState,
    SessionUpdate,
    StoredFactors,
    StoredSession,
    StoredSightings,
    StoredSubmap,
    StoredTrajectory,
)
from holoslam.store.schema import MIGRATIONS, SCHEMA_VERSION, create_schema

__all__ = ["MapStore", "STORE_FORMAT"]

STORE_FORMAT = "holoslam-map-store"
StoreProgress = Callable[[str], None]


def _now() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def _version() -> str:
    """The installed holoslam's version (read from its metadata: importing the package here would close an import
    cycle through its lazy names)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("holoslam")
    except PackageNotFoundError:
        return "unknown"


def _state(r: Any) -> ObjectState:
    """An ``ObjectState`` of an ``object_history`` row (the columns ``object_history`` selects)."""
    xy = None if r[5] is None else np.array([r[5], r[6]])
    d = None if r[9] is None else np.array([r[9], r[10]])
    view = None if r[13] is None else np.array([r[13], r[14]])
    normal = None if r[16] is None else np.array([r[16], r[17]])
    return ObjectState(r[1], r[2], r[3], r[4], xy, np.nan if r[7] is None else r[7], _opt(r[8], "object cov"),
                       r[12], r[15] or "", d, _opt(r[11], "object cov_d"), view, r[0], normal,
                       np.nan if r[18] is None else float(r[18]))


def _opt(blob: bytes | None, where: str) -> np.ndarray | None:
    return None if blob is None else unpack(blob, where)


class MapStore:
    """An open map store. ``MapStore.open(path)`` creates it when absent (``create=True``), migrates an older
    schema, refuses a newer one; use it as a context manager or ``close()`` it."""

    def __init__(self, path: Path, con: sqlite3.Connection) -> None:
        self.path = path
        self._con = con

    # ------------------------------------------------------------------------------------------- opening

    @classmethod
    def open(cls, path: str | Path, create: bool = True) -> MapStore:
        p = Path(path)
        if not p.exists() and not create:
            raise StoreError(f"map store {p} does not exist; make one with 'holoslam run LOG --map {p} -o OUT'")
        if p.exists() and not p.is_file():
            raise StoreError(f"map store {p} is not a file; name a store file (e.g. home.holomap)")
        if not p.parent.exists():
            raise StoreError(f"folder {p.parent} of the map store does not exist; create it first")
        try:
            con = sqlite3.connect(str(p), isolation_level=None, timeout=30.0)
            con.execute("PRAGMA journal_mode=DELETE")
            con.execute("PRAGMA synchronous=FULL")
            con.execute("PRAGMA foreign_keys=ON")
            store = cls(p, con)
            store._prepare()
        except sqlite3.DatabaseError as e:
            raise StoreError(f"{p} is not a holoslam map store ({e}); give a store 'holoslam run --map' wrote") from None
        return store

    def _prepare(self) -> None:
        names = {r[0] for r in self._con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if not names:
            with self.transaction():
                create_schema(self._con)
                self._con.executemany("INSERT INTO meta VALUES (?, ?)", [
                    ("format", STORE_FORMAT), ("schema_version", str(SCHEMA_VERSION)),
                    ("created_by", f"holoslam {_version()}"), ("created_utc", _now())])
            return
        if "meta" not in names:
            raise StoreError(f"{self.path} is an SQLite database but not a holoslam map store (no meta table)")
        meta = dict(self._con.execute("SELECT key, value FROM meta").fetchall())
        if meta.get("format") != STORE_FORMAT:
            raise StoreError(f"{self.path} is not a holoslam map store (format {meta.get('format')!r})")
        version = int(meta.get("schema_version", "0"))
        if version > SCHEMA_VERSION:
            raise StoreError(f"{self.path} has map store schema {version}, newer than this holoslam's "
                             f"{SCHEMA_VERSION}; update holoslam to open it")
        if version < SCHEMA_VERSION:
            self.migrate(version)

    def migrate(self, version: int) -> None:
        """Bring a version-``version`` store to ``SCHEMA_VERSION`` in one transaction (``schema.MIGRATIONS``)."""
        with self.transaction():
            for v in range(version, SCHEMA_VERSION):
                if v not in MIGRATIONS:
                    raise StoreError(f"{self.path}: no migration from map store schema {v}; this store cannot "
                                     "be opened by this holoslam")
                MIGRATIONS[v](self._con)
            self._con.execute("UPDATE meta SET value=? WHERE key='schema_version'", (str(SCHEMA_VERSION),))

    @contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        """One write transaction: committed when the block ends, rolled back on any exception."""
        self._con.execute("BEGIN IMMEDIATE")
        try:
            yield self._con
        except BaseException:
            self._con.execute("ROLLBACK")
            raise
        self._con.execute("COMMIT")

    def close(self) -> None:
        self._con.close()

    def __enter__(self) -> MapStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def meta(self) -> dict[str, str]:
        return dict(self._con.execute("SELECT key, value FROM meta").fetchall())

    @property
    def schema_version(self) -> int:
        return int(self.meta["schema_version"])

    # ------------------------------------------------------------------------------------------- reading

    def sessions(self) -> tuple[StoredSession, ...]:
        rows = self._con.execute(
            "SELECT id, log_name, log_sha256, start_ns, end_ns, added_utc, joined, joined_by, wTs, cov_wTs, "
            "relocalisation_s, summary FROM sessions ORDER BY id").fetchall()
        return tuple(StoredSession(r[0], r[1], r[2], r[3], r[4], r[5], bool(r[6]), r[7],
                                   unpack(r[8], f"session {r[0]} wTs"), _opt(r[9], f"session {r[0]} cov_wTs"),
                                   float(r[10]), json.loads(r[11])) for r in rows)

    def submaps(self, *, working: bool = True, grids: bool = False, session_id: int | None = None
                ) -> tuple[StoredSubmap, ...]:
        """Stored submaps (by row id). ``working``: only those of joined sessions not retired; ``grids``: with
        their probability grids and points; ``session_id``: one session's (every one of them)."""
        cols = "s.id, s.session_id, s.idx, s.anchor_stamp_ns, s.wTa, s.cov_wTa, s.sTa, s.origin_x, s.origin_y, " \
               "s.resolution, s.retired_by" + (", s.grid, s.points" if grids else "")
        sql = f"SELECT {cols} FROM submaps s JOIN sessions e ON e.id = s.session_id"
        args: tuple = ()
        if session_id is not None:
            sql += " WHERE s.session_id = ?"
            args = (int(session_id),)
        elif working:
            sql += " WHERE e.joined = 1 AND s.retired_by IS NULL"
        out = []
        for r in self._con.execute(sql + " ORDER BY s.id", args):
            w = f"submap {r[0]}"
            prob, known = unpack_prob(r[11], w) if grids else (None, None)
            out.append(StoredSubmap(
                r[0], r[1], r[2], r[3], unpack(r[4], w), _opt(r[5], w), unpack(r[6], w), (r[7], r[8]), r[9], r[10],
                prob, unpack(r[12], w) if grids else None, known))
        return tuple(out)

    def factors(self, submap_ids: np.ndarray | None = None) -> StoredFactors:
        """The relative poses; with ``submap_ids``, those whose both ends are among them."""
        rows = self._con.execute("SELECT id, session_id, i, j, iTj, cov_iTj, kind FROM factors ORDER BY id").fetchall()
        if submap_ids is not None:
            keep = set(np.asarray(submap_ids).tolist())
            rows = [r for r in rows if r[2] in keep and r[3] in keep]
        return StoredFactors(
            np.array([r[0] for r in rows], np.int64), np.array([r[1] for r in rows], np.int64),
            np.array([r[2] for r in rows], np.int64), np.array([r[3] for r in rows], np.int64),
            np.array([unpack(r[4], f"factor {r[0]}") for r in rows]).reshape(-1, 3),
            np.array([unpack(r[5], f"factor {r[0]}") for r in rows]).reshape(-1, 3, 3),
            np.array([r[6] for r in rows], dtype=object))

    def sightings(self, submap_ids: np.ndarray | None = None) -> StoredSightings:
        """Object sightings; with ``submap_ids``, those from these submaps (selected by the database's index on
        the submap, so a session reads its working submaps' rows, not the whole history)."""
        sql = "SELECT submap_id, object_id, placement, a_x, a_y, cov, z, id FROM sightings"
        if submap_ids is None:
            rows = self._con.execute(sql + " ORDER BY id").fetchall()
        else:
            ids = sorted({int(k) for k in np.asarray(submap_ids).tolist()})
            rows = []
            for k in range(0, len(ids), 900):  # SQLite's bound parameters: at most 999 in older builds
                chunk = ids[k:k + 900]
                rows += self._con.execute(sql + f" WHERE submap_id IN ({','.join('?' * len(chunk))})",  # noqa: S608
                                          chunk).fetchall()
            rows.sort(key=lambda r: r[7])
        return StoredSightings(
            np.array([r[0] for r in rows], np.int64), tuple(r[1] for r in rows), tuple(r[2] for r in rows),
            np.array([[r[3], r[4]] for r in rows], np.float64).reshape(-1, 2),
            np.array([unpack(r[5], "sighting") for r in rows]).reshape(-1, 2, 2),
            np.array([np.nan if r[6] is None else r[6] for r in rows], np.float64))

    def placements(self) -> set[str]:
        """Every placement the store ever gave (object history and sightings, retired submaps' included)."""
        rows = self._con.execute("SELECT placement FROM object_history WHERE placement IS NOT NULL AND placement != '' "
                                 "UNION SELECT placement FROM sightings").fetchall()
        return {r[0] for r in rows if r[0]}

    def object_history(self, object_id: str | None = None, session_id: int | None = None
                       ) -> tuple[ObjectState, ...]:
        """Object states by session, then object id; filtered by object and/or session."""
        sql = ("SELECT session_id, object_id, kind, payload, status, x, y, z, cov, dx, dy, cov_d, sightings, "
               "view_x, view_y, placement, normal_x, normal_y, normal_sigma FROM object_history")
        cond: list[str] = []
        args: list[Any] = []
        if object_id is not None:
            cond.append("object_id = ?")
            args.append(object_id)
        if session_id is not None:
            cond.append("session_id = ?")
            args.append(int(session_id))
        if cond:
            sql += " WHERE " + " AND ".join(cond)
        return tuple(_state(r) for r in self._con.execute(sql + " ORDER BY session_id, object_id", args))

    def latest_objects(self) -> dict[str, ObjectState]:
        """Each object's state in the latest joined session that has a row for it (gone ones included): one row
        per object, chosen by the database (the history's index on object and session)."""
        sql = ("SELECT h.session_id, h.object_id, h.kind, h.payload, h.status, h.x, h.y, h.z, h.cov, h.dx, h.dy, "
               "h.cov_d, h.sightings, h.view_x, h.view_y, h.placement, h.normal_x, h.normal_y, h.normal_sigma "
               "FROM object_history h "
               "WHERE h.session_id = (SELECT MAX(h2.session_id) FROM object_history h2 JOIN sessions e "
               "ON e.id = h2.session_id WHERE e.joined = 1 AND h2.object_id = h.object_id) ORDER BY h.object_id")
        return {st.object_id: st for st in (_state(r) for r in self._con.execute(sql))}

    def trajectory(self, session_id: int) -> StoredTrajectory:
        r = self._con.execute("SELECT stamps_ns, anchor_idx, aTb, sTb FROM trajectories WHERE session_id = ?",
                              (int(session_id),)).fetchone()
        if r is None:
            raise StoreError(f"{self.path}: session {session_id} has no trajectory")
        w = f"session {session_id} trajectory"
        return StoredTrajectory(np.cumsum(unpack(r[0], w)), unpack(r[1], w), unpack(r[2], w), unpack(r[3], w))

    def counts(self) -> dict[str, int]:
        """Rows per table, and the working graph's submaps."""
        out = {t: int(self._con.execute(f"SELECT COUNT(*) FROM {t}").fetchone()[0])  # noqa: S608 (fixed names)
               for t in ("sessions", "submaps", "factors", "sightings", "object_history", "trajectories")}
        out["working_submaps"] = int(self._con.execute(
            "SELECT COUNT(*) FROM submaps s JOIN sessions e ON e.id = s.session_id "
            "WHERE e.joined = 1 AND s.retired_by IS NULL").fetchone()[0])
        return out

    # ------------------------------------------------------------------------------------------- writing

    def add_session(self, u: SessionUpdate, progress: StoreProgress | None = None) -> int:
        """Write one session (``SessionUpdate``) in one transaction; returns its id. ``progress(step)`` is called
        after each step inside the transaction (the kill tests stop a process there)."""
        step = progress or (lambda _s: None)
        with self.transaction() as con:
            sid = self._insert_session(con, u)
            if u.expected_id and sid != u.expected_id:
                raise StoreError(f"{self.path} changed while this session ran (another session was added); run "
                                 "the log into the store again")
            step("session")
            ref = self._insert_submaps(con, sid, u)
            step("submaps")
            con.executemany("INSERT INTO factors (session_id, i, j, iTj, cov_iTj, kind) VALUES (?, ?, ?, ?, ?, ?)", [
                (sid, ref(i), ref(j), pack(np.asarray(T, np.float64)), pack(np.asarray(C, np.float64)), str(k))
                for i, j, T, C, k in zip(u.factors_i.tolist(), u.factors_j.tolist(), u.factors_iTj, u.factors_cov,
                                         u.factors_kind, strict=True)])
            step("factors")
            con.executemany("INSERT INTO sightings (submap_id, object_id, placement, a_x, a_y, cov, z) "
                            "VALUES (?, ?, ?, ?, ?, ?, ?)", [
                (ref(r), o, p, float(a[0]), float(a[1]), pack(np.asarray(c, np.float64)),
                 None if not np.isfinite(z) else float(z))
                for r, o, p, a, c, z in zip(u.sightings_ref.tolist(), u.sightings_object, u.sightings_placement,
                                            u.sightings_a_position, u.sightings_cov, u.sightings_z, strict=True)])
            step("sightings")
            self._insert_objects(con, sid, u.objects)
            step("objects")
            t = u.trajectory
            con.execute("INSERT INTO trajectories VALUES (?, ?, ?, ?, ?)", (
                sid, pack(np.diff(np.asarray(t.stamps_ns, np.int64), prepend=np.int64(0))),
                pack(np.asarray(t.anchor_idx, np.int32)), pack(np.asarray(t.aTb, np.float32)),
                pack(np.asarray(t.sTb, np.float32))))
            step("trajectory")
            con.executemany("UPDATE submaps SET wTa = ?, cov_wTa = ? WHERE id = ?", [
                (pack(np.asarray(T, np.float64)), None if C is None else pack(np.asarray(C, np.float64)), int(k))
                for k, (T, C) in u.wTa_updates.items()])
            con.executemany("UPDATE submaps SET retired_by = ? WHERE id = ?", [(sid, int(k)) for k in u.retire])
            step("graph")
            con.execute("INSERT OR REPLACE INTO meta VALUES ('last_written_utc', ?)", (_now(),))
        step("committed")
        return sid

    @staticmethod
    def _insert_session(con: sqlite3.Connection, u: SessionUpdate) -> int:
        from holoslam.io.jsonsafe import dumps

        cur = con.execute(
            "INSERT INTO sessions (log_name, log_sha256, start_ns, end_ns, added_utc, joined, joined_by, wTs, cov_wTs, "
            "relocalisation_s, summary) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (u.log_name, u.log_sha256, int(u.start_ns), int(u.end_ns), _now(), int(bool(u.joined)), u.joined_by,
             pack(np.asarray(u.wTs, np.float64)), None if u.cov_wTs is None else pack(np.asarray(u.cov_wTs)),
             float(u.relocalisation_s), dumps(u.summary)))
        return int(cur.lastrowid or 0)

    @staticmethod
    def _insert_submaps(con: sqlite3.Connection, sid: int, u: SessionUpdate) -> Callable[[int], int]:
        ids: dict[int, int] = {}
        for sm in u.submaps:
            cur = con.execute(
                "INSERT INTO submaps (session_id, idx, anchor_stamp_ns, wTa, cov_wTa, sTa, grid, origin_x, origin_y, "
                "resolution, points) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (sid, int(sm.idx), int(sm.anchor_stamp_ns), pack(np.asarray(sm.wTa, np.float64)),
                 None if sm.cov_wTa is None else pack(np.asarray(sm.cov_wTa, np.float64)),
                 pack(np.asarray(sm.sTa, np.float64)), pack_prob(sm.prob, sm.known), float(sm.origin[0]), float(sm.origin[1]),
                 float(sm.resolution), pack(np.asarray(sm.points, np.float32))))
            ids[-(int(sm.idx) + 1)] = int(cur.lastrowid or 0)

        def ref(r: int) -> int:
            if r >= 1:
                return int(r)
            if r not in ids:
                raise StoreError(f"session update refers to new submap {-r - 1}, which it does not add")
            return ids[r]

        return ref

    @staticmethod
    def _insert_objects(con: sqlite3.Connection, sid: int, objects: tuple[ObjectState, ...]) -> None:
        def opt(a: Any, k: int) -> float | None:
            return None if a is None else float(a[k])

        con.executemany(
            "INSERT INTO object_history (session_id, object_id, kind, payload, status, x, y, z, cov, dx, dy, cov_d, "
            "sightings, view_x, view_y, placement, normal_x, normal_y, normal_sigma) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            [(sid, o.object_id, o.kind, o.payload, o.status, opt(o.w_xy, 0), opt(o.w_xy, 1),
              None if not np.isfinite(o.z) else float(o.z),
              None if o.cov_w_xy is None else pack(np.asarray(o.cov_w_xy, np.float64)),
              opt(o.displacement, 0), opt(o.displacement, 1),
              None if o.cov_displacement is None else pack(np.asarray(o.cov_displacement, np.float64)),
              int(o.sightings), opt(o.view, 0), opt(o.view, 1), o.placement, opt(o.normal, 0), opt(o.normal, 1),
              None if o.normal is None or not np.isfinite(o.normal_sigma_rad) else float(o.normal_sigma_rad))
             for o in objects])
