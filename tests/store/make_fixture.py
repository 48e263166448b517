"""Makes ``fixture_v<schema>.holomap``: two 60 s simulated sessions of the household (the second from another start,
its odometry from the identity there) run into a new store by ``holoslam.lifelong.session.run_session``. Run it only
when the schema version changes (the old fixtures stay, as ``fixture_v<old>.holomap``, for the migration tests):

    PYTHONPATH=. python tests/store/make_fixture.py tests/store/fixture_v2.holomap
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path


def main(out: str) -> None:
    from holoslam.lifelong.session import run_session
    from holoslam.sim import SimConfig
    from holoslam.sim.core import simulate_household
    from holoslam.sim.writer import write_household_log

    with tempfile.TemporaryDirectory() as tmp:
        for k, (seed, start) in enumerate([(3, (3.0, 4.8, 0.0)), (5, (4.0, 4.2, 1.2))]):
            log = Path(tmp) / f"session{k + 1}.mcap"
            write_household_log(simulate_household(SimConfig(seed=seed, duration_s=60), start_pose=start), log)
            done = run_session(log, out)
            print("\n".join(done.summary.text_lines()))


if __name__ == "__main__":
    main(sys.argv[1])
