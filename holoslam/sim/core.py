"""``SimConfig``, ``SimulatedRun`` and the entry points ``simulate_household`` / ``simulate_to_file``."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from holoslam.errors import ConfigError

if TYPE_CHECKING:
    from holoslam.sim.sensors import CompassStream, OdometryStream, ScanStream, Snapshot
    from holoslam.sim.world import World

__all__ = ["SimConfig", "SimulatedRun", "simulate_household", "simulate_to_file", "T0_NS"]

T0_NS = 1_700_000_000_000_000_000  # sensor time of the first odometry message (2023-11-14T22:13:20Z)


@dataclass(frozen=True)
class SimConfig:
    """Settings of one simulated run; every noise default is the documented sensor model's.

    Angles are given in degrees here (config files are written by people); the sensor functions take
    radians."""

    seed: int = 2
    duration_s: float | None = 500.0  # None: one complete tour (about 570 s)
    odom_rate_hz: float = 20.0
    odom_scale: float = 0.015  # systematic distance scale error (+1.5 %)
    odom_slip_sigma: float = 0.01  # random slip, m per sqrt(m) travelled
    odom_slip_event_rate: float = 0.05  # wheel-slip events per metre (each over-reports one step 1.5-3x)
    odom_turn_scale: float = 0.02  # systematic turn scale error (+2 %)
    odom_drift_deg_per_m: float = 0.5  # heading drift from unequal wheel radii
    odom_turn_sigma: float = 0.02  # rad per sqrt(rad) turned
    odom_heading_sigma_deg: float = 0.2  # heading random walk while driving, deg per sqrt(m)
    odom_lateral_sigma: float = 0.0  # sideways slip the odometer does not see, m per sqrt(m) (0: differential)
    odom_covariance: str = "propagated"  # what the odometry driver publishes: propagated | constant | zero
    compass_rate_hz: float = 10.0
    compass_sigma_deg: float = 1.5
    compass_bias_deg: float = 2.0
    compass_disturbance_scale: float = 1.0  # multiplies the world's appliance amplitudes (3-6 deg)
    compass_disturbance_radius: float = 1.0  # m
    laser_rate_hz: float = 5.0
    laser_sigma: float = 0.01  # m
    laser_beams: int = 181  # evenly over laser_fov_deg, the first at -fov / 2
    laser_fov_deg: float = 180.0
    laser_range_max_m: float = 8.0
    laser_dropout: float = 0.0  # share of beams that return nothing at random (glass, dark or shiny surfaces)
    image_rate_hz: float = 0.25  # most snapshots per second
    resnap_s: float = 60.0  # the operator does not photograph the same label again within this time
    image_width: int = 640
    image_height: int = 480
    jpeg_quality: int = 55
    wall_codes: int = 0  # foreign QR codes on walls (holoslam.sim.world.WALL_CODES, the first k)
    sizeless_labels: int = 0  # labels printed without their size (holoslam.sim.world.SIZELESS_ORDER, the first k)
    # camera stream (holoslam.sim.stream): frames per second for the whole drive; 0 = operator snapshots only
    camera_rate_hz: float = 0.0
    # ms: the stream's exposure, over which the robot's motion blurs a frame; a typical indoor auto-exposure of
    # a robot's CMOS camera (5-30 ms at a few hundred lux); the longest a 15 fps stream allows is 66 ms
    camera_exposure_ms: float = 10.0
    # s: how long the stream's head tracks a label after the operator's logic aimed at it (then it looks ahead)
    camera_dwell_s: float = 2.0

    def __post_init__(self) -> None:
        checks = [
            (
                "duration_s",
                self.duration_s is None or self.duration_s > 0,
                "a positive number of seconds or None",
            ),
            ("odom_rate_hz", self.odom_rate_hz > 0, "positive"),
            ("compass_rate_hz", self.compass_rate_hz > 0, "positive"),
            ("laser_rate_hz", self.laser_rate_hz > 0, "positive"),
            ("image_rate_hz", self.image_rate_hz >= 0, "zero (no images) or positive"),
            ("jpeg_quality", 1 <= self.jpeg_quality <= 100, "an integer in 1..100"),
            ("image_width", 160 <= self.image_width <= 4096, "160..4096 pixels"),
            ("image_height", 120 <= self.image_height <= 4096, "120..4096 pixels"),
            ("odom_slip_sigma", self.odom_slip_sigma >= 0, ">= 0"),
            ("odom_turn_sigma", self.odom_turn_sigma >= 0, ">= 0"),
            ("odom_heading_sigma_deg", self.odom_heading_sigma_deg >= 0, ">= 0"),
            ("odom_lateral_sigma", self.odom_lateral_sigma >= 0, ">= 0"),
            ("odom_covariance", self.odom_covariance in ("propagated", "constant", "zero"),
             "propagated, constant or zero"),
            ("compass_sigma_deg", self.compass_sigma_deg >= 0, ">= 0"),
            ("laser_sigma", self.laser_sigma >= 0, ">= 0"),
            ("laser_beams", 2 <= self.laser_beams <= 10_000, "2..10000 beams"),
            ("laser_fov_deg", 0 < self.laser_fov_deg <= 360, "a field of view in (0, 360] degrees"),
            ("laser_range_max_m", 0 < self.laser_range_max_m <= 200, "(0, 200] metres"),
            ("laser_dropout", 0 <= self.laser_dropout < 1, "a share of beams in [0, 1)"),
            ("wall_codes", 0 <= self.wall_codes <= 12, "0..12"),
            ("sizeless_labels", 0 <= self.sizeless_labels <= 8, "0..8"),
            ("camera_rate_hz", 0 <= self.camera_rate_hz <= 60, "0 (no stream) or up to 60 frames per second"),
            ("camera_exposure_ms", 0 <= self.camera_exposure_ms <= 1000.0 / max(self.camera_rate_hz, 1.0),
             "0 ms up to one frame period"),
            ("camera_dwell_s", self.camera_dwell_s >= 0, ">= 0 seconds"),
        ]
        for name, ok, what in checks:
            if not ok:
                raise ConfigError(f"SimConfig.{name} = {getattr(self, name)!r}: expected {what}")

    def with_noise_scale(self, factor: float) -> SimConfig:
        """A copy with every sensor noise and error (odometer, compass, laser) multiplied by ``factor``."""
        if not (factor >= 0 and math.isfinite(factor)):
            raise ConfigError(f"noise scale {factor!r}: expected a finite number >= 0")
        names = (
            "odom_scale",
            "odom_slip_sigma",
            "odom_slip_event_rate",
            "odom_turn_scale",
            "odom_drift_deg_per_m",
            "odom_turn_sigma",
            "odom_heading_sigma_deg",
            "odom_lateral_sigma",
            "compass_sigma_deg",
            "compass_bias_deg",
            "compass_disturbance_scale",
            "laser_sigma",
        )
        return dataclasses.replace(self, **{n: getattr(self, n) * factor for n in names})

    def metadata(self) -> dict[str, str]:
        """The config as the string map of the MCAP metadata record ``holoslam``."""
        d = {k: repr(v) if isinstance(v, float) else str(v) for k, v in dataclasses.asdict(self).items()}
        for extra in ("wall_codes", "sizeless_labels"):  # the reference household's log stays as it was
            if not getattr(self, extra):
                del d[extra]
        if not self.camera_rate_hz:  # snapshot mode: the stream's settings are not part of the run
            for extra in ("camera_rate_hz", "camera_exposure_ms", "camera_dwell_s"):
                del d[extra]
        for name, default in (("odom_lateral_sigma", 0.0), ("odom_covariance", "propagated"), ("laser_beams", 181),
                              ("laser_fov_deg", 180.0), ("laser_range_max_m", 8.0),
                              ("laser_dropout", 0.0)):
            if getattr(self, name) == default:  # likewise: absent from a differential-drive profile's metadata
                del d[name]
        d["generator"] = "holoslam.sim.simulate_household"
        d["world"] = "reference_household (seed 002)"
        return d


@dataclass(frozen=True)
class SimulatedRun:
    """Everything one simulation produced, in memory."""

    config: SimConfig
    world: World
    stamps_ns: np.ndarray  # (N,) true trajectory stamps (= odometry stamps)
    wTb: np.ndarray  # (N, 3) true base poses in map
    odometry: OdometryStream
    compass: CompassStream
    scans: ScanStream
    snapshots: tuple[Snapshot, ...]


def simulate_household(config: SimConfig = SimConfig(), world: World | None = None,
                       start_pose: tuple[float, float, float] | None = None, t0_ns: int = T0_NS,
                       remembered: tuple = ()) -> SimulatedRun:
    """Simulate the reference household run for ``config`` (pure and deterministic for a config). ``world``:
    another household (default: the reference household with the config's extras); ``start_pose`` (x, y, yaw
    in map): where the robot starts (default ``route.START_POSE``); ``t0_ns``: the first stamp (another day);
    ``remembered``: the robot's map of the home (``WorldObject`` records where it believes objects are), whose
    places the route stops at (``route.plan_stations``) and the snapshot camera checks
    (``sensors.camera_snapshots``; empty: none, a first day)."""
    from holoslam.sim.route import START_POSE, household_trajectory
    from holoslam.sim.sensors import camera_snapshots, compass, laser_scans, odometry
    from holoslam.sim.world import reference_household

    if world is None:
        world = reference_household(config.wall_codes, config.sizeless_labels)
    start = START_POSE if start_pose is None else (float(start_pose[0]), float(start_pose[1]), float(start_pose[2]))
    traj = household_trajectory(world, config.duration_s, config.odom_rate_hz, config.seed, t0_ns, start,
                                tuple(remembered))

    def rng(stream: int) -> np.random.Generator:
        return np.random.default_rng(np.random.SeedSequence([config.seed, stream]))

    odo = odometry(
        traj.stamps_ns,
        traj.wTb,
        rng(1),
        scale=config.odom_scale,
        slip_sigma=config.odom_slip_sigma,
        slip_event_rate=config.odom_slip_event_rate,
        turn_scale=config.odom_turn_scale,
        drift=math.radians(config.odom_drift_deg_per_m),
        turn_sigma=config.odom_turn_sigma,
        heading_sigma=math.radians(config.odom_heading_sigma_deg),
        lateral_sigma=config.odom_lateral_sigma,
        covariance=config.odom_covariance,
    )
    com = compass(
        world,
        traj.stamps_ns,
        traj.wTb,
        rng(2),
        rate_hz=config.compass_rate_hz,
        sigma=math.radians(config.compass_sigma_deg),
        bias=math.radians(config.compass_bias_deg),
        disturbance_radius=config.compass_disturbance_radius,
        disturbance_scale=config.compass_disturbance_scale,
    )
    scans = laser_scans(
        world, traj.stamps_ns, traj.wTb, rng(3), rate_hz=config.laser_rate_hz, sigma=config.laser_sigma,
        beams=config.laser_beams, fov_deg=config.laser_fov_deg, range_max=config.laser_range_max_m,
        dropout=config.laser_dropout,
    )
    snaps: list = []
    if config.camera_rate_hz > 0:
        from holoslam.sim.stream import camera_stream

        snaps = camera_stream(
            world,
            traj.stamps_ns,
            traj.wTb,
            rng(4),
            rate_hz=config.camera_rate_hz,
            exposure_s=config.camera_exposure_ms * 1e-3,
            dwell_s=config.camera_dwell_s,
            image_rate_hz=config.image_rate_hz,
            resnap_s=config.resnap_s,
            jpeg_quality=config.jpeg_quality,
            size=(config.image_width, config.image_height),
        )
    elif config.image_rate_hz > 0:
        snaps = camera_snapshots(
            world,
            traj.stamps_ns,
            traj.wTb,
            rng(4),
            image_rate_hz=config.image_rate_hz,
            resnap_s=config.resnap_s,
            jpeg_quality=config.jpeg_quality,
            size=(config.image_width, config.image_height),
            remembered=tuple(remembered),
        )
    return SimulatedRun(config, world, traj.stamps_ns, traj.wTb, odo, com, scans, tuple(snaps))


def simulate_to_file(path: str | Path, config: SimConfig = SimConfig()) -> dict:
    """Simulate and write the MCAP log; returns a summary (path, size, counts, sha256) for the CLI."""
    import hashlib

    from holoslam.sim.writer import write_household_log

    run = simulate_household(config)
    counts = write_household_log(run, path)
    data = Path(path).read_bytes()
    return {
        "path": str(path),
        "bytes": len(data),
        "sha256": hashlib.sha256(data).hexdigest(),
        "duration_s": round(float((run.stamps_ns[-1] - run.stamps_ns[0]) * 1e-9), 6),
        "seed": config.seed,
        "messages": counts,
        "images": len(run.snapshots),
        "labels_seen": sorted({i for s in run.snapshots for i in s.visible_ids}),
    }
