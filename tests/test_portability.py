"""The suite passes wherever the README's command runs: no timing limits, no working-directory assumptions."""

from __future__ import annotations

import ast
from pathlib import Path

TESTS = Path(__file__).resolve().parent


def test_property_tests_have_no_time_limit():
    from hypothesis import settings

    assert settings.default.deadline is None


def test_tests_do_not_open_repository_files_relative_to_the_working_directory():
    """``read_log("datasets/...")`` works only when pytest runs from the repository root."""
    bad = []
    for path in sorted(TESTS.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if (
                isinstance(node, ast.Constant)
                and isinstance(node.value, str)
                and node.value.startswith(("datasets/", "notebooks/", "benchmarks/"))
                and node.value.endswith((".mcap", ".ipynb", ".py", ".yaml"))
            ):
                bad.append(f"{path.name}:{node.lineno} {node.value!r}")
    assert bad == [], "use bundled_household_log() or a path from __file__: " + ", ".join(bad)
