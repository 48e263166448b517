"""Settings of the whole test suite that must hold on any machine, and fixtures several test folders share."""

from __future__ import annotations

import pytest
from hypothesis import settings

# Hypothesis' default deadline (200 ms per example, then a "flaky" failure) is a timing assertion: on a loaded
# 2-core CI machine, under pytest-xdist, or on the first call into a just-compiled numba kernel, an example can
# take longer without anything being wrong. The suite checks results, not speed (benchmarks/ measure speed).
settings.register_profile("holoslam", deadline=None, derandomize=True)  # the same examples on every machine
settings.load_profile("holoslam")


@pytest.fixture(scope="session")
def twenty_short_logs(tmp_path_factory):
    """20 short simulated logs (6 s each, seeds 100..119) and a fast run configuration, written once per test
    process (~9 s): (folder of logs, list of logs, config file). See tests/fault_logs.py."""
    from fault_logs import fast_config, write_short_logs

    root = tmp_path_factory.mktemp("fleet20")
    logs = write_short_logs(root / "logs", 20)
    return root / "logs", logs, fast_config(root)
