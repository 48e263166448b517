"""Where the tests find the repository's files and the shared data folder beside it (``../shared``), from any
working directory and any test subfolder."""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
