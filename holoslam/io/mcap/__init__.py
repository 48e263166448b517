"""Read robot logs (MCAP files and rosbag2 directories of MCAP files) into holoslam records.

Public API
----------
- ``iter_records(path, mapping=None)``: stream ``(topic, record)`` pairs; memory is bounded by one chunk.
- ``read_log(path, mapping=None, progress=None, require=())``: every record grouped in a ``LogData`` plus the
  ``IngestReport`` (always produced).
- ``inspect_log(path)``: a ``LogSummary`` (channels, counts, rates, roles, time range, indexed or not, what a
  run would use) read from the summary section alone when the file has one.
- ``format_summary`` / ``summary_to_dict`` / ``format_report`` / ``report_to_dict``: pure renderers.
- ``LogReader``: the streaming reader behind ``iter_records``; ``.report()`` after iterating.
- ``load_mapping``: parse and validate a YAML topic mapping (see below).

Roles
-----
A channel's role comes from its schema name (ROS 2 ``pkg/msg/Type``, ROS 1 ``pkg/Type``, Foxglove
``foxglove.Type`` in protobuf or JSON), see ``ROLE_BY_SCHEMA``; ``PoseStamped``-like poses are ground truth on
topics containing ``ground_truth`` and odometry on topics containing ``odom``. A YAML mapping overrides it::

    frames:
      base: base_footprint            # the robot's base frame (default: the odometry's child frame)
      static:                         # static transforms (static_transform_publisher's arguments) that
        - {parent: base_link, child: laser, xyz: [0.2, 0, 0.3], rpy_deg: [0, 0, 0]}  # replace the log's
    topics:
      /wheel/odom: ignored            # a role name: odometry heading scan image camera_info tf tf_static tags
      /odom_fused: odometry           #   ground_truth ground_truth_world ignored
      /compass_deg:                   # a custom type: name the fields (dotted paths) and their units
        role: heading
        fields: {yaw: heading, sigma: accuracy, stamp: header.stamp}
        units: {yaw: deg, sigma: deg}

Custom fields: heading ``yaw sigma``; odometry / ground_truth ``x y yaw``; scan ``ranges angle_min
angle_increment range_min range_max``; every role ``stamp frame_id``. Units: angles ``rad``/``deg``, lengths
``m``/``cm``/``mm``.

Frames
------
The robot's base frame is the mapping's ``frames: {base: NAME}``, else the odometry's child frame (``base_link``
when no odometry names one); ``LogData.base_frame`` and ``IngestReport.base_frame`` carry it. A mapping's
``frames.static`` entries (xyz in metres, rpy_deg in degrees, fixed axes as tf2) replace every transform the
log holds for the same child frame, or supply one it lacks; each replacement is a note in
``IngestReport.warnings`` with what the log had. A laser whose z
axis points down in the base frame (mounted upside down) has its scans mirrored into a level frame
``<laser>_level`` (``level_scans``): ``read_log`` does it, with a note in ``IngestReport.levelled``.

Several topics for one role
---------------------------
When several topics could fill one role (odometry, heading, scan, image, camera_info, tags, ground_truth,
ground_truth_world), topics the mapping names for it come first, then rules pick one (``_ROLE_RULES``): the most
complete (``COMPLETE_FRACTION`` of the most messages), the unfiltered topic, the compressed image beside a raw
one, a colour camera over a depth camera, odometry over a bare pose, the most messages. The choice is a
``RoleChoice`` in the report and the summary. When no rule tells them apart an optional role takes the first by
name (reported); odometry and scan (what a run needs) stop with an IngestError naming the mapping line that fixes
it.

Time
----
Records carry the header stamp (sensor time). A zero stamp means "not set" and the log time is used. For each
channel the median of (log time - stamp) over its first 8 messages is measured; when it exceeds
``CLOCK_THRESHOLD_NS`` (1 s) the channel's stamps are on another clock (e.g. a simulator clock starting at 0)
and the whole channel is re-based by that offset, snapped to the offset of an already re-based channel when
within the threshold (channels on one clock stay mutually synchronised). ``/tf_static`` is never re-based:
static transforms hold for the whole log whatever their stamp. Each re-basing is listed in the report.

Headings
--------
``sensor_msgs/Imu``: the yaw of the orientation quaternion (messages whose orientation_covariance[0] is -1,
"no orientation", are counted as skipped), sigma = sqrt(orientation_covariance[8]) or NaN when zero.
``sensor_msgs/MagneticField``: the sensor is taken level with REP-103 axes (x forward, y left, z up) and the
heading is the yaw of x from magnetic north, counter-clockwise: ``yaw = -atan2(m_y, m_x)``.

Damaged files
-------------
Chunk CRCs are validated (CRC-32 of the decompressed records, always). A chunk that fails CRC or does not
decompress is dropped and its time range reported; reading continues with the next record (or, when a
corrupt length desynchronises the stream, at the next chunk listed in the summary's chunk index). A file
that ends early (recorder crash) keeps every complete chunk and reports the truncation and the lost range.

Layout
------
``mapping`` (the YAML mapping), ``container`` (files, records, chunks, CRCs, salvage), ``roles`` (channels, roles,
the rules among several topics), ``summary`` (``inspect_log``), ``convert`` (message -> records, one converter
per role), ``report`` (the ingest report), ``levelling`` (upside-down lasers), ``reader`` (``LogReader``,
``iter_records``, ``read_log``). Every public name is importable from ``holoslam.io.mcap``.
"""

from __future__ import annotations

from holoslam.io.mcap.container import MCAP_MAGIC, LostRange
from holoslam.io.mcap.convert import MOSTLY_INVALID, rotate_cov_xy
from holoslam.io.mcap.levelling import LEVEL_SUFFIX, TILT_WARN_DEG, level_scans, mirrored_scan
from holoslam.io.mcap.mapping import LogMapping, TopicRule, load_mapping
from holoslam.io.mcap.reader import CLOCK_THRESHOLD_NS, CLOCK_WINDOW, LogReader, iter_records, read_log
from holoslam.io.mcap.report import GAP_FACTOR, ChannelReport, IngestReport, format_report, report_to_dict
from holoslam.io.mcap.roles import (
    COMPLETE_FRACTION,
    EXCLUSIVE_ROLES,
    ROLE_BY_SCHEMA,
    RUN_ROLES,
    ChannelInfo,
    RoleChoice,
    normalize_schema_name,
)
from holoslam.io.mcap.summary import LogSummary, format_summary, inspect_log, summary_to_dict

__all__ = [
    "iter_records",
    "read_log",
    "inspect_log",
    "LogReader",
    "LogMapping",
    "TopicRule",
    "load_mapping",
    "ChannelInfo",
    "LogSummary",
    "ChannelReport",
    "LostRange",
    "IngestReport",
    "format_summary",
    "summary_to_dict",
    "format_report",
    "report_to_dict",
    "normalize_schema_name",
    "ROLE_BY_SCHEMA",
    "EXCLUSIVE_ROLES",
    "CLOCK_THRESHOLD_NS",
    "COMPLETE_FRACTION",
    "RoleChoice",
    "level_scans",
    "mirrored_scan",
    "rotate_cov_xy",
    "RUN_ROLES",
    "MCAP_MAGIC",
    "CLOCK_WINDOW",
    "GAP_FACTOR",
    "MOSTLY_INVALID",
    "LEVEL_SUFFIX",
    "TILT_WARN_DEG",
]
