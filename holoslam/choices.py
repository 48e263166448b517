"""The named choices a user picks from (the configuration file, the CLI, the library's options), each an enum
defined once here. This module imports nothing heavy, so the CLI derives its ``choices=`` from these enums
without loading numpy or gtsam; the modules that act on a choice import it from here."""

from __future__ import annotations

from enum import Enum

__all__ = ["Method", "Initialisation", "RobustKernel", "TextNoise", "SOLVE_METHODS", "SOLVE_STARTS"]


class Method(str, Enum):
    """How the graph is optimised."""

    BATCH = "batch"  # Levenberg-Marquardt over the whole graph
    ISAM2 = "isam2"  # incremental, anchor by anchor

    @classmethod
    def _missing_(cls, value: object) -> Method | None:
        # "lm" (Levenberg-Marquardt) names the batch solve in configuration files and on the command line
        return cls.BATCH if isinstance(value, str) and value.strip().lower() == "lm" else None


class Initialisation(str, Enum):
    """Where the optimisation starts."""

    PROBLEM = "problem"  # the problem's initial_wTa (g2o vertices / dead reckoning)
    ODOMETRY = "odometry"  # compose the relative measurements in order
    LAGO = "lago"  # gtsam.lago.initialize on the pose graph (diagonal part of each covariance)
    CHORDAL = "chordal"  # chordal relaxation of the rotations, then positions and landmarks by linear least squares
    INCREMENTAL = "incremental"  # an iSAM2 pass, each new pose initialised from the current estimate
    AUTO = "auto"  # LM from each of SolveOptions.auto_candidates (and the fallback if needed), keep the lowest


class RobustKernel(str, Enum):
    """The robust loss on a factor family."""

    NONE = "none"
    HUBER = "huber"
    CAUCHY = "cauchy"
    DCS = "dcs"
    GEMAN_MCCLURE = "geman_mcclure"


class TextNoise(str, Enum):
    """How to read the noise numbers of EDGE2 / EDGE / ODOMETRY / LANDMARK lines (``holoslam.io.g2o``)."""

    GTSAM_AUTO = "gtsam_auto"
    COVARIANCE = "covariance"
    INFORMATION = "information"
    TORO_INFORMATION = "toro_information"
    SQRT_INFORMATION = "sqrt_information"


# the ``holoslam solve`` command's names: "lm" for the batch solve, "file" for the problem's own guess
SOLVE_METHODS: dict[str, Method] = {"lm": Method.BATCH, "isam2": Method.ISAM2}
SOLVE_STARTS: dict[str, Initialisation] = {
    ("file" if i is Initialisation.PROBLEM else i.value): i for i in Initialisation
}
