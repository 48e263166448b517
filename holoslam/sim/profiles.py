"""Robot profiles of the simulator: the same household and tour driven by robots whose sensors differ.

holoslam is never told which profile wrote a log (tests map them with the same default configuration), so a
profile checks that nothing in holoslam is tuned to the default robot's noise:

- ``default``: the reference robot (``SimConfig()``: a Pioneer III-like differential drive whose driver publishes
  its propagated odometry covariance).
- ``noisy``: every sensor noise and error three times the default's (``SimConfig.with_noise_scale(3)``): odometer,
  compass, laser.
- ``skid-steer``: another odometer: a four-wheel skid-steer base (Pioneer 3-AT / Husky-like) at 50 Hz. Skid
  steering turns by dragging its wheels sideways, so the turn the wheels report is too large and uncertain (turn
  scale +8 %, 0.05 rad per sqrt(rad)), the base slips sideways (0.02 m per sqrt(m)) and more often (slip events
  0.1 per metre), distance scale +3 %; its driver publishes a constant covariance diagonal
  (``diff_drive_controller``-style), not a propagated one. Compass and laser as the default.
- ``dense-lidar``: the default robot with a Hokuyo UST-10LX / UTM-30LX-like laser: 1,081 beams over 270 deg at
  40 Hz, 30 m range (40 times the default laser's points per second), for speed and memory on dense scans.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from holoslam.errors import ConfigError
from holoslam.sim.core import SimConfig

__all__ = ["PROFILES", "profile_config"]


def _skid_steer(c: SimConfig) -> SimConfig:
    return dataclasses.replace(
        c,
        odom_rate_hz=50.0,
        odom_scale=0.03,
        odom_slip_sigma=0.015,
        odom_slip_event_rate=0.1,
        odom_turn_scale=0.08,
        odom_drift_deg_per_m=0.3,
        odom_turn_sigma=0.05,
        odom_heading_sigma_deg=0.3,
        odom_lateral_sigma=0.02,
        odom_covariance="constant",
    )


def _dense_lidar(c: SimConfig) -> SimConfig:
    return dataclasses.replace(c, laser_rate_hz=40.0, laser_beams=1081, laser_fov_deg=270.0, laser_range_max_m=30.0)


PROFILES: dict[str, Callable[[SimConfig], SimConfig]] = {
    "default": lambda c: c,
    "noisy": lambda c: c.with_noise_scale(3.0),
    "skid-steer": _skid_steer,
    "dense-lidar": _dense_lidar,
}


def profile_config(name: str, **settings) -> SimConfig:
    """The ``SimConfig`` of robot profile ``name`` (module docstring); ``settings`` (seed, duration_s,
    image_rate_hz, ...) are applied first, then the profile's sensors."""
    if name not in PROFILES:
        raise ConfigError(f"unknown robot profile {name!r}; choose one of {', '.join(PROFILES)}")
    return PROFILES[name](SimConfig(**settings))
