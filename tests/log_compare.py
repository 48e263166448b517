"""Compare two ROS 2 MCAP logs by decoded content, within tolerances that hold across machines.

A regenerated simulated log is not byte-identical on another machine: numpy's transcendental functions
(SIMD / SVML code paths chosen by the CPU), BLAS kernels and the zstd / mcap library versions all change the
last bits of float values or the compressed bytes. What must not change is the content: the same topics,
schemas, message counts, order, stamps and sequence numbers (exact), the same strings and integers (exact),
and float values equal within a tolerance small against every sensor noise of the simulator.

Tolerances (``compare_logs``), per field (a field is a topic plus a path inside the message, list indices left
out; JSON strings are parsed and their numbers are fields too):

- generic floats: ``|a - b| <= FLOAT_TOL * scale`` with ``scale`` the largest finite magnitude of that field
  over the reference log (metres of the house, unit quaternions, pixels of the image). Measured between two
  machines (AVX-512/SVML vs not): true poses differ by ~2e-13 m, but the odometer's random walk scales its noise
  by sqrt(step length) and sqrt(|turn|), and sqrt turns a 1e-16 difference of a near-zero step into ~1e-8:
  odometry poses differ by up to 4e-9 m, yaw rates by 1e-8 rad/s (1.2e-8 of their scale). FLOAT_TOL = 1e-6
  leaves ~100x headroom over that, and is still 1e-3 of the smallest simulated noise (laser 1 cm over ~8 m,
  compass 1.5 deg, tag corners 0.3 px over 640 px): a changed noise draw, seed, pose or model fails.
  Non-finite values (``inf`` = no laser return) must sit in the same places with the same sign.
- quantised floats, where a last-bit difference before rounding can move the value by one quantum when it sat on
  a rounding boundary: laser ranges (the LMS-200's 1 mm resolution) may differ by one millimetre; the odometry
  pose covariance (printed with two significant digits, as drivers report it) by one unit of its second digit.
- compressed images: decoded pixels, mean absolute difference <= IMAGE_MEAN_TOL grey levels per image. A
  rounding flip of the float rendering changes a pixel by one level and JPEG spreads it over its 8x8 block;
  the simulated camera noise alone is sigma = 2 levels (two noise draws differ by a mean of ~2.3 levels), so
  0.5 is below any change of the scene, pose, exposure or noise draw.
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

FLOAT_TOL = 1e-6  # of the field's largest magnitude in the reference log (see the module docstring)
IMAGE_MEAN_TOL = 0.5  # grey levels, mean absolute difference of the decoded pixels
QUANTUM = {("/scan", ".ranges"): 1e-3}  # one step of the laser's 1 mm range resolution
TWO_DIGITS = {("/odom", ".pose.covariance")}  # values printed with two significant digits


@dataclass
class DecodedLog:
    """Every message of a log in file order: (topic, log_time, publish_time, sequence, decoded message)."""

    messages: list[tuple[str, int, int, int, Any]] = field(default_factory=list)
    schemas: dict[str, tuple[str, str, str]] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    profile: str = ""


def decode_log(path: str | Path) -> DecodedLog:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out = DecodedLog()
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()], validate_crcs=True)
        out.profile = reader.get_header().profile
        for schema, channel, message, ros_msg in reader.iter_decoded_messages(log_time_order=False):
            out.messages.append(
                (channel.topic, message.log_time, message.publish_time, message.sequence, ros_msg)
            )
            out.schemas[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
        out.metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return out


def _leaves(v: Any, path: str):
    """(path, value) leaves of a decoded message; list indices are left out of the path (``[]``), list lengths
    are leaves of their own (``#len``); float lists are one leaf (a tuple); JSON strings are parsed."""
    if hasattr(v, "__slots__") and not isinstance(v, str | bytes):
        for name in v.__slots__:
            yield from _leaves(getattr(v, name), f"{path}.{name}")
    elif isinstance(v, dict):
        yield f"{path}#keys", "|".join(sorted(map(str, v)))
        for k in sorted(v):
            yield from _leaves(v[k], f"{path}.{k}")
    elif isinstance(v, list | tuple):
        yield f"{path}#len", len(v)
        if v and all(isinstance(x, float) for x in v):
            yield path, tuple(v)
        else:
            for x in v:
                yield from _leaves(x, f"{path}[]")
    elif isinstance(v, str) and v[:1] in ("{", "["):
        try:
            parsed = json.loads(v)
        except ValueError:
            yield path, v
        else:
            yield from _leaves(parsed, f"{path}{{json}}")
    else:
        yield path, v


def _two_digit_step(x: np.ndarray) -> np.ndarray:
    """One unit of the second significant digit of each value (0 for zeros)."""
    ax = np.abs(x)
    with np.errstate(divide="ignore"):
        e = np.floor(np.log10(np.where(ax > 0, ax, 1.0)))
    return np.where(ax > 0, 10.0 ** (e - 1), 0.0)


def _image_problem(a: bytes, b: bytes) -> str | None:
    import cv2

    ia = cv2.imdecode(np.frombuffer(bytes(a), np.uint8), cv2.IMREAD_UNCHANGED)
    ib = cv2.imdecode(np.frombuffer(bytes(b), np.uint8), cv2.IMREAD_UNCHANGED)
    if ia is None or ib is None:
        return "an image does not decode"
    if ia.shape != ib.shape:
        return f"image shapes {ia.shape} != {ib.shape}"
    mad = float(np.mean(np.abs(ia.astype(np.int16) - ib.astype(np.int16))))
    if mad > IMAGE_MEAN_TOL:
        return f"decoded pixels differ by {mad:.2f} grey levels on average (> {IMAGE_MEAN_TOL})"
    return None


def compare_logs(ref: DecodedLog, got: DecodedLog, max_problems: int = 20) -> list[str]:
    """What differs between two decoded logs beyond the module's tolerances ([] = the same content)."""
    problems: list[str] = []

    def fail(msg: str) -> bool:
        problems.append(msg)
        return len(problems) >= max_problems

    if ref.profile != got.profile:
        fail(f"profile {ref.profile!r} != {got.profile!r}")
    if ref.schemas != got.schemas:
        fail(f"topics/schemas differ: {ref.schemas} != {got.schemas}")
    if ref.metadata != got.metadata:
        fail(f"metadata differs: {ref.metadata} != {got.metadata}")
    counts_a = defaultdict(int)
    counts_b = defaultdict(int)
    for m in ref.messages:
        counts_a[m[0]] += 1
    for m in got.messages:
        counts_b[m[0]] += 1
    if dict(counts_a) != dict(counts_b):
        fail(f"message counts differ: {dict(counts_a)} != {dict(counts_b)}")
    if ref.schemas != got.schemas or dict(counts_a) != dict(counts_b):
        return problems  # the messages cannot be paired
    # floats gathered per field (topic, path), compared at the end against the field's scale
    cols_a: dict[tuple[str, str], list] = defaultdict(list)
    cols_b: dict[tuple[str, str], list] = defaultdict(list)
    for k, (ma, mb) in enumerate(zip(ref.messages, got.messages, strict=True)):
        topic = ma[0]
        if ma[:4] != mb[:4]:
            if fail(f"message {k}: (topic, log time, publish time, sequence) {ma[:4]} != {mb[:4]}"):
                return problems
            continue
        la, lb = list(_leaves(ma[4], "")), list(_leaves(mb[4], ""))
        if [p for p, _ in la] != [p for p, _ in lb]:
            if fail(f"message {k} on {topic}: different structure"):
                return problems
            continue
        for (path, va), (_, vb) in zip(la, lb, strict=True):
            if isinstance(va, float | tuple) and not isinstance(va, bool):
                if not isinstance(vb, type(va)):
                    bad = f"{type(va).__name__} != {type(vb).__name__}"
                elif isinstance(va, tuple) and len(va) != len(vb):
                    bad = f"{len(va)} != {len(vb)} values"
                else:
                    cols_a[(topic, path)].append(np.atleast_1d(np.asarray(va, dtype=np.float64)))
                    cols_b[(topic, path)].append(np.atleast_1d(np.asarray(vb, dtype=np.float64)))
                    continue
            elif topic == "/camera/image/compressed" and path == ".data":
                bad = _image_problem(va, vb)
            else:
                bad = None if (type(va) is type(vb) and va == vb) else f"{va!r:.80} != {vb!r:.80}"
            if bad and fail(f"message {k} on {topic} at {path or 'value'}: {bad}"):
                return problems
    _compare_columns(cols_a, cols_b, fail)
    return problems


def _compare_columns(cols_a: dict, cols_b: dict, fail) -> None:
    """Each float field of the two logs (gathered per (topic, path)) within its tolerance; ``fail`` takes
    each problem and says when enough were found."""
    for key, parts in cols_a.items():
        a, b = np.concatenate(parts), np.concatenate(cols_b[key])
        fin_a, fin_b = np.isfinite(a), np.isfinite(b)
        same_nonfinite = np.array_equal(fin_a, fin_b) and np.array_equal(
            a[~fin_a], b[~fin_b], equal_nan=True
        )
        if not same_nonfinite:
            if fail(f"{key[0]} {key[1]}: non-finite values in other places"):
                return
            continue
        a, b = a[fin_a], b[fin_b]
        if a.size == 0:
            continue
        d = np.abs(a - b)
        if key in QUANTUM:
            # + 1 %: the ranges are float32 on the wire (an ulp is <= 1e-6 m below 16 m)
            tol = np.full_like(a, QUANTUM[key] * 1.01)
        elif key in TWO_DIGITS:
            tol = _two_digit_step(a) * (1 + 1e-6)
        else:
            tol = np.full_like(a, FLOAT_TOL * float(np.max(np.abs(a))))
        worst = int(np.argmax(d - tol))
        if d[worst] > tol[worst]:
            n_bad = int(np.sum(d > tol))
            if fail(
                f"{key[0]} {key[1]}: {n_bad} of {a.size} values differ beyond tolerance, worst "
                f"{a[worst]!r} vs {b[worst]!r} (|d| = {d[worst]:.3g} > {tol[worst]:.3g})"
            ):
                return


def max_differences(ref: DecodedLog, got: DecodedLog) -> dict[tuple[str, str], float]:
    """Largest absolute difference of every float field (for reports); assumes compare_logs found the same
    structure."""
    out: dict[tuple[str, str], float] = {}
    for ma, mb in zip(ref.messages, got.messages, strict=True):
        for (path, va), (_, vb) in zip(_leaves(ma[4], ""), _leaves(mb[4], ""), strict=True):
            if isinstance(va, float | tuple) and not isinstance(va, bool):
                a, b = np.asarray(va, dtype=np.float64), np.asarray(vb, dtype=np.float64)
                ok = np.isfinite(a) & np.isfinite(b)
                if ok.any():
                    key = (ma[0], path)
                    out[key] = max(out.get(key, 0.0), float(np.max(np.abs(a[ok] - b[ok]))))
    return out


__all__ = ["DecodedLog", "decode_log", "compare_logs", "max_differences", "FLOAT_TOL", "IMAGE_MEAN_TOL"]
