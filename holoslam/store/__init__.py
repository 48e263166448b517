"""The map store of one home (lifelong maps): sessions, their submaps and anchors, the graph's relative poses
within and across sessions, objects with their history, and every session's trajectory, in one SQLite file with
a versioned schema (``holoslam.store.schema``). ``holoslam.store.db.MapStore`` is the only code that opens it;
each session is added in one transaction. The records it reads and writes are in ``holoslam.store.records``."""

from __future__ import annotations

__all__ = ["MapStore", "SCHEMA_VERSION"]


def __getattr__(name: str):  # lazy: importing holoslam.store opens nothing and imports no sqlite3
    if name == "MapStore":
        from holoslam.store.db import MapStore

        return MapStore
    if name == "SCHEMA_VERSION":
        from holoslam.store.schema import SCHEMA_VERSION

        return SCHEMA_VERSION
    raise AttributeError(name)
