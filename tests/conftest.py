"""Settings of the whole test suite that must hold on any machine."""

from __future__ import annotations

from hypothesis import settings

# Hypothesis' default deadline (200 ms per example, then a "flaky" failure) is a timing assertion: on a loaded
# 2-core CI machine, under pytest-xdist, or on the first call into a just-compiled numba kernel, an example can
# take longer without anything being wrong. The suite checks results, not speed (benchmarks/ measure speed).
settings.register_profile("holoslam", deadline=None, derandomize=True)  # the same examples on every machine
settings.load_profile("holoslam")
