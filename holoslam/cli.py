"""The ``holoslam`` command: parses arguments, calls one library function per command, prints, and maps
errors to exit codes. Only the command line's modules (this one and ``cli_*``) print or exit.

Exit codes: 0 success; 1 the job ran but something failed (a log in a batch, an unreachable goal);
2 bad input (a missing or unreadable required input, a malformed file or config, a usage error).

The command is split by job: :mod:`holoslam.cli_output` (exit codes, progress, error lines),
:mod:`holoslam.cli_commands` (what each command does), :mod:`holoslam.cli_parser` (their arguments).
"""

from __future__ import annotations

import gc
import os
import sys
from collections.abc import Sequence

from holoslam.cli_commands import _topology_config
from holoslam.cli_output import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK, Progress, _err
from holoslam.cli_parser import build_parser
from holoslam.errors import HoloslamError, PlanningError

__all__ = ["main", "console", "build_parser", "Progress", "EXIT_OK", "EXIT_FAILED", "EXIT_BAD_INPUT", "_topology_config"]

#: objects (allocations less frees) between two collections of the garbage collector's youngest generation;
#: CPython's default is 700. A command is one batch job: it allocates millions of short-lived objects (decoded
#: messages, tuples, array wrappers) beside the millions its libraries keep for the process's life (numba's types,
#: matplotlib, networkx), and every tenth collection of the middle generation traverses all of the latter. At 700
#: the collector took 0.4 s of a household run's ~12 s CPU (5 full passes, 0.33 s); at 10,000 it takes 0.17 s (no
#: full pass on that log). Only when garbage forms cycles does the threshold delay freeing it.
GC_YOUNG_OBJECTS = 10_000


def main(argv: Sequence[str] | None = None) -> int:
    # holoslam reports bad images itself; OpenCV's own log lines would only repeat it
    os.environ.setdefault("OPENCV_LOG_LEVEL", "OFF")
    gc.set_threshold(GC_YOUNG_OBJECTS, *gc.get_threshold()[1:])
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


def console() -> int:
    """The ``holoslam`` program (its console script and ``python -m holoslam.cli``): ``main``, then the process
    ends without the interpreter's last garbage collection. That collection walks every object the libraries
    made for the process's life (numba's compiled kernels, matplotlib, networkx): 0.3 s of the household run's
    8 s, to free memory the operating system takes back at exit anyway. ``gc.freeze`` moves those objects out
    of the collector's reach; an embedding program calls ``main``, which leaves the collector alone."""
    code = main()
    gc.freeze()
    return code


if __name__ == "__main__":
    sys.exit(console())
