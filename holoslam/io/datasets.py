"""Find holoslam's bundled household log and the public datasets listed in ``datasets/manifest.yaml``.

Where a dataset is looked for, by its manifest entry's ``where``:

- ``bundled``: the package's own ``holoslam/_datasets/`` folder (an installed wheel: ``setup.py`` copies the
  repository's ``datasets/`` there at build time), else the ``datasets/`` folder next to the ``holoslam``
  package (a source checkout or an editable install), or a ``datasets/`` folder in the folders of
  ``$HOLOSLAM_DATA``; the sha256 is verified.
- ``gtsam``: inside the installed gtsam wheel (``gtsam.findExampleDataFile``).
- ``external``: the folders listed in ``$HOLOSLAM_DATA`` (separated by ``os.pathsep``), e.g.
  ``HOLOSLAM_DATA=/work/shared/posegraph``.

A name not in the manifest is still looked up as a file name in those places.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field
from pathlib import Path

from holoslam.errors import IngestError

__all__ = [
    "DatasetEntry",
    "datasets_dir",
    "load_manifest",
    "find_dataset",
    "bundled_household_log",
    "sha256_of",
    "BUNDLED_HOUSEHOLD",
    "DATA_ENV",
]

BUNDLED_HOUSEHOLD = "household_small"
DATA_ENV = "HOLOSLAM_DATA"


@dataclass(frozen=True)
class DatasetEntry:
    """One manifest entry; ``extra`` keeps the entry's other fields (description, licence, source, ...)."""

    name: str
    where: str  # "bundled" | "gtsam" | "external"
    file: str
    sha256: str | None = None
    licence: str = ""
    extra: dict = field(default_factory=dict, compare=False)


def datasets_dir() -> Path:
    """The folder of the manifest and the bundled log: ``holoslam/_datasets`` inside an installed wheel, else
    the repository's ``datasets/`` beside the package (a source checkout or an editable install)."""
    package = Path(__file__).resolve().parent.parent
    shipped = package / "_datasets"
    if (shipped / "manifest.yaml").is_file():
        return shipped
    return package.parent / "datasets"


def _env_dirs() -> list[Path]:
    raw = os.environ.get(DATA_ENV, "")
    return [Path(p).expanduser() for p in raw.split(os.pathsep) if p.strip()]


def load_manifest(path: str | Path | None = None) -> dict[str, DatasetEntry]:
    """The manifest's entries by name. Raises ``IngestError`` if the file is missing or malformed."""
    import yaml

    p = Path(path) if path is not None else datasets_dir() / "manifest.yaml"
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except OSError as e:
        raise IngestError(
            f"dataset manifest {p} cannot be read ({e.strerror}); reinstall holoslam from its wheel "
            f"(it ships the manifest) or pass the manifest's path"
        ) from e
    except yaml.YAMLError as e:
        raise IngestError(f"dataset manifest {p} is not valid YAML: {e}") from e
    if not isinstance(data, dict) or not isinstance(data.get("datasets"), list):
        raise IngestError(f"dataset manifest {p}: expected a mapping with a 'datasets' list")
    out: dict[str, DatasetEntry] = {}
    for i, d in enumerate(data["datasets"]):
        if not isinstance(d, dict) or not {"name", "where", "file"} <= d.keys():
            raise IngestError(f"dataset manifest {p}: entry {i} needs 'name', 'where' and 'file'")
        if d["where"] not in ("bundled", "gtsam", "external"):
            raise IngestError(
                f"dataset manifest {p}: entry {d['name']!r} has where={d['where']!r}; "
                "expected bundled, gtsam or external"
            )
        rest = {k: v for k, v in d.items() if k not in ("name", "where", "file", "sha256", "licence")}
        out[str(d["name"])] = DatasetEntry(
            str(d["name"]), d["where"], str(d["file"]), d.get("sha256"), str(d.get("licence", "")), rest
        )
    return out


def sha256_of(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _in_gtsam(file: str) -> Path | None:
    try:
        import gtsam

        return Path(gtsam.findExampleDataFile(file))
    except Exception:  # gtsam missing, or the file is not in the wheel: "not found" either way
        return None


def find_dataset(name: str) -> Path | None:
    """The path of dataset ``name`` (a manifest name or a file name), or None if it is nowhere here."""
    try:
        entry = load_manifest().get(name)
    except IngestError:
        entry = None
    file = entry.file if entry else name
    where = entry.where if entry else None
    candidates: list[Path] = []
    if where in (None, "bundled"):
        candidates.append(datasets_dir() / file)
        candidates += [d / "datasets" / file for d in _env_dirs()]
    if where in (None, "external", "bundled"):
        candidates += [d / file for d in _env_dirs()]
    for c in candidates:
        if c.is_file():
            return c
    if where in (None, "gtsam"):
        return _in_gtsam(file)
    return None


_verified: dict[tuple[str, int, int], bool] = {}


def bundled_household_log(verify: bool = True) -> Path:
    """The committed household MCAP log; its sha256 is checked against the manifest (once per file version).

    Raises ``IngestError`` when the file is missing (e.g. a clone without the data) or was modified."""
    entry = load_manifest().get(BUNDLED_HOUSEHOLD)
    if entry is None:
        raise IngestError(f"the dataset manifest has no {BUNDLED_HOUSEHOLD!r} entry")
    path = find_dataset(BUNDLED_HOUSEHOLD)
    if path is None:
        raise IngestError(
            f"bundled log {entry.file} not found in {datasets_dir()} or ${DATA_ENV}; regenerate it with: "
            f"{entry.extra.get('cli_equivalent', 'holoslam simulate')}"
        )
    if verify and entry.sha256:
        st = path.stat()
        key = (str(path), st.st_size, st.st_mtime_ns)
        if key not in _verified:
            digest = sha256_of(path)
            if digest != entry.sha256:
                raise IngestError(
                    f"bundled log {path} has sha256 {digest[:12]}..., "
                    f"the manifest says {entry.sha256[:12]}...: "
                    f"the file was modified or truncated; restore it from git "
                    f"(git checkout -- datasets/{entry.file}): a log regenerated with "
                    f"'{entry.extra.get('cli_equivalent', 'holoslam simulate')}' has the same content "
                    f"but, on another machine, not the same bytes"
                )
            _verified[key] = True
    return path
