"""The ``holoslam`` command: parses arguments, calls one library function per command, prints, and maps
errors to exit codes. Only the command line's modules (this one and ``cli_*``) print or exit.

Exit codes: 0 success; 1 the job ran but something failed (a log in a batch, an unreachable goal);
2 bad input (a missing or unreadable required input, a malformed file or config, a usage error).

The command is split by job: :mod:`holoslam.cli_output` (exit codes, progress, error lines),
:mod:`holoslam.cli_commands` (what each command does), :mod:`holoslam.cli_parser` (their arguments).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence

from holoslam.cli_commands import _topology_config
from holoslam.cli_output import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK, Progress, _err
from holoslam.cli_parser import build_parser
from holoslam.errors import HoloslamError, PlanningError

__all__ = ["main", "build_parser", "Progress", "EXIT_OK", "EXIT_FAILED", "EXIT_BAD_INPUT", "_topology_config"]


def main(argv: Sequence[str] | None = None) -> int:
    # holoslam reports bad images itself; OpenCV's own log lines would only repeat it
    os.environ.setdefault("OPENCV_LOG_LEVEL", "OFF")
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except PlanningError as e:
        _err(str(e))
        return EXIT_FAILED
    except HoloslamError as e:
        _err(str(e))
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        _err("interrupted")
        return 130
    except BrokenPipeError:
        return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
