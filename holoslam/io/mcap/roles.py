"""Channels and roles: what each topic of a log is (``ChannelInfo``), its role from its schema or the
mapping, and the rules that choose one topic when several could fill a role (``RoleChoice``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from holoslam.errors import IngestError
from holoslam.io.mcap.container import _OP_CHANNEL, _OP_SCHEMA, _check_magic, _FileState, _iter_file
from holoslam.io.mcap.mapping import LogMapping, TopicRule
from holoslam.types import (
    Role,
)

# Of several topics for one role, those with at least this fraction of the most messages are "complete" (a
# compressed stream that dropped a few frames is as complete as its raw twin); the rest are not used.
COMPLETE_FRACTION = 0.9
RUN_ROLES = (Role.ODOMETRY, Role.SCAN)  # what a SLAM run needs at least

EXCLUSIVE_ROLES = frozenset(
    {
        Role.ODOMETRY,
        Role.HEADING,
        Role.SCAN,
        Role.IMAGE,
        Role.CAMERA_INFO,
        Role.TAGS,
        Role.GROUND_TRUTH,
        Role.GROUND_TRUTH_WORLD,
    }
)

ROLE_BY_SCHEMA: dict[str, Role] = {
    "nav_msgs/Odometry": Role.ODOMETRY,
    "foxglove.Odometry": Role.ODOMETRY,
    "sensor_msgs/Imu": Role.HEADING,
    "sensor_msgs/MagneticField": Role.HEADING,
    "sensor_msgs/LaserScan": Role.SCAN,
    "foxglove.LaserScan": Role.SCAN,
    "sensor_msgs/CompressedImage": Role.IMAGE,
    "sensor_msgs/Image": Role.IMAGE,
    "foxglove.CompressedImage": Role.IMAGE,
    "foxglove.RawImage": Role.IMAGE,
    "sensor_msgs/CameraInfo": Role.CAMERA_INFO,
    "foxglove.CameraCalibration": Role.CAMERA_INFO,
    "tf2_msgs/TFMessage": Role.TF,
    "tf/tfMessage": Role.TF,
    "foxglove.FrameTransform": Role.TF,
    "foxglove.FrameTransforms": Role.TF,
    "holoslam_msgs/TagDetectionArray": Role.TAGS,
}
_POSE_SCHEMAS = frozenset(
    {"geometry_msgs/PoseStamped", "geometry_msgs/PoseWithCovarianceStamped", "foxglove.PoseInFrame"}
)


def normalize_schema_name(name: str) -> str:
    """``pkg/msg/Type`` and ``pkg/Type`` -> ``pkg/Type``; Foxglove names (``foxglove.X``) unchanged."""
    parts = name.strip().split("/")
    if len(parts) == 3 and parts[1] in ("msg", "srv", "action"):
        return f"{parts[0]}/{parts[2]}"
    return name.strip()


def _is_service_event(topic: str, schema_name: str) -> bool:
    return topic.endswith("/_service_event") or ("/srv/" in schema_name and schema_name.endswith("_Event"))


@dataclass(frozen=True, slots=True)
class ChannelInfo:
    """One topic of a log (channels of the same topic merged): what it is and what holoslam does with it."""

    topic: str
    schema: str
    schema_encoding: str
    message_encoding: str
    message_count: int
    rate_hz: float
    role: str | None  # a Role value, or None when unused
    status: str  # "used", "unused: <why>", "undecodable: <why>", "service event", "ambiguous: ..."
    channel_ids: tuple[int, ...] = ()


def _decoder_problem(schema: Any, channel: Any) -> str | None:
    """Why a channel cannot be decoded (None when it can)."""
    enc = channel.message_encoding
    if schema is None or (schema.encoding == "" and enc not in ("json",)):
        if enc == "json":
            return None
        return (
            f"no schema (schema id {channel.schema_id}); a {enc or '?'} message cannot be decoded without one"
        )
    if enc == "cdr":
        if schema.encoding != "ros2msg":
            return f"schema encoding '{schema.encoding}' (only ros2msg definitions are read for CDR)"
        if not schema.data:
            return "empty schema: the ros2msg definition is missing from the file"
        return None
    if enc == "protobuf":
        return (
            None
            if schema.encoding == "protobuf" and schema.data
            else "protobuf channel without a FileDescriptorSet"
        )
    if enc == "json":
        return None
    if enc == "ros1":
        return "ROS 1 messages are not decoded; convert the bag to ROS 2 first (`rosbags-convert`)"
    return f"unknown message encoding '{enc}' (holoslam decodes cdr, protobuf and json)"


def _default_role(topic: str, schema_name: str) -> Role | None:
    n = normalize_schema_name(schema_name)
    gt = "ground_truth" in topic
    if n == "std_msgs/String" and topic.rstrip("/").endswith("ground_truth/world"):
        return Role.GROUND_TRUTH_WORLD
    if n in _POSE_SCHEMAS or n in ("nav_msgs/Odometry", "foxglove.Odometry"):
        if gt:
            return Role.GROUND_TRUTH
        if n in ("nav_msgs/Odometry", "foxglove.Odometry") or "odom" in topic:
            return Role.ODOMETRY
        return None
    role = ROLE_BY_SCHEMA.get(n)
    if role is Role.TF and topic.rstrip("/").endswith("tf_static"):
        return Role.TF_STATIC
    return role


@dataclass
class _Topic:
    topic: str
    schema: Any
    channels: list = field(default_factory=list)  # (file index, channel)
    role: Role | None = None
    status: str = ""
    problem: str | None = None
    rule: TopicRule | None = None
    count: int = 0
    first_ns: int | None = None
    last_ns: int | None = None


def _scan_channels(files: list[Path]) -> tuple[dict[str, _Topic], bool, int, int, list[str]]:
    """Channels of every file (from the summary when present, else by streaming the file). Returns
    (topics, indexed, start_ns, end_ns, notes)."""
    from mcap.reader import make_reader

    topics: dict[str, _Topic] = {}
    indexed = True
    start = end = None
    notes: list[str] = []
    for fi, path in enumerate(files):
        summary = None
        with open(path, "rb") as f:
            _check_magic(path, f.read(16))
            f.seek(0)
            try:
                summary = make_reader(f).get_summary()
            except Exception:
                summary = None
        if summary is not None and summary.statistics is not None:
            counts = summary.statistics.channel_message_counts
            for cid, ch in sorted(summary.channels.items()):
                sc = summary.schemas.get(ch.schema_id)
                t = topics.setdefault(ch.topic, _Topic(ch.topic, sc))
                t.channels.append((fi, ch))
                t.count += counts.get(cid, 0)
            if summary.statistics.message_count:
                s0, s1 = summary.statistics.message_start_time, summary.statistics.message_end_time
                start = s0 if start is None else min(start, s0)
                end = s1 if end is None else max(end, s1)
            # per-topic time range is not in the summary: rates use the file's duration
            for t in topics.values():
                if t.first_ns is None:
                    t.first_ns, t.last_ns = (
                        summary.statistics.message_start_time,
                        summary.statistics.message_end_time,
                    )
            continue
        indexed = False
        st = _FileState(path)
        schemas: dict[int, Any] = {}
        chan: dict[int, Any] = {}
        for op, rec in _iter_file(st, messages=True):
            if op == _OP_SCHEMA:
                schemas[rec.id] = rec
            elif op == _OP_CHANNEL:
                chan[rec.id] = rec
                t = topics.setdefault(rec.topic, _Topic(rec.topic, schemas.get(rec.schema_id)))
                if all(c.id != rec.id or i != fi for i, c in t.channels):
                    t.channels.append((fi, rec))
            else:
                cid, lt, _ = rec
                known = chan.get(cid)
                if known is None:
                    continue
                t = topics[known.topic]
                t.count += 1
                t.first_ns = lt if t.first_ns is None else min(t.first_ns, lt)
                t.last_ns = lt if t.last_ns is None else max(t.last_ns, lt)
                start = lt if start is None else min(start, lt)
                end = lt if end is None else max(end, lt)
        notes.append(
            f"{path.name}: no summary section (unindexed or unfinished file); counted by a full read"
        )
        notes.extend(f"{path.name}: {n}" for n in st.notes)
        notes.extend(f"{path.name}: lost {lr.reason}" for lr in st.lost)
    return topics, indexed, start or 0, end or 0, notes


def _assign_roles(
    topics: dict[str, _Topic], mapping: LogMapping | None
) -> tuple[list[RoleChoice], list[str]]:
    """Give each topic its role and status; return the choices made among topics of one role and the problems
    (a role a run needs offered by topics no rule tells apart)."""
    if mapping is not None:
        for rule in mapping.rules:
            if rule.topic not in topics:
                raise IngestError(
                    f"{mapping.source} line {rule.line or '?'}: topic '{rule.topic}' is not in the log; its topics "
                    f"are: {', '.join(sorted(topics)) or 'none'}. Fix the topic name or delete the line."
                )
    for t in topics.values():
        schema_name = t.schema.name if t.schema is not None else ""
        ch = t.channels[0][1]
        t.rule = mapping.get(t.topic) if mapping else None
        if _is_service_event(t.topic, schema_name):
            t.role, t.status = (
                None,
                "skipped: service event (request/response introspection, not sensor data)",
            )
            continue
        t.problem = _decoder_problem(t.schema, ch)
        if t.rule is not None:
            t.role = None if t.rule.role is Role.IGNORED else t.rule.role
        else:
            t.role = _default_role(t.topic, schema_name)
        if t.problem:
            t.status = f"undecodable: {t.problem}"
        elif t.role is None:
            t.status = (
                "ignored by the mapping" if t.rule else "skipped: no role for this type (add it to a mapping)"
            )
        else:
            t.status = "used"
    choices, problems = _choose_roles(topics)
    return choices, problems


@dataclass(frozen=True, slots=True)
class RoleChoice:
    """Several topics could fill one role: the one used, the others left unused, and the rule that decided."""

    role: str
    topic: str
    others: tuple[str, ...]
    rule: str

    def text(self) -> str:
        return (
            f"{self.role}: {self.topic} used, not {', '.join(self.others)} ({self.rule}); the mapping line "
            f"'{self.others[0]}: {self.role}' chooses another"
        )


_ODOMETRY_TYPES = frozenset({"nav_msgs/Odometry", "foxglove.Odometry"})
_COMPRESSED_TYPES = frozenset({"sensor_msgs/CompressedImage", "foxglove.CompressedImage"})


def _schema_of(t: _Topic) -> str:
    return normalize_schema_name(t.schema.name) if t.schema is not None else ""


def _filtered(role: Role, t: _Topic) -> int:
    return int("filter" in t.topic.lower())


def _raw_image(role: Role, t: _Topic) -> int:
    return int(role is Role.IMAGE and _schema_of(t) not in _COMPRESSED_TYPES)


def _depth(role: Role, t: _Topic) -> int:
    return int(role in (Role.IMAGE, Role.CAMERA_INFO) and "depth" in t.topic.lower())


def _poorer_pose(role: Role, t: _Topic) -> int:
    n = _schema_of(t)
    if role not in (Role.ODOMETRY, Role.GROUND_TRUTH) or n in _ODOMETRY_TYPES:
        return 0
    return 1 if "Covariance" in n else 2


# The rules that pick one topic when several could fill a role, in order: each keeps the candidates with the
# lowest key and the next rule decides among those. (name, key(role, topic), why)
_ROLE_RULES: tuple[tuple[str, Callable[[Role, _Topic], int], str], ...] = (
    (
        "unfiltered",
        _filtered,
        "the unfiltered topic, as holoslam filters and fuses itself: a filtered scan has lost beams, filtered "
        "odometry has fused the IMU already",
    ),
    (
        "compressed",
        _raw_image,
        "the compressed image beside a raw one: the same camera in a fraction of the memory",
    ),
    ("colour", _depth, "a colour camera rather than a depth camera"),
    ("richer", _poorer_pose, "the richer message type (odometry with covariance and twist)"),
)


def _pick(role: Role, candidates: list[_Topic]) -> tuple[list[_Topic], str]:
    """The candidates left after the rules (one when a rule decided) and the reasons of the rules that acted."""
    most = max(t.count for t in candidates)
    keep = [t for t in candidates if t.count >= COMPLETE_FRACTION * most]
    why = []
    if len(keep) < len(candidates):
        why.append(
            f"the most complete: {most} messages against {max(t.count for t in candidates if t not in keep)}"
        )
    for _name, key, reason in _ROLE_RULES:
        if len(keep) == 1:
            break
        best = min(key(role, t) for t in keep)
        kept = [t for t in keep if key(role, t) == best]
        if len(kept) < len(keep):
            why.append(reason)
        keep = kept
    if len(keep) > 1:
        top = max(t.count for t in keep)
        kept = [t for t in keep if t.count == top]
        if len(kept) < len(keep):
            why.append(f"the most messages ({top})")
        keep = kept
    return sorted(keep, key=lambda t: t.topic), "; ".join(why)


def _choose_roles(topics: dict[str, _Topic]) -> tuple[list[RoleChoice], list[str]]:
    """One topic per exclusive role. Topics the mapping names for a role come first; among several candidates
    ``_pick``'s rules decide. When no rule decides, an optional role takes the first topic by name (reported);
    a role a SLAM run needs (odometry, scan) is a problem naming the mapping line that fixes it."""
    by_role: dict[Role, list[_Topic]] = {}
    for t in topics.values():
        if t.role in EXCLUSIVE_ROLES and t.status == "used":
            by_role.setdefault(t.role, []).append(t)
    choices: list[RoleChoice] = []
    problems: list[str] = []
    for role, ts in by_role.items():
        if len(ts) < 2:
            continue
        named = [t for t in ts if t.rule is not None]
        pool = named or ts
        keep, why = _pick(role, pool) if len(pool) > 1 else (pool, "")
        if named and len(named) < len(ts):
            why = "; ".join(x for x in ("named in the mapping", why) if x)
        if len(keep) > 1:
            if role in RUN_ROLES:
                names = " and ".join(f"'{t.topic}' ({t.schema.name if t.schema else '?'})" for t in keep)
                fix = "; ".join(f"'  {t.topic}: ignored'" for t in keep[1:])
                problems.append(
                    f"two topics could fill the {role.value} role and no rule tells them apart: {names}. Keep one: "
                    f"add under 'topics:' of a mapping file the line {fix}"
                )
                for t in keep:
                    t.status = f"ambiguous: {role.value} is also offered by another topic"
                continue
            why = "; ".join(x for x in (why, "no rule tells the rest apart: the first by name") if x)
        chosen = keep[0]
        others = tuple(sorted(t.topic for t in ts if t is not chosen))
        for t in ts:
            if t is not chosen:
                t.status = f"unused: the {role.value} role comes from {chosen.topic}"
        choices.append(RoleChoice(role.value, chosen.topic, others, why))
    choices.sort(key=lambda c: c.role)
    return choices, problems


def _choice_dict(c: RoleChoice) -> dict[str, Any]:
    return {"role": c.role, "topic": c.topic, "others": list(c.others), "rule": c.rule}
