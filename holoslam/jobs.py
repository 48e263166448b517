"""One typed library call per CLI command (the commands whose job lives here; the older ones are in
:mod:`holoslam.pipeline`). Each returns a result record that knows its numbers; the CLI turns it into text.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from holoslam.errors import ConfigError, IngestError

if TYPE_CHECKING:
    from holoslam.evaluate import GroundTruthErrors, RelationErrors

__all__ = ["Evaluation", "evaluate_trajectory", "trajectory_path"]


@dataclass(frozen=True)
class Evaluation:
    """What ``holoslam evaluate`` measured: the trajectory scored, what it was scored against, and the errors
    (``relations`` for a ``.relations`` file, ``truth`` for a TUM ground truth)."""

    trajectory: str
    reference: str
    poses: int
    relations: RelationErrors | None = None
    truth: GroundTruthErrors | None = None

    @property
    def ok(self) -> bool:
        """False when nothing could be scored (no relation had a pose near both of its stamps)."""
        return self.relations is None or self.relations.n_matched > 0

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "trajectory": self.trajectory,
            "reference": self.reference,
            "poses": self.poses,
        }
        if self.relations is not None:
            out["relation_errors"] = self.relations.to_dict()
        if self.truth is not None:
            out["ground_truth_errors"] = self.truth.to_dict()
        return out


def trajectory_path(target: str | Path) -> Path:
    """The TUM file to score: ``target`` itself, or the ``trajectory.tum`` of a run folder."""
    p = Path(target)
    if p.is_dir():
        tum = p / "trajectory.tum"
        if not tum.is_file():
            raise IngestError(
                f"{p}: a folder without trajectory.tum; give a run folder written by 'holoslam run' or a TUM file"
            )
        return tum
    if not p.exists():
        raise IngestError(f"{p}: no such file or folder; give a run folder or a TUM trajectory file")
    return p


def evaluate_trajectory(
    target: str | Path,
    *,
    relations: str | Path | None = None,
    truth: str | Path | None = None,
    max_dt_s: float = 0.05,
    rpe_delta_s: float = 1.0,
) -> Evaluation:
    """Score a run folder's ``trajectory.tum`` (or any TUM file) against a ``.relations`` file (relation
    errors: poses matched to the nearest stamp within ``max_dt_s``) or a TUM ground truth (ATE after SE(2)
    alignment and RPE over ``rpe_delta_s``). Exactly one of ``relations`` and ``truth``."""
    import math

    from holoslam.evaluate import ground_truth_errors, relation_errors
    from holoslam.io.relations import read_relations

    if (relations is None) == (truth is None):
        raise ConfigError("give exactly one reference: a .relations file or a TUM ground truth")
    if not (math.isfinite(max_dt_s) and max_dt_s >= 0):
        raise ConfigError(f"the stamp tolerance must be a finite number of seconds >= 0, got {max_dt_s}")
    if not (math.isfinite(rpe_delta_s) and rpe_delta_s > 0):
        raise ConfigError(f"the RPE time step must be a finite number of seconds > 0, got {rpe_delta_s}")
    tum = trajectory_path(target)
    stamps, wTb = _read_trajectory(tum)
    if relations is not None:
        rel = read_relations(relations)
        errors = relation_errors(stamps, wTb, rel, max_dt_ns=int(round(max_dt_s * 1e9)))
        return Evaluation(str(tum), str(relations), int(len(stamps)), relations=errors)
    gt_path = trajectory_path(truth)  # type: ignore[arg-type]
    gt_stamps, gt_wTb = _read_trajectory(gt_path)
    if not (stamps.max() >= gt_stamps.min() and stamps.min() <= gt_stamps.max()):
        raise IngestError(
            f"{tum}: no pose inside the ground truth's time span ({gt_stamps.min() / 1e9:.6f} to "
            f"{gt_stamps.max() / 1e9:.6f} s; the trajectory spans {stamps.min() / 1e9:.6f} to "
            f"{stamps.max() / 1e9:.6f} s); give the ground truth of the same log, stamped in the same clock"
        )
    errors_gt = ground_truth_errors(
        stamps, wTb, gt_stamps, gt_wTb, rpe_delta_ns=int(round(rpe_delta_s * 1e9))
    )
    return Evaluation(str(tum), str(gt_path), int(len(stamps)), truth=errors_gt)


def _read_trajectory(path: Path) -> tuple[Any, Any]:
    """(stamps_ns, wTb) of a TUM file, with every way it can be unusable said as an IngestError."""
    import numpy as np

    from holoslam.io.trajectory import read_tum

    try:
        stamps, wTb = read_tum(path)
    except IsADirectoryError:
        raise IngestError(f"{path}: is a folder; give a TUM trajectory file") from None
    except UnicodeDecodeError:
        raise IngestError(
            f"{path}: not a text file; a TUM trajectory holds lines 'stamp x y z qx qy qz qw'"
        ) from None
    except OSError as e:
        raise IngestError(f"{path}: cannot be read ({e.strerror})") from None
    if len(stamps) == 0:
        raise IngestError(
            f"{path}: no pose in the file; a TUM trajectory holds lines 'stamp x y z qx qy qz qw'"
        )
    if not np.all(np.isfinite(wTb)):
        raise IngestError(f"{path}: a pose holds a non-finite number (nan or inf); give finite poses")
    return stamps, wTb
