"""Where the tests find the repository's files and the shared data folder beside it (``../shared``), from any
working directory and any test subfolder."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"


def benchmark_module(name: str) -> ModuleType:
    """``benchmarks/NAME.py`` imported as module ``NAME`` (the benchmarks are scripts, not a package; registered in
    ``sys.modules`` so that dataclasses and pickling inside it find their module)."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, REPO / "benchmarks" / f"{name}.py")
    assert spec is not None and spec.loader is not None, name
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod
