"""Synthetic session updates for the map store tests (random but valid arrays, deterministic per seed)."""

from __future__ import annotations

import numpy as np

from holoslam.store.records import NewSubmap, ObjectState, SessionUpdate, StoredTrajectory, new_ref


def make_update(seed: int = 0, n_submaps: int = 4, stored_ids: tuple[int, ...] = (), n_poses: int = 200,
                expected_id: int = 0) -> SessionUpdate:
    rng = np.random.default_rng(seed)
    subs = []
    for k in range(n_submaps):
        prob = rng.uniform(0.1, 0.9, (40, 50)).astype(np.float32)
        known = rng.uniform(size=(40, 50)) > 0.3
        subs.append(NewSubmap(k, 1_000 + k, rng.normal(size=3), np.eye(3) * 1e-4, rng.normal(size=3), prob,
                              (-1.0, -1.2), 0.05, rng.normal(size=(100, 2)).astype(np.float32), known))
    fi = [new_ref(k) for k in range(n_submaps - 1)] + list(stored_ids)
    fj = [new_ref(k + 1) for k in range(n_submaps - 1)] + [new_ref(0)] * len(stored_ids)
    kinds = ("scan_match",) * (n_submaps - 1) + ("cross",) * len(stored_ids)
    m = len(fi)
    objs = (ObjectState("O05", "cup", "HL1;O05;cup;s=60", "new", np.array([1.0, 2.0]), 0.5, np.eye(2) * 1e-4, 3,
                        "O05#1", view=np.array([0.0, 1.0]), normal=np.array([0.6, 0.8]), normal_sigma_rad=0.03),
            ObjectState("O07", "armchair", "HL1;O07;armchair", "moved", np.array([3.0, 2.0]), 0.45, np.eye(2) * 4e-4,
                        2, "O07#2", np.array([0.5, 0.1]), np.eye(2) * 1e-3))
    stamps = np.sort(rng.integers(0, 10**12, n_poses))
    traj = StoredTrajectory(stamps, rng.integers(0, n_submaps, n_poses).astype(np.int32), rng.normal(size=(n_poses, 3)),
                            rng.normal(size=(n_poses, 3)))
    return SessionUpdate(
        f"log{seed}.mcap", f"{seed:064x}", int(stamps[0]), int(stamps[-1]), True, "laser", rng.normal(size=3),
        np.eye(3) * 1e-4, 1.5, {"seed": seed}, tuple(subs), np.array(fi, np.int64), np.array(fj, np.int64),
        rng.normal(size=(m, 3)), np.broadcast_to(np.eye(3) * 1e-3, (m, 3, 3)).copy(), kinds,
        np.array([new_ref(0), new_ref(1)], np.int64), ("O05", "O07"), ("O05#1", "O07#2"), rng.normal(size=(2, 2)),
        np.broadcast_to(np.eye(2) * 1e-3, (2, 2, 2)).copy(), np.array([0.5, np.nan]), objs, traj,
        expected_id=expected_id)
