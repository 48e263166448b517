"""Strict JSON text of reports and summaries: non-finite numbers become ``null``.

Python's ``json.dumps`` writes ``NaN`` / ``Infinity`` by default, which is not JSON (RFC 8259): ``jq``,
JavaScript's ``JSON.parse`` and most other readers refuse the whole file. A report has such values where a
statistic is undefined (the RMSE of zero matched objects, a coverage without covariances): they are written
as ``null``, "no value". numpy scalars and arrays become plain numbers and lists, paths and enums strings.
"""

from __future__ import annotations

import json
import math
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["json_safe", "dumps"]


def json_safe(v: Any) -> Any:
    """A copy of ``v`` made of dicts, lists, str, int, finite float, bool and None (non-finite floats -> None)."""
    if isinstance(v, dict):
        return {str(k) if not isinstance(k, str) else k: json_safe(x) for k, x in v.items()}
    if isinstance(v, list | tuple | set | frozenset):
        return [json_safe(x) for x in v]
    if isinstance(v, np.ndarray):
        return json_safe(v.tolist())
    if isinstance(v, bool | np.bool_):
        return bool(v)
    if isinstance(v, int | np.integer) and not isinstance(v, Enum):
        return int(v)
    if isinstance(v, float | np.floating):
        f = float(v)
        return f if math.isfinite(f) else None
    if v is None or isinstance(v, str):
        return v
    if isinstance(v, Enum):
        return json_safe(v.value)
    if isinstance(v, Path):
        return str(v)
    if hasattr(v, "value"):
        return json_safe(v.value)
    return str(v)


def dumps(v: Any, indent: int | None = None) -> str:
    """Strict JSON text of ``v`` (see the module docstring); never ``NaN`` or ``Infinity``."""
    return json.dumps(json_safe(v), indent=indent, allow_nan=False)
