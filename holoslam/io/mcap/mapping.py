"""A YAML topic mapping: which role a topic plays, custom fields and units, and the frames it names
(``frames: {base: NAME, static: [...]}``). See the package docstring for the format."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from holoslam.errors import ConfigError
from holoslam.types import (
    Role,
    Transform,
)

_ROLE_NAMES = {r.value: r for r in Role}
_RULE_FIELDS: dict[Role, frozenset[str]] = {
    Role.HEADING: frozenset({"yaw", "sigma", "stamp", "frame_id"}),
    Role.ODOMETRY: frozenset({"x", "y", "yaw", "stamp", "frame_id"}),
    Role.GROUND_TRUTH: frozenset({"x", "y", "yaw", "stamp", "frame_id"}),
    Role.SCAN: frozenset(
        {"ranges", "angle_min", "angle_increment", "range_min", "range_max", "stamp", "frame_id"}
    ),
}
_ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}
_LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
_UNIT_KIND = {
    "yaw": _ANGLE_UNITS,
    "sigma": _ANGLE_UNITS,
    "angle_min": _ANGLE_UNITS,
    "angle_increment": _ANGLE_UNITS,
    "x": _LENGTH_UNITS,
    "y": _LENGTH_UNITS,
    "ranges": _LENGTH_UNITS,
    "range_min": _LENGTH_UNITS,
    "range_max": _LENGTH_UNITS,
}


@dataclass(frozen=True, slots=True)
class TopicRule:
    """One topic entry of a mapping: its role, custom field paths and units, and its line in the file."""

    topic: str
    role: Role
    fields: tuple[tuple[str, str], ...] = ()
    units: tuple[tuple[str, str], ...] = ()
    line: int = 0


@dataclass(frozen=True, slots=True)
class LogMapping:
    """A validated topic mapping (see the module docstring); ``source`` names the file for messages."""

    rules: tuple[TopicRule, ...]
    source: str = "<mapping>"
    base_frame: str | None = None  # ``frames: {base: NAME}``; None: the odometry's child frame
    # ``frames: {static: [...]}``: static transforms that replace the log's for the same child frame
    static_transforms: tuple[Transform, ...] = ()

    def get(self, topic: str) -> TopicRule | None:
        for r in self.rules:
            if r.topic == topic:
                return r
        return None


def _read_text(source: str | Path) -> tuple[str, str]:
    """(name for messages, YAML text) of a mapping given as a file path or as YAML text."""
    text = str(source)
    if not (isinstance(source, Path) or (("\n" not in text) and (text.endswith((".yaml", ".yml"))))):
        return "<mapping>", text
    p = Path(source)
    if not p.is_file():
        raise ConfigError(f"mapping file {p} does not exist; pass the path of a YAML topic mapping")
    try:
        return str(p), p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"mapping file {p} is not UTF-8 text (byte {exc.start}); pass the YAML topic mapping"
        ) from None
    except OSError as exc:
        raise ConfigError(f"cannot read mapping file {p}: {exc.strerror or exc}; check the path") from None


def _parse_yaml(name: str, text: str) -> tuple[Any, dict[str, int]]:
    """The YAML data and the line of each topic under ``topics:`` (for messages)."""
    import yaml

    lines: dict[str, int] = {}
    try:
        data = yaml.safe_load(text)
        root = yaml.compose(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{name}: not valid YAML: {exc}") from exc
    if isinstance(root, yaml.MappingNode):
        for k, v in root.value:
            if k.value == "topics" and isinstance(v, yaml.MappingNode):
                for tk, _ in v.value:
                    lines[str(tk.value)] = tk.start_mark.line + 1
    return data, lines


def load_mapping(source: str | Path | dict | LogMapping | None) -> LogMapping | None:
    """Parse and validate a mapping from a YAML file path, YAML text, or an already loaded dict.

    Raises ConfigError naming the line and the accepted values for anything it does not understand.
    """
    if source is None or isinstance(source, LogMapping):
        return source
    lines: dict[str, int] = {}
    name = "<mapping>"
    if isinstance(source, dict):
        data: Any = source
    else:
        name, text = _read_text(source)
        data, lines = _parse_yaml(name, text)
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(
            f"{name}: a mapping is a YAML dictionary with a 'topics:' key, got {type(data).__name__}"
        )
    extra = set(data) - {"topics", "frames"}
    if extra:
        raise ConfigError(
            f"{name}: unknown key(s) {sorted(map(str, extra))}; the top-level keys are 'topics' and 'frames'"
        )
    base_frame, static = _mapping_frames(name, data.get("frames"))
    topics = data.get("topics") or {}
    if not isinstance(topics, dict):
        raise ConfigError(f"{name}: 'topics' must map topic names to a role or to {{role, fields, units}}")
    rules = [
        _topic_rule(
            f"{name} line {lines.get(str(topic), '?')} (topic {topic})", topic, spec, lines.get(topic, 0)
        )
        for topic, spec in topics.items()
    ]
    return LogMapping(tuple(rules), name, base_frame, static)


def _topic_rule(where: str, topic: Any, spec: Any, line: int) -> TopicRule:
    """One ``topics:`` entry, validated: a role name, or {role, fields, units}."""
    if not isinstance(topic, str) or not topic:
        raise ConfigError(f"{where}: topic names must be non-empty strings")
    if isinstance(spec, str):
        spec = {"role": spec}
    if not isinstance(spec, dict):
        raise ConfigError(f"{where}: give a role name or a dictionary with role/fields/units")
    bad = set(spec) - {"role", "fields", "units"}
    if bad:
        raise ConfigError(f"{where}: unknown key(s) {sorted(map(str, bad))}; allowed: role, fields, units")
    role = _ROLE_NAMES.get(str(spec.get("role", "")).strip().lower())
    if role is None:
        roles_txt = ", ".join(sorted(_ROLE_NAMES))
        raise ConfigError(f"{where}: role {spec.get('role')!r} is not one of: {roles_txt}")
    fields = spec.get("fields") or {}
    units = spec.get("units") or {}
    if not isinstance(fields, dict) or not isinstance(units, dict):
        raise ConfigError(f"{where}: 'fields' and 'units' must be dictionaries")
    allowed = _RULE_FIELDS.get(role, frozenset())
    for k, v in fields.items():
        if k not in allowed:
            raise ConfigError(
                f"{where}: field {k!r} is not used by role {role.value}; allowed: {sorted(allowed) or 'none'}"
            )
        if not isinstance(v, str) or not re.fullmatch(
            r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*", v
        ):
            raise ConfigError(f"{where}: field path {v!r} must be a dotted name like header.stamp")
    for k, u in units.items():
        table = _UNIT_KIND.get(k)
        if table is None or not isinstance(u, str) or u not in table:
            ok = f"one of {sorted(table)}" if table else "not a field with units"
            raise ConfigError(f"{where}: unit {u!r} for {k!r}: {ok}")
    return TopicRule(
        topic=topic,
        role=role,
        fields=tuple(sorted((str(k), str(v)) for k, v in fields.items())),
        units=tuple(sorted((str(k), str(v)) for k, v in units.items())),
        line=line,
    )


def _mapping_frames(name: str, frames: Any) -> tuple[str | None, tuple[Transform, ...]]:
    """The ``frames:`` section of a mapping -> (the base frame it names or None, its static transforms)."""
    if frames is None:
        return None, ()
    if not isinstance(frames, dict):
        raise ConfigError(
            f"{name}: 'frames' must map 'base' to a frame name, e.g. 'frames: {{base: base_footprint}}'"
        )
    bad = set(frames) - {"base", "static"}
    if bad:
        raise ConfigError(
            f"{name}: unknown key(s) {sorted(map(str, bad))} under 'frames'; allowed: base, static"
        )
    static = _static_transforms(name, frames.get("static"))
    base = frames.get("base")
    if base is None:
        return None, static
    if not isinstance(base, str) or not base.strip("/ "):
        raise ConfigError(f"{name}: frames.base must be a frame name (like base_footprint), got {base!r}")
    return base.strip().lstrip("/"), static


_STATIC_EXAMPLE = "e.g. 'frames: {static: [{parent: base_link, child: laser, xyz: [0.2, 0, 0.3], rpy_deg: [0, 0, 0]}]}'"


def _numbers(where: str, value: Any, unit: str) -> tuple[float, float, float]:
    if (not isinstance(value, (list, tuple)) or len(value) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)):
        raise ConfigError(f"{where} must be three finite numbers in {unit}, got {value!r}; {_STATIC_EXAMPLE}")
    return float(value[0]), float(value[1]), float(value[2])


def _static_transforms(name: str, items: Any) -> tuple[Transform, ...]:
    """``frames.static``: a list of ``{parent, child, xyz (m), rpy_deg (deg, optional)}``, the arguments of ROS's
    ``static_transform_publisher``; each replaces what the log's /tf_static says about its child frame."""
    if items is None:
        return ()
    if not isinstance(items, list):
        raise ConfigError(f"{name}: frames.static must be a list of transforms; {_STATIC_EXAMPLE}")
    out: list[Transform] = []
    for i, item in enumerate(items):
        where = f"{name}: frames.static[{i}]"
        if not isinstance(item, dict) or set(item) - {"parent", "child", "xyz", "rpy_deg"}:
            raise ConfigError(f"{where} must hold parent, child, xyz and optionally rpy_deg; {_STATIC_EXAMPLE}")
        parent, child = (str(item.get(k) or "").strip().lstrip("/") for k in ("parent", "child"))
        if not parent or not child or parent == child:
            raise ConfigError(f"{where} needs two different frame names 'parent' and 'child'; {_STATIC_EXAMPLE}")
        if any(t.child == child for t in out):
            raise ConfigError(f"{where}: frame {child!r} is already a child in frames.static (a frame has one parent)")
        xyz = _numbers(f"{where}.xyz", item.get("xyz"), "metres")
        roll, pitch, yaw = (math.radians(v) for v in _numbers(f"{where}.rpy_deg", item.get("rpy_deg", [0, 0, 0]),
                                                             "degrees"))
        out.append(Transform(0, parent, child, xyz, _quaternion_rpy(roll, pitch, yaw), static=True))
    return tuple(out)


def _quaternion_rpy(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of the fixed-axis roll-pitch-yaw rotation Rz(yaw) Ry(pitch) Rx(roll), as ROS's tf2."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)
