"""What the ``holoslam`` command prints besides a command's result: its exit codes, stage-by-stage progress and
error lines on stderr, strict JSON. Only the command line's modules (``holoslam.cli``, ``cli_*``) print or exit.
"""

from __future__ import annotations

import sys
import time

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2


class Progress:
    """Stage-by-stage progress on stderr: a line per finished stage with its time; quiet when asked."""

    def __init__(self, quiet: bool = False) -> None:
        self.quiet = quiet
        self.tty = sys.stderr.isatty()
        self._t0 = time.perf_counter()
        self._last = ""

    def __call__(self, stage: str, done: float | None = None, total: float | None = None) -> None:
        if self.quiet:
            return
        if done is not None and total:
            line = f"  {stage}: {100.0 * done / total:5.1f}%"
            if self.tty:
                sys.stderr.write("\r" + line.ljust(len(self._last)))
                sys.stderr.flush()
                self._last = line
            return
        if self._last:
            sys.stderr.write("\n")
            self._last = ""
        sys.stderr.write(f"[{time.perf_counter() - self._t0:7.2f}s] {stage}\n")
        sys.stderr.flush()


def _err(msg: str) -> None:
    sys.stderr.write(f"holoslam: {msg}\n")


def _json(v, indent: int | None = 2) -> str:
    """Strict JSON (NaN / infinity printed as null: ``NaN`` is not JSON and breaks jq and JSON.parse)."""
    from holoslam.io.jsonsafe import dumps

    return dumps(v, indent=indent)
