"""holoslam: a factor-graph SLAM backend for household service robots, built on GTSAM.

Importing this package is cheap and has no side effects: heavy modules (gtsam, OpenCV, mcap) are imported by
the functions that need them.
"""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__"]
