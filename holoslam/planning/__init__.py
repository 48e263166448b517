"""holoslam.planning: the two-layer planning graph of seed 003 (``twolayer``) and planning queries
(``routes``: pose -> pose and pose -> object through the convex regions)."""

from holoslam.planning.routes import (
    LENGTH_FACTOR,
    Route,
    RoutePlanner,
    build_planner,
    plan_path,
    plan_to_object,
    segments_free,
)
from holoslam.planning.twolayer import TwoLayerGraph, build_two_layer, decompose

__all__ = [
    "LENGTH_FACTOR",
    "Route",
    "RoutePlanner",
    "TwoLayerGraph",
    "build_planner",
    "build_two_layer",
    "decompose",
    "plan_path",
    "plan_to_object",
    "segments_free",
]
