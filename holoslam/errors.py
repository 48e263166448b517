"""holoslam's exceptions: one base class and one subclass per layer.

Every message says what went wrong, where (file, topic, line, record) and how to fix it, so the CLI can
print it as it is, without a traceback.
"""

from __future__ import annotations

__all__ = [
    "HoloslamError",
    "ConfigError",
    "IngestError",
    "ImageDecodeError",
    "PayloadError",
    "G2oFormatError",
    "GraphError",
    "SolverError",
    "MapError",
    "PlanningError",
    "VisionError",
    "OutputError",
    "StoreError",
]


class HoloslamError(Exception):
    """Base class of every error holoslam raises on purpose."""


class ConfigError(HoloslamError):
    """A configuration file or option is malformed or out of range."""


class IngestError(HoloslamError):
    """A log cannot be read or a required input is missing from it."""


class ImageDecodeError(IngestError):
    """An image's bytes do not decode to pixels."""


class PayloadError(HoloslamError):
    """A QR payload is not a holoslam label."""


class G2oFormatError(HoloslamError):
    """A g2o (or TORO/iSAM text) graph file has a malformed line."""


class GraphError(HoloslamError):
    """The factor graph cannot be built (missing keys, degenerate noise, nothing to optimise)."""


class SolverError(HoloslamError):
    """An optimiser failed (indeterminate system, diverged)."""


class MapError(HoloslamError):
    """An occupancy grid or a map file is malformed."""


class PlanningError(HoloslamError):
    """A planning query has no answer (unknown object, unreachable goal)."""


class VisionError(HoloslamError):
    """Camera geometry or an image measurement is invalid (a non-orthonormal rotation, a point behind the
    camera, a degenerate view pair, a missing camera calibration)."""


class OutputError(HoloslamError):
    """An output cannot be written (disk full, read-only file system, no permission); nothing was replaced."""


class StoreError(HoloslamError):
    """A map store (``holoslam.store``) cannot be opened, read or updated."""
