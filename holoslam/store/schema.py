"""The map store's SQLite schema, its version and the migrations from every older version.

One SQLite file holds one home. ``meta`` carries ``schema_version`` (an integer as text), the holoslam version
that created the store and the one that last wrote it. Version 1 tables:

- ``sessions``: one row per log run into the store: the log's name and SHA-256, its first and last stamp, when
  it was added, whether it was joined to the world (and by what: laser / objects / both / none), the session
  frame's pose in the world ``wTs`` with its covariance, the relocalisation time, and the session object of its
  report (JSON).
- ``submaps``: the sessions' submaps: index in the session, anchor stamp, the anchor's pose in the world ``wTa``
  (re-estimated by every later joint solve) and in its session's own frame ``sTa``, its probability grid
  (uint8, origin, resolution, anchor frame), its decimated scan points (anchor frame), and ``retired_by``: the
  session whose fresher submaps cover its area (kept for history, left out of the working graph).
- ``factors``: relative poses ``iTj`` between submap anchors (submap row ids), with covariance and kind
  (``dead_reckoning``, ``scan_match``, ``loop`` within a session; ``cross`` between sessions), and the session
  that added them.
- ``sightings``: an object seen from a submap's anchor: position in the anchor frame, 2x2 covariance, label
  height, and the ``placement``: the landmark variable it belongs to (``<id>#<session>``: the object at the place
  it had from that session on).
- ``object_history``: per session and object: world position and covariance, status (seen / moved / gone /
  new / unplaced), displacement and its covariance when moved, number of sightings, the direction it was seen
  from, and the placement.
- ``trajectories``: per session, the base poses at every odometry and scan stamp, as the pose in the anchor
  frame of the submap they hang from (so a later re-solve of the anchors moves them along).

Version 2 adds to ``object_history`` the label's normal as far as the sessions' readings tell (``normal_x``,
``normal_y``: its horizontal direction in the world, a unit vector; ``normal_sigma``: the standard deviation of
that direction in rad), NULL where it is not known (every row of a version-1 store).

Arrays are BLOBs (``holoslam.store.codec``). A migration ``MIGRATIONS[v]`` turns a version-v store into a
version v+1 store inside the transaction that opens it; a store newer than this holoslam is refused.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Callable

__all__ = ["SCHEMA_VERSION", "SCHEMA_V1", "MIGRATIONS", "create_schema"]

SCHEMA_VERSION = 2

SCHEMA_V1 = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE sessions (
    id INTEGER PRIMARY KEY,
    log_name TEXT NOT NULL,
    log_sha256 TEXT NOT NULL,
    start_ns INTEGER NOT NULL,
    end_ns INTEGER NOT NULL,
    added_utc TEXT NOT NULL,
    joined INTEGER NOT NULL,
    joined_by TEXT NOT NULL,
    wTs BLOB NOT NULL,
    cov_wTs BLOB,
    relocalisation_s REAL NOT NULL,
    summary TEXT NOT NULL
);
CREATE TABLE submaps (
    id INTEGER PRIMARY KEY,
    session_id INTEGER NOT NULL REFERENCES sessions(id),
    idx INTEGER NOT NULL,
    anchor_stamp_ns INTEGER NOT NULL,
    wTa BLOB NOT NULL,
    cov_wTa BLOB,
    sTa BLOB NOT NULL,
    grid BLOB NOT NULL,
    origin_x REAL NOT NULL,
    origin_y REAL NOT NULL,
    resolution REAL NOT NULL,
    points BLOB NOT NULL,
    retired_by INTEGER REFERENCES sessions(id),
    UNIQUE (session_id, idx)
);
CREATE TABLE factors (
    id INTEGER PRIMARY KEY,
    session_id INTEGER NOT NULL REFERENCES sessions(id),
    i INTEGER NOT NULL REFERENCES submaps(id),
    j INTEGER NOT NULL REFERENCES submaps(id),
    iTj BLOB NOT NULL,
    cov_iTj BLOB NOT NULL,
    kind TEXT NOT NULL
);
CREATE TABLE sightings (
    id INTEGER PRIMARY KEY,
    submap_id INTEGER NOT NULL REFERENCES submaps(id),
    object_id TEXT NOT NULL,
    placement TEXT NOT NULL,
    a_x REAL NOT NULL,
    a_y REAL NOT NULL,
    cov BLOB NOT NULL,
    z REAL
);
CREATE TABLE object_history (
    session_id INTEGER NOT NULL REFERENCES sessions(id),
    object_id TEXT NOT NULL,
    kind TEXT NOT NULL,
    payload TEXT NOT NULL,
    status TEXT NOT NULL,
    x REAL, y REAL, z REAL,
    cov BLOB,
    dx REAL, dy REAL,
    cov_d BLOB,
    sightings INTEGER NOT NULL,
    view_x REAL, view_y REAL,
    placement TEXT,
    PRIMARY KEY (session_id, object_id)
);
CREATE TABLE trajectories (
    session_id INTEGER PRIMARY KEY REFERENCES sessions(id),
    stamps_ns BLOB NOT NULL,
    anchor_idx BLOB NOT NULL,
    aTb BLOB NOT NULL,
    sTb BLOB NOT NULL
);
CREATE INDEX submaps_session ON submaps (session_id);
CREATE INDEX factors_session ON factors (session_id);
CREATE INDEX sightings_submap ON sightings (submap_id);
CREATE INDEX history_object ON object_history (object_id, session_id);
"""


def _v1_to_v2(con: sqlite3.Connection) -> None:
    """Version 2: the label's normal in ``object_history`` (unknown for the rows already there)."""
    for column in ("normal_x REAL", "normal_y REAL", "normal_sigma REAL"):
        con.execute(f"ALTER TABLE object_history ADD COLUMN {column}")


# MIGRATIONS[v](connection) turns a version-v store into version v + 1 (run inside the opening transaction). A
# change of the tables adds SCHEMA_VERSION + 1, its migration here, and a fixture store of the old version under
# tests/store/ that the tests open and extend. A new store is made as version 1 and migrated in the same
# transaction, so a new store and an upgraded one have the same tables.
MIGRATIONS: dict[int, Callable[[sqlite3.Connection], None]] = {1: _v1_to_v2}


def create_schema(con: sqlite3.Connection) -> None:
    """The tables of a new store at ``SCHEMA_VERSION`` (the caller holds the transaction)."""
    for statement in SCHEMA_V1.split(";"):
        if statement.strip():
            con.execute(statement)
    for v in range(1, SCHEMA_VERSION):
        MIGRATIONS[v](con)
