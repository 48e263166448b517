"""Typed configuration: frozen dataclasses with defaults, loadable from YAML (safe loader only).

``from_mapping(cls, data)`` builds any (nested) config dataclass from plain data and rejects nonsense with a
message that names the offending key path, what was expected, and (for a misspelt key) the closest valid
name. The run configuration tree (``RunConfig`` and its sections) is defined here too, so every setting a run uses
is in one file; each stage's own settings (front end, map cleaning, ...) live beside their algorithm and are
nested into the tree.
"""

from __future__ import annotations

import dataclasses
import difflib
import enum
import math
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any, TypeVar

from holoslam.choices import Method
from holoslam.errors import ConfigError, MapError
from holoslam.maps.settings import HolographicConfig, TopologyConfig
from holoslam.maps.topology import DEFAULT_ROBOT_RADIUS_M
from holoslam.submaps.frontend import FrontEndConfig

if typing.TYPE_CHECKING:
    from holoslam.vision.stream import StreamSettings

__all__ = [
    "from_mapping",
    "to_mapping",
    "load_yaml_config",
    "RunConfig",
    "SolverMethod",
    "SolverConfig",
    "VisionConfig",
    "SightingSource",
    "GridConfig",
    "TopologyConfig",
    "HolographicConfig",
    "PlanningConfig",
    "RobotConfig",
    "load_run_config",
    "dump_run_config",
]

T = TypeVar("T")

# settings that moved or went: (section class, old key) -> what to do instead
_ROBOT = "(one robot description); move it there"
_RATE = ("is gone: a per-step sigma depends on how often the odometry is published; the random walks are "
         "sigma_s_per_sqrt_m, odo_sigma_turn_per_sqrt_rad and odo_sigma_heading_per_sqrt_m, the floor sigma_floor_m/rad")
_MOVED_KEYS = {
    ("PlanningConfig", "robot_radius_m"): f"is now 'robot.radius_m' {_ROBOT}",
    ("HolographicConfig", "robot_radius_m"): f"is now 'robot.radius_m' {_ROBOT}",
    ("HolographicConfig", "arm_reach_m"): f"is now 'robot.arm_reach_m' {_ROBOT}",
    ("HolographicConfig", "doorway_width_m"): "is now 'holographic.rooms.door_width_max_m'; move it there",
    ("HolographicConfig", "min_room_area_m2"): "is now 'holographic.rooms.min_room_area_m2'; move it there",
    ("FrontEndConfig", "default_heading_sigma"): "is now 'frontend.dead_reckoning.compass_sigma' (one compass default)",
    **{("DeadReckoningConfig", k): _RATE for k in ("sigma_s_per_m", "sigma_s_floor", "odo_sigma_dtheta_per_rad",
                                                   "odo_sigma_dtheta_per_m", "odo_sigma_dtheta_floor")},
}


def _describe(tp: Any) -> str:
    return getattr(tp, "__name__", str(tp))


def _convert(tp: Any, value: Any, where: str) -> Any:
    origin = typing.get_origin(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        errors = []
        for a in args:
            if a is type(None):
                continue
            try:
                return _convert(a, value, where)
            except ConfigError as e:
                errors.append(str(e))
        raise ConfigError(errors[0] if errors else f"{where}: unexpected value {value!r}")
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: expected a mapping of {_describe(tp)} fields, got {value!r}")
        return from_mapping(tp, value, where)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        choices = [m.value for m in tp]
        if isinstance(value, tp):
            return value
        for m in tp:
            if value == m.value or (isinstance(value, str) and value.lower() == str(m.value).lower()):
                return m
        try:  # an enum's own aliases (its _missing_: "lm" for Method.BATCH)
            return tp(value)
        except ValueError:
            raise ConfigError(f"{where}: {value!r} is not one of {choices}") from None
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise ConfigError(f"{where}: expected true or false, got {value!r}")
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        if not math.isfinite(float(value)):
            raise ConfigError(f"{where}: expected a finite number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected text, got {value!r}")
        return value
    if tp is Path:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a path, got {value!r}")
        if not value.strip():
            raise ConfigError(f"{where}: the path is empty; give a file path or remove the key")
        return Path(value)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{where}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ConfigError(f"{where}: expected {len(args)} items, got {len(value)}")
        return tuple(
            _convert(a, v, f"{where}[{i}]") for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if origin in (dict, Mapping) or tp is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: expected a mapping, got {value!r}")
        return dict(value)
    return value


def from_mapping(cls: type[T], data: Mapping[str, Any], where: str = "config") -> T:
    """Build the dataclass ``cls`` from ``data``; unknown keys and wrong types raise ``ConfigError``."""
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        if not isinstance(key, str) or key not in fields:
            moved = _MOVED_KEYS.get((cls.__name__, str(key)))
            if moved is not None:
                raise ConfigError(f"{where}: {key!r} {moved}")
            close = difflib.get_close_matches(str(key), list(fields), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else f"; valid keys: {', '.join(sorted(fields))}"
            raise ConfigError(f"{where}: unknown key {key!r}{hint}")
        kwargs[key] = _convert(hints[key], value, f"{where}.{key}")
    try:
        obj = cls(**kwargs)
    except (TypeError, ValueError, MapError) as e:
        raise ConfigError(f"{where}: {e}") from None
    return obj


def to_mapping(obj: Any) -> Any:
    """Plain data (dicts, lists, scalars) of a config dataclass, for YAML/JSON and reports."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_mapping(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, enum.Enum):
        return obj.value
    if isinstance(obj, tuple | list):
        return [to_mapping(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, Mapping):
        return {str(k): to_mapping(v) for k, v in obj.items()}
    return obj


def load_yaml_config(cls: type[T], path: str | Path) -> T:
    """Read a YAML file with ``yaml.safe_load`` and build ``cls`` from it."""
    import yaml

    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as e:
        raise ConfigError(f"cannot read config file {p}: {e.strerror}; check the path") from None
    except UnicodeDecodeError:
        raise ConfigError(f"config file {p} is not UTF-8 text; is it the right file?") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise ConfigError(f"config file {p} is not valid YAML{at}: {getattr(e, 'problem', e)}") from None
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise ConfigError(f"config file {p} must hold a mapping of sections, got {type(data).__name__}")
    return from_mapping(cls, data, where=p.name)


# ------------------------------------------------------------------------------------------- the run tree


SolverMethod = Method  # the configuration's name for holoslam.choices.Method ("lm" reads as batch)


@dataclass(frozen=True)
class SolverConfig:
    """How the graph is optimised: batch Levenberg-Marquardt or incremental iSAM2 (anchor by anchor),
    outlier rejection (robust kernels + chi2 consistency rounds), marginal covariances of anchors/objects."""

    method: Method = Method.BATCH  # batch (Levenberg-Marquardt; "lm" is read as batch) or isam2
    reject_outliers: bool = True
    chi2_probability: float = 0.9999
    covariances: bool = True
    max_iterations: int = 100
    # isam2: a variable is relinearised when its step exceeds this (m / rad). gtsam's 0.1 leaves the estimate
    # millimetres off the batch optimum, enough to flip a chi2 outlier decision on the household log; 0.001
    # gives the batch answer (1e-6 m) at the same cost on a household-sized graph
    isam2_relinearize_threshold: float = 0.001


class SightingSource(str, Enum):
    """Where object sightings come from. ``auto``: the log's images decoded here when it has images, else the
    robot's own tag topic; ``images`` / ``tags``: only that; ``both``: images first, then the tag sightings no
    image decode gave (same stamp and id)."""

    AUTO = "auto"
    IMAGES = "images"
    TAGS = "tags"
    BOTH = "both"


@dataclass(frozen=True)
class VisionConfig:
    """Where object sightings come from (pixels first: ``source``), how objects are located from them, and
    whether codes that are not holoslam labels become landmarks.

    A label with its printed size (``s=``) is located by PnP in every view; one without (and a foreign code)
    by triangulation over views from robot poses at least ``min_parallax_deg`` apart as seen from the code,
    views agreeing within ``inlier_m`` (``holoslam.vision.multiview``), once the trajectory is solved; the
    graph is then solved again with them. ``foreign_landmarks``: any QR code that is not a holoslam label
    (a product code, a Wi-Fi sticker, a poster) becomes an anonymous landmark keyed by its payload
    (``holoslam.vision.label.foreign_code_id``); off by default until measured on real homes. ``laser_range``:
    where at least two views' rays meet laser-seen surfaces (walls, furniture fronts) at one place that agrees
    with the triangulation, each view is located by its ray and the laser's range instead
    (``holoslam.vision.landmarks``)."""

    source: SightingSource = SightingSource.AUTO
    sigma_px: float = 0.5
    # the robot's base frame; "" = the log's: the mapping's frames.base, else the odometry's child frame
    base_frame: str = ""
    features: bool = True  # the object feature set of Eq. 13 (size, texture, colours, SIFT) from image crops
    triangulate: bool = True  # labels without a printed size: located over views from several robot poses
    foreign_landmarks: bool = False  # codes that are not holoslam labels become anonymous landmarks
    min_parallax_deg: float = 2.0  # deg between two views' rays at the code, for them to triangulate it
    inlier_m: float = 0.10  # m: a view agrees with a triangulated point when its ray passes this close
    laser_range: bool = True  # a code's range along its rays from the laser points, where views agree
    # camera streams (holoslam.vision.stream.StreamSettings, where the defaults are justified): a quick look
    # (zxing-cpp's fast path) before the full decode; frames showing the view just decoded are not decoded again
    prefilter: bool = True
    skip_same_view: bool = True
    same_view_m: float = 0.05  # m the camera moved since the last full decode: one map cell
    same_view_deg: float = 1.0  # deg the camera turned since: twice a PTZ head's pointing repeatability
    same_view_max_s: float = 1.0  # s: a view is decoded again at least this often while it lasts
    decodes_per_view: int = 2  # full decodes of a view before its repeats are skipped: a payload's confirmation
    first_decoder_when_read: bool = True  # zbar only on frames whose quick look left a symbol unread

    def stream_settings(self) -> StreamSettings:
        """The stream settings of the vision stage (``holoslam.vision.stream``)."""
        from holoslam.vision.stream import StreamSettings

        return StreamSettings(self.prefilter, self.skip_same_view, self.same_view_m, self.same_view_deg,
                              self.same_view_max_s, self.decodes_per_view, self.first_decoder_when_read)


@dataclass(frozen=True)
class GridConfig:
    """The global occupancy grid: resolution (m/cell) and how far a no-return beam clears free space."""

    resolution: float = 0.05
    no_return_clear_m: float = 3.0
    margin_m: float = 0.5


@dataclass(frozen=True)
class RobotConfig:
    """The robot description: one base footprint and one arm, for every stage that asks how big the robot is or
    how far it reaches: the configuration space of the planning graph (free space eroded by ``radius_m``), the
    reach model of the holographic graph (where the base fits, what the arm reaches from there) and the narrowest
    passage doorway detection considers (``2 radius_m``). Defaults: the reference robot of the method (seed 002):
    a Pioneer III (3-DX) base with an arm on its top plate. Sensor mountings are not here: the log's /tf_static gives
    the laser's and the camera's pose on the base, and a second copy could only disagree with it."""

    # m: radius of the circle the base sweeps turning in place about its centre (the odometry frame's origin);
    # the paper's Pioneer III (3-DX datasheet: body 455 x 381 mm, swing radius about 26 cm). The planning graph's
    # configuration space, the reach model's standing points and the narrowest doorway (2 radius_m) use it
    radius_m: float = DEFAULT_ROBOT_RADIUS_M
    # m: horizontal distance from the base centre the gripper reaches; a Kinova JACO-class arm (reach 0.90 m)
    # mounted near the centre of the top plate
    arm_reach_m: float = 0.9
    # m: how far the arm reaches over an obstacle (the furniture an object stands on) toward the object: the
    # front half of a standard 600 mm deep kitchen worktop plus one 5 cm map cell, the full depth of a 350 mm
    # shelf. An object farther behind an obstacle is out of reach (the paper's chair behind the dining table)
    reach_through_m: float = 0.35
    # m: label heights the robot can handle, from the floor ...
    reach_z_min_m: float = 0.0
    reach_z_max_m: float = 2.5  # m: ... to the highest label it operates (the paper counts its air conditioner)

    def __post_init__(self) -> None:
        for name in ("radius_m", "arm_reach_m", "reach_through_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name} must be a finite number of metres >= 0, got {v!r}")
        if not self.reach_z_min_m <= self.reach_z_max_m:
            raise ValueError(f"reach_z_min_m {self.reach_z_min_m} is above reach_z_max_m {self.reach_z_max_m}")


@dataclass(frozen=True)
class PlanningConfig:
    """Two-layer planning graph: built on the free space eroded by the robot's radius (``robot.radius_m``: its
    configuration space), with the nine-square split stopping at ``min_block_cells`` (mixed blocks smaller count
    as occupied)."""

    min_block_cells: int = 1


@dataclass(frozen=True)
class RunConfig:
    """The whole run's configuration; every section has defaults, so an empty YAML file is valid."""

    mapping: Path | None = None  # YAML topic-role mapping for custom topics (see holoslam.io.mcap)
    vision: VisionConfig = field(default_factory=VisionConfig)
    frontend: FrontEndConfig = field(default_factory=FrontEndConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    grid: GridConfig = field(default_factory=GridConfig)
    topology: TopologyConfig = field(default_factory=TopologyConfig)
    holographic: HolographicConfig = field(default_factory=HolographicConfig)
    planning: PlanningConfig = field(default_factory=PlanningConfig)
    pictures: bool = True
    results_mcap: bool = True


def load_run_config(path: str | Path | None) -> RunConfig:
    """The run configuration from a YAML file (safe loader), or the defaults when ``path`` is None."""
    if path is None:
        return RunConfig()
    cfg = load_yaml_config(RunConfig, path)
    if cfg.mapping is not None and not cfg.mapping.is_absolute():
        cfg = dataclasses.replace(cfg, mapping=Path(path).parent / cfg.mapping)
    return cfg


# ------------------------------------------------------------------------------------------- dump


def _field_comments(cls: type) -> dict[str, str]:
    """The source comments of a dataclass's fields: a trailing ``# ...`` on the field's line, else the
    ``#`` lines right above it. Empty when the source is not available (a frozen build)."""
    import inspect
    import re

    try:
        lines = inspect.getsource(cls).splitlines()
    except (OSError, TypeError):
        return {}
    names = {f.name for f in dataclasses.fields(cls)}
    out: dict[str, str] = {}
    above: list[str] = []
    for line in lines:
        s = line.strip()
        if s.startswith("#"):
            above.append(s.lstrip("#").strip())
            continue
        m = re.match(r"(\w+)\s*:", s)
        if m and m.group(1) in names:
            trailing = s.split("  # ", 1)[1].strip() if "  # " in s else ""
            out[m.group(1)] = trailing or " ".join(above)
        above = []
    return out


def _yaml_scalar(value: Any) -> str:
    import yaml

    text = yaml.safe_dump([value], default_flow_style=True, width=10_000).strip()
    return text[1:-1]  # "[x]" -> "x"


def _dump_lines(obj: Any, indent: int) -> list[str]:
    pad = "  " * indent
    out: list[str] = []
    doc = " ".join((type(obj).__doc__ or "").split())
    if doc and not doc.startswith(type(obj).__name__ + "("):  # dataclasses without a docstring get a signature
        import textwrap

        out.extend(f"{pad}# {line}" for line in textwrap.wrap(doc, max(60, 108 - len(pad))))
    comments = _field_comments(type(obj))
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        note = comments.get(f.name, "")
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            if note:
                out.append(f"{pad}# {note}")
            out.append(f"{pad}{f.name}:")
            out.extend(_dump_lines(value, indent + 1))
        else:
            line = f"{pad}{f.name}: {_yaml_scalar(to_mapping(value))}"
            out.append(f"{line}  # {note}" if note else line)
    return out


def dump_run_config(config: RunConfig | None = None) -> str:
    """Every setting of a run as YAML (the defaults, or ``config``), each section with its docstring and each
    setting with its source comment (unit, why its default). ``load_run_config`` reads it back to the same
    configuration."""
    cfg = config if config is not None else RunConfig()
    head = [
        "# holoslam run configuration: every setting (`holoslam config --dump`). Pass a copy, edited or cut",
        "# down to the settings you change, as `holoslam run --config FILE`; a missing setting keeps its default.",
    ]
    return "\n".join(head + _dump_lines(cfg, 0)) + "\n"
