"""The holoslam QR label payload: a compact text carrying an object's id, type and handling attributes
(the object information of Eq. 13, seed 002).

Format (ASCII, at most 64 characters so that a version-3/4 QR code holds it at error-correction level M)::

    HL1;<id>;<type>[;<key>=<value>,<key>=<value>...]

    HL1;O07;cup;g=handle,m=0.3,f=1

- ``HL1``   magic and format version.
- ``id``    unique object id: 1-16 of ``A-Z 0-9 -``.
- ``type``  object type: 1-24 of ``a-z 0-9 _`` (``cup``, ``air_conditioner``).
- attributes: optional comma-separated ``key=value`` pairs; keys 1-8 of ``a-z``, values 0-16 of
  ``A-Z a-z 0-9 . _ -``. Documented keys: ``g`` grasp (``handle``, ``top``, ``side``, ``none``),
  ``m`` mass in kg, ``f`` fragile (0/1), ``s`` printed side of the QR code (outer corners of the finder
  patterns, quiet zone excluded) in millimetres, which single-view localisation (PnP) needs.

Payloads are untrusted text: they are matched against this grammar and never evaluated. A text that is not
a holoslam label raises ``PayloadError`` saying why; callers report such codes as foreign, never guess.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from holoslam.errors import PayloadError

__all__ = [
    "ObjectLabel",
    "encode_label",
    "parse_label",
    "is_label",
    "foreign_code_id",
    "FOREIGN_PREFIX",
    "MAGIC",
    "MAX_PAYLOAD_CHARS",
]

MAGIC = "HL1"
FOREIGN_PREFIX = "QR-"
MAX_PAYLOAD_CHARS = 64
_ID = re.compile(r"[A-Z0-9-]{1,16}")
_TYPE = re.compile(r"[a-z0-9_]{1,24}")
_KEY = re.compile(r"[a-z]{1,8}")
_VALUE = re.compile(r"[A-Za-z0-9._-]{0,16}")


@dataclass(frozen=True, slots=True)
class ObjectLabel:
    """The typed content of a label: id, type and attributes as sorted (key, value) pairs."""

    object_id: str
    kind: str
    attributes: tuple[tuple[str, str], ...] = ()

    def attribute(self, key: str, default: str | None = None) -> str | None:
        return dict(self.attributes).get(key, default)

    @property
    def size_m(self) -> float | None:
        """The printed code side in metres from the ``s`` attribute (millimetres), or None."""
        v = self.attribute("s")
        try:
            return float(v) / 1000.0 if v else None
        except ValueError:
            return None


def encode_label(label: ObjectLabel) -> str:
    """The payload text of a label; raises ``PayloadError`` if a field breaks the grammar."""
    if not _ID.fullmatch(label.object_id):
        raise PayloadError(f"object id {label.object_id!r} must be 1-16 characters of A-Z, 0-9, '-'")
    if not _TYPE.fullmatch(label.kind):
        raise PayloadError(f"object type {label.kind!r} must be 1-24 characters of a-z, 0-9, '_'")
    parts = [MAGIC, label.object_id, label.kind]
    if label.attributes:
        for k, v in label.attributes:
            if not _KEY.fullmatch(k) or not _VALUE.fullmatch(v):
                raise PayloadError(f"attribute {k!r}={v!r}: keys are 1-8 of a-z, values 0-16 of A-Za-z0-9._-")
        parts.append(",".join(f"{k}={v}" for k, v in sorted(label.attributes)))
    text = ";".join(parts)
    if len(text) > MAX_PAYLOAD_CHARS:
        raise PayloadError(
            f"label payload is {len(text)} characters; at most {MAX_PAYLOAD_CHARS} fit a small code"
        )
    return text


def parse_label(text: str) -> ObjectLabel:
    """Parse a payload; raises ``PayloadError`` naming the first field that breaks the grammar."""
    if not isinstance(text, str):
        raise PayloadError(f"payload must be text, got {type(text).__name__}")
    shown = text if len(text) <= 40 else text[:37] + "..."
    if len(text) > MAX_PAYLOAD_CHARS:
        raise PayloadError(f"payload {shown!r} is {len(text)} characters, longer than a holoslam label")
    fields = text.split(";")
    if fields[0] != MAGIC:
        raise PayloadError(f"payload {shown!r} does not start with {MAGIC!r}: not a holoslam label")
    if len(fields) not in (3, 4):
        raise PayloadError(f"payload {shown!r} has {len(fields)} ';'-separated fields; expected 3 or 4")
    object_id, kind = fields[1], fields[2]
    if not _ID.fullmatch(object_id):
        raise PayloadError(f"payload {shown!r}: object id {object_id!r} is not 1-16 of A-Z, 0-9, '-'")
    if not _TYPE.fullmatch(kind):
        raise PayloadError(f"payload {shown!r}: object type {kind!r} is not 1-24 of a-z, 0-9, '_'")
    attrs: list[tuple[str, str]] = []
    if len(fields) == 4 and fields[3]:
        for item in fields[3].split(","):
            k, sep, v = item.partition("=")
            if not sep or not _KEY.fullmatch(k) or not _VALUE.fullmatch(v):
                raise PayloadError(f"payload {shown!r}: attribute {item!r} is not key=value (a-z keys)")
            attrs.append((k, v))
    keys = [k for k, _ in attrs]
    if len(set(keys)) != len(keys):
        raise PayloadError(f"payload {shown!r}: an attribute key is repeated")
    return ObjectLabel(object_id, kind, tuple(sorted(attrs)))


def is_label(text: str) -> bool:
    """True if ``text`` parses as a holoslam label."""
    try:
        parse_label(text)
    except PayloadError:
        return False
    return True


def foreign_code_id(payload: str | bytes) -> str:
    """The id of an anonymous landmark: a QR code that is not a holoslam label, keyed by its payload (the same
    payload always gives the same id): ``QR-`` and the first 10 hex digits of the SHA-256 of its bytes (UTF-8
    for text), upper case, so it fits the label id grammar and cannot be mistaken for a label's id."""
    import hashlib

    data = payload.encode("utf-8") if isinstance(payload, str) else bytes(payload)
    return FOREIGN_PREFIX + hashlib.sha256(data).hexdigest()[:10].upper()
