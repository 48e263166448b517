"""Read and write 2D pose graphs: g2o (VERTEX_SE2, VERTEX_XY, EDGE_SE2, EDGE_SE2_XY, FIX) and the TORO / iSAM text
variants that gtsam ships (VERTEX2, EDGE2, ODOMETRY, LANDMARK, BR, EQUIV).

Noise conventions (what the six numbers after an edge's measurement mean):

- ``EDGE_SE2``: upper triangle of the *information* matrix in (x, y, theta) order, I11 I12 I13 I22 I23 I33
  (g2o's definition; gtsam ``readG2o``). ``EDGE_SE2_XY``: I11 I12 I22 of the landmark's information.
- ``EDGE2`` / ``EDGE`` / ``ODOMETRY`` / ``LANDMARK`` carry no convention in the file, so the reader takes a
  :class:`TextNoise`. The default, ``GTSAM_AUTO``, reproduces ``gtsam.load2D`` with ``NoiseFormatAUTO`` exactly
  (so results compare with gtsam's): a line whose numbers look like (a 0 b c 0 0) is TORO order read as a
  *covariance* (gtsam's "GRAPH"), (a 0 0 b 0 c) is g2o order read as a *covariance* ("COV"); anything else is an
  error that asks for an explicit convention. LANDMARK lines under ``GTSAM_AUTO`` get gtsam's rule: when
  v1 == v3 the point is uncertain with bearing sigma sqrt(v1 / 10) and range sigma sqrt(v1), otherwise
  bearing and range sigmas of 1; holoslam stores the equivalent x/y covariance at the measured point.
  ``INFORMATION`` (g2o order, what SLAM++ and the SLAM++ reference chi2 assume), ``TORO_INFORMATION``
  (TORO's I_xx I_xy I_yy I_tt I_xt I_yt), ``COVARIANCE`` (g2o order) and ``SQRT_INFORMATION`` (iSAM's own
  meaning: the upper triangle of R with information R^T R) are explicit choices. Which convention the
  reference files need is in ``shared/posegraph/SOURCES.md``: the gtsam wheel's ``victoria_park.txt`` stores
  covariances (GTSAM_AUTO reads it right); iSAM's ``victoriaPark.txt`` / ``manhattanOlson3500_isam.txt`` store
  square-root information.

Speed: the lines are grouped by tag in one pass and each tag's numbers are converted by one ``np.loadtxt`` call
(numpy's C parser); the 3x3 / 2x2 inverses are closed-form batches (:mod:`holoslam.graph.linalg`). A text with
comments, lower-case tags or any malformed line goes through the line-by-line reader, which reports the problem.

Everything is kept as covariances in the returned :class:`G2oGraph` (the writer, :mod:`holoslam.io.g2o_write`,
converts back to information).
A malformed line raises :class:`~holoslam.errors.G2oFormatError` with the file, line number, the line and what is
wrong. Tags the reader does not know are listed in ``G2oGraph.skipped`` (or raise with ``strict=True``); known
tags holoslam does not use (EQUIV: TORO's equivalence of two vertices) are listed there too.
"""

from __future__ import annotations

import warnings
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from holoslam.choices import TextNoise
from holoslam.errors import G2oFormatError

__all__ = [
    "TextNoise",
    "G2oGraph",
    "SkippedTag",
    "read_g2o",
    "parse_g2o",
    "read_g2o_text",
]


@dataclass(frozen=True, slots=True)
class SkippedTag:
    """Lines the reader did not turn into graph elements: their tag, how many, and the first line number."""

    tag: str
    count: int
    first_line: int
    known: bool


def _ro(a: np.ndarray, dtype: type = np.float64) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=dtype)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class G2oGraph:
    """A 2D graph as read from a file: pose vertices, point vertices, pose-pose edges and pose-point edges, all as
    numpy batches. Covariances are in the measurement's own frame, (x, y, theta) order. ``*_line`` are 1-based
    line numbers in the source (0 when built in memory)."""

    vertex_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    vertex_poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    point_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    point_positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    edge_i: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    edge_j: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    edge_measured: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    edge_cov: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    edge_line: np.ndarray | None = None
    landmark_pose: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    landmark_id: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    landmark_measured: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    landmark_cov: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    landmark_line: np.ndarray | None = None
    fixed_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    skipped: tuple[SkippedTag, ...] = ()
    source: str = "<memory>"

    def __post_init__(self) -> None:
        s = object.__setattr__
        s(self, "vertex_ids", _ro(self.vertex_ids, np.int64).reshape(-1))
        s(self, "vertex_poses", _ro(self.vertex_poses).reshape(-1, 3))
        s(self, "point_ids", _ro(self.point_ids, np.int64).reshape(-1))
        s(self, "point_positions", _ro(self.point_positions).reshape(-1, 2))
        s(self, "edge_i", _ro(self.edge_i, np.int64).reshape(-1))
        s(self, "edge_j", _ro(self.edge_j, np.int64).reshape(-1))
        s(self, "edge_measured", _ro(self.edge_measured).reshape(-1, 3))
        s(self, "edge_cov", _ro(self.edge_cov).reshape(-1, 3, 3))
        el = np.zeros(self.edge_i.size, np.int64) if self.edge_line is None else self.edge_line
        s(self, "edge_line", _ro(el, np.int64).reshape(-1))
        s(self, "landmark_pose", _ro(self.landmark_pose, np.int64).reshape(-1))
        s(self, "landmark_id", _ro(self.landmark_id, np.int64).reshape(-1))
        s(self, "landmark_measured", _ro(self.landmark_measured).reshape(-1, 2))
        s(self, "landmark_cov", _ro(self.landmark_cov).reshape(-1, 2, 2))
        ll = np.zeros(self.landmark_pose.size, np.int64) if self.landmark_line is None else self.landmark_line
        s(self, "landmark_line", _ro(ll, np.int64).reshape(-1))
        s(self, "fixed_ids", _ro(self.fixed_ids, np.int64).reshape(-1))

    @property
    def num_poses(self) -> int:
        return int(
            np.unique(np.concatenate([self.vertex_ids, self.edge_i, self.edge_j, self.landmark_pose])).size
        )


# tag -> (number of fields after the tag, kind)
_TAGS: dict[str, tuple[int, str]] = {
    "VERTEX_SE2": (4, "vertex"),
    "VERTEX2": (4, "vertex"),
    "VERTEX": (4, "vertex"),
    "VERTEX_XY": (3, "point"),
    "EDGE_SE2": (11, "edge_g2o"),
    "EDGE2": (11, "edge_text"),
    "EDGE": (11, "edge_text"),
    "ODOMETRY": (11, "edge_text"),
    "EDGE_SE2_XY": (7, "landmark_g2o"),
    "LANDMARK": (7, "landmark_text"),
    "BR": (6, "landmark_br"),
    "FIX": (1, "fix"),
}
_KNOWN_IGNORED = {"EQUIV": "TORO vertex equivalence (not used by holoslam)"}
_MAX_ID = 2**53  # ids are read as float64: larger integers are not exact (and would not fit int64)
_INT_FIELDS = {
    "vertex": 1,
    "point": 1,
    "edge_g2o": 2,
    "edge_text": 2,
    "landmark_g2o": 2,
    "landmark_text": 2,
    "landmark_br": 2,
    "fix": 1,
}


class _Rows:
    def __init__(self) -> None:
        self.lines: list[int] = []
        self.fields: list[list[str]] = []


def _fail(path: str, lineno: int, line: str, what: str) -> G2oFormatError:
    return G2oFormatError(f"{path}:{lineno}: {what}\n    {line.strip()}")


def _to_array(rows: _Rows, ncol: int, nint: int, path: str, text_lines: list[str]) -> np.ndarray:
    """Convert the rows of one tag to a float array, pointing at the first bad line on failure."""
    try:
        arr = np.array(rows.fields, dtype=np.float64).reshape(-1, ncol)
    except ValueError:
        for ln, f in zip(rows.lines, rows.fields, strict=True):
            for k, tok in enumerate(f):
                try:
                    float(tok)
                except ValueError:
                    raise _fail(
                        path, ln, text_lines[ln - 1], f"field {k + 2} ({tok!r}) is not a number"
                    ) from None
        raise
    return _check_array(arr, rows, nint, path, text_lines)


def _sym3_g2o(v: np.ndarray) -> np.ndarray:
    """(M, 6) upper triangle in g2o order (11 12 13 22 23 33) -> (M, 3, 3)."""
    M = np.empty((v.shape[0], 3, 3))
    M[:, 0, 0], M[:, 0, 1], M[:, 0, 2] = v[:, 0], v[:, 1], v[:, 2]
    M[:, 1, 0], M[:, 1, 1], M[:, 1, 2] = v[:, 1], v[:, 3], v[:, 4]
    M[:, 2, 0], M[:, 2, 1], M[:, 2, 2] = v[:, 2], v[:, 4], v[:, 5]
    return M


def _sym3_toro(v: np.ndarray) -> np.ndarray:
    """(M, 6) in TORO order (xx xy yy tt xt yt) -> (M, 3, 3)."""
    return _sym3_g2o(v[:, [0, 1, 4, 2, 5, 3]])


def _inv_checked(
    M: np.ndarray, rows: _Rows, sel: np.ndarray, path: str, text: list[str], what: str
) -> np.ndarray:
    """Invert a batch of symmetric matrices; a matrix that is not positive definite is a format error."""
    if M.shape[0] == 0:
        return M
    bad = ~positive_definite(M)
    if bad.any():
        r = int(np.flatnonzero(sel)[np.argmax(bad)])
        eig = np.linalg.eigvalsh(M[np.argmax(bad)])
        raise _fail(
            path,
            rows.lines[r],
            text[rows.lines[r] - 1],
            f"the {what} matrix is not positive definite (eigenvalues {eig.tolist()})",
        )
    from holoslam.graph.linalg import inv_sym

    return inv_sym(M)


def positive_definite(M: np.ndarray) -> np.ndarray:
    """Sylvester's criterion for a batch (K, d, d) of symmetric 2x2 or 3x3 matrices (vectorised, cheap)."""
    a = M[:, 0, 0]
    m2 = a * M[:, 1, 1] - M[:, 0, 1] * M[:, 1, 0]
    if M.shape[1] == 2:
        return (a > 0) & (m2 > 0)
    det = (
        a * (M[:, 1, 1] * M[:, 2, 2] - M[:, 1, 2] * M[:, 2, 1])
        - M[:, 0, 1] * (M[:, 1, 0] * M[:, 2, 2] - M[:, 1, 2] * M[:, 2, 0])
        + M[:, 0, 2] * (M[:, 1, 0] * M[:, 2, 1] - M[:, 1, 1] * M[:, 2, 0])
    )
    return (a > 0) & (m2 > 0) & (det > 0) & np.isfinite(det)


def _edge_text_cov(v: np.ndarray, noise: TextNoise, rows: _Rows, path: str, text: list[str]) -> np.ndarray:
    m = v.shape[0]
    if m == 0:
        return np.zeros((0, 3, 3))
    cov = np.empty((m, 3, 3))
    if noise is TextNoise.GTSAM_AUTO:
        nz = v != 0.0
        graph = nz[:, 0] & ~nz[:, 1] & nz[:, 2] & nz[:, 3] & ~nz[:, 4] & ~nz[:, 5]
        covfmt = nz[:, 0] & ~nz[:, 1] & ~nz[:, 2] & nz[:, 3] & ~nz[:, 4] & nz[:, 5]
        neither = ~(graph | covfmt)
        if neither.any():
            r = int(np.argmax(neither))
            raise _fail(
                path,
                rows.lines[r],
                text[rows.lines[r] - 1],
                "gtsam's automatic noise format recognises only diagonal (a 0 b c 0 0) or (a 0 0 b 0 c) "
                "noise; pass an explicit TextNoise (information, toro_information, covariance, "
                "sqrt_information)",
            )
        cov[graph] = _sym3_toro(v[graph])
        cov[covfmt] = _sym3_g2o(v[covfmt])
        return cov
    all_rows = np.ones(m, bool)
    if noise is TextNoise.COVARIANCE:
        cov = _sym3_g2o(v)
        _inv_checked(cov, rows, all_rows, path, text, "covariance")
        return cov
    if noise is TextNoise.INFORMATION:
        return _inv_checked(_sym3_g2o(v), rows, all_rows, path, text, "information")
    if noise is TextNoise.TORO_INFORMATION:
        return _inv_checked(_sym3_toro(v), rows, all_rows, path, text, "information")
    # SQRT_INFORMATION: R upper triangular in g2o order, information R^T R
    R = _sym3_g2o(v)
    R[:, 1, 0] = R[:, 2, 0] = R[:, 2, 1] = 0.0
    return _inv_checked(np.swapaxes(R, 1, 2) @ R, rows, all_rows, path, text, "square-root information")


def _br_jacobian(xy: np.ndarray) -> np.ndarray:
    """d(bearing, range)/d(x, y) at points xy (L, 2) -> (L, 2, 2)."""
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    r = np.sqrt(r2)
    return np.stack([np.stack([-y / r2, x / r2], -1), np.stack([x / r, y / r], -1)], -2)


def xy_cov_from_bearing_range(
    xy: np.ndarray, sigma_bearing: np.ndarray, sigma_range: np.ndarray
) -> np.ndarray:
    """The x/y covariance (L, 2, 2) whose first-order bearing/range covariance is diag(sb^2, sr^2)."""
    J = _br_jacobian(xy)
    det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
    Jinv = np.stack([np.stack([J[:, 1, 1], -J[:, 0, 1]], -1), np.stack([-J[:, 1, 0], J[:, 0, 0]], -1)], -2)
    Jinv /= det[:, None, None]
    D = np.zeros((xy.shape[0], 2, 2))
    D[:, 0, 0] = np.square(sigma_bearing)
    D[:, 1, 1] = np.square(sigma_range)
    return Jinv @ D @ np.swapaxes(Jinv, 1, 2)


def _landmark_text_cov(
    v: np.ndarray, xy: np.ndarray, noise: TextNoise, rows: _Rows, path: str, text: list[str]
) -> np.ndarray:
    m = v.shape[0]
    if m == 0:
        return np.zeros((0, 2, 2))
    if np.any(np.hypot(xy[:, 0], xy[:, 1]) == 0.0):
        r = int(np.argmax(np.hypot(xy[:, 0], xy[:, 1]) == 0.0))
        raise _fail(path, rows.lines[r], text[rows.lines[r] - 1], "a landmark at range 0 has no bearing")
    all_rows = np.ones(m, bool)
    M = np.empty((m, 2, 2))
    M[:, 0, 0], M[:, 0, 1], M[:, 1, 0], M[:, 1, 1] = v[:, 0], v[:, 1], v[:, 1], v[:, 2]
    if noise is TextNoise.GTSAM_AUTO:
        iso = np.abs(v[:, 0] - v[:, 2]) < 1e-4
        if np.any(iso & ~(v[:, 0] > 0)):
            r = int(np.argmax(iso & ~(v[:, 0] > 0)))
            raise _fail(path, rows.lines[r], text[rows.lines[r] - 1], "landmark variance must be > 0")
        sb = np.where(iso, np.sqrt(np.abs(v[:, 0]) / 10.0), 1.0)
        sr = np.where(iso, np.sqrt(np.abs(v[:, 0])), 1.0)
        return xy_cov_from_bearing_range(xy, sb, sr)
    if noise is TextNoise.COVARIANCE:
        _inv_checked(M, rows, all_rows, path, text, "covariance")
        return M
    if noise is TextNoise.SQRT_INFORMATION:
        M[:, 1, 0] = 0.0
        M = np.swapaxes(M, 1, 2) @ M
    return _inv_checked(M, rows, all_rows, path, text, "information")


def _split_fields(
    lines: list[str], source: str, strict: bool
) -> tuple[dict[str, _Rows], dict[str, list[int]]]:
    """The slow, line-by-line tokeniser: exact messages for malformed lines (the fallback of :func:`_tokenise`)."""
    by_kind: dict[str, _Rows] = defaultdict(_Rows)
    skipped: dict[str, list[int]] = {}
    for lineno, line in enumerate(lines, start=1):
        body = line.split("#", 1)[0]
        parts = body.split()
        if not parts:
            continue
        tag = parts[0].upper()
        spec = _TAGS.get(tag)
        if spec is None:
            if strict and tag not in _KNOWN_IGNORED:
                raise _fail(
                    source, lineno, line, f"unknown tag {parts[0]!r} (a 3D graph? holoslam reads 2D graphs)"
                )
            skipped.setdefault(tag, [lineno, 0])[1] += 1
            continue
        nf, kind = spec
        if len(parts) - 1 != nf:
            raise _fail(
                source, lineno, line, f"{tag} needs {nf} fields after the tag, found {len(parts) - 1}"
            )
        rows = by_kind[kind]
        rows.lines.append(lineno)
        rows.fields.append(parts[1:])
    return by_kind, skipped


def _tokenise(
    lines: list[str], source: str, strict: bool
) -> tuple[dict[str, np.ndarray], dict[str, _Rows], dict[str, list[int]]]:
    """Group the lines by tag (one pass) and convert each tag's fields in one ``np.loadtxt`` call (numpy's C
    parser), so a 10,000-line file costs a few milliseconds. Any irregularity (a wrong field count, a token that
    is not a number, lower-case tags) sends the whole text through the line-by-line tokeniser, which
    names the file, line and problem. Returns ({kind: (rows, fields) float array}, {kind: line numbers (fields
    empty when the array is given)}, {skipped tag: [first line, count]})."""
    groups: dict[str, tuple[list[int], list[str]]] = {}
    for lineno, line in enumerate(lines, start=1):
        parts = line.split(None, 1)
        if not parts:
            continue
        g = groups.get(parts[0])
        if g is None:
            g = groups[parts[0]] = ([], [])
        g[0].append(lineno)
        g[1].append(parts[1] if len(parts) == 2 else "")
    kinds: dict[str, list[str]] = defaultdict(list)
    skipped: dict[str, list[int]] = {}
    regular = True
    for tag, (nums, _) in groups.items():
        spec = _TAGS.get(tag)
        if spec is None:
            if tag.startswith("#"):
                continue  # a comment line
            if tag.upper() in _TAGS or "#" in tag:
                regular = False  # lower-case tags, "TAG#comment": the careful path
                break
            if strict and tag not in _KNOWN_IGNORED:
                regular = False
                break
            skipped[tag] = [nums[0], len(nums)]
            continue
        kinds[spec[1]].append(tag)
    arrays: dict[str, np.ndarray] = {}
    by_kind: dict[str, _Rows] = {}
    if regular:
        for kind, tags in kinds.items():
            ncol = next(n for n, k in _TAGS.values() if k == kind)
            nums = [n for t in tags for n in groups[t][0]]
            rests = [r for t in tags for r in groups[t][1]]
            try:  # loadtxt drops "# ..." tails; a line that is only a comment changes the row count below
                # an empty row ("TAG" alone) only warns (UserWarning): the shape check below catches it
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)
                    a = np.loadtxt(rests, dtype=np.float64, ndmin=2, comments="#")
            except ValueError:
                regular = False
                break
            if a.shape != (len(rests), ncol):
                regular = False
                break
            if len(tags) > 1:
                order = np.argsort(np.array(nums), kind="stable")
                a, nums = a[order], np.array(nums)[order].tolist()
            rows = _Rows()
            rows.lines = nums
            by_kind[kind] = rows
            arrays[kind] = a
    if not regular:
        slow, skipped = _split_fields(lines, source, strict)
        return {}, dict(slow), skipped
    return arrays, by_kind, skipped


def _check_array(arr: np.ndarray, rows: _Rows, nint: int, path: str, text_lines: list[str]) -> np.ndarray:
    """Finiteness and integer-id checks of a converted (M, ncol) array, naming the first bad line."""
    if not np.all(np.isfinite(arr)):
        r = int(np.argmax(~np.isfinite(arr).all(axis=1)))
        raise _fail(path, rows.lines[r], text_lines[rows.lines[r] - 1], "a field is not finite (nan or inf)")
    if nint:
        ids = arr[:, :nint]
        bad = (ids != np.round(ids)) | (ids < 0) | (ids > _MAX_ID)
        if bad.any():
            r = int(np.argmax(bad.any(axis=1)))
            raise _fail(
                path,
                rows.lines[r],
                text_lines[rows.lines[r] - 1],
                "a vertex id is not a non-negative integer (at most 2**53)",
            )
    return arr


def parse_g2o(
    text: str, source: str = "<memory>", noise: TextNoise = TextNoise.GTSAM_AUTO, strict: bool = False
) -> G2oGraph:
    """Parse the text of a 2D g2o / TORO / iSAM graph (see the module docstring for the conventions)."""
    noise = TextNoise(noise)
    lines = text.splitlines()
    arrays, by_kind, skipped = _tokenise(lines, source, strict)

    def arr(kind: str) -> tuple[np.ndarray, _Rows]:
        ncol = next(n for n, k in _TAGS.values() if k == kind)
        rows = by_kind.get(kind)
        if rows is None:
            return np.zeros((0, ncol)), _Rows()
        if kind in arrays:
            return _check_array(arrays[kind], rows, _INT_FIELDS[kind], source, lines), rows
        return _to_array(rows, ncol, _INT_FIELDS[kind], source, lines), rows

    def merge(
        parts: list[tuple[np.ndarray, ...]], row_sets: list[_Rows]
    ) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
        """Concatenate the per-kind arrays of one element type in file order (a single kind: as it is)."""
        present = [k for k, r in enumerate(row_sets) if r.lines]
        if len(present) == 1:
            k = present[0]
            return parts[k], np.array(row_sets[k].lines, dtype=np.int64)
        line = np.array([n for r in row_sets for n in r.lines], dtype=np.int64)
        order = np.argsort(line, kind="stable")
        return tuple(np.concatenate(cols)[order] for cols in zip(*parts, strict=True)), line[order]

    v, _ = arr("vertex")
    p, _ = arr("point")
    fx, _ = arr("fix")
    # pose-pose edges: g2o (information) and text (convention) merged in file order
    eg, rg = arr("edge_g2o")
    et, rt = arr("edge_text")
    cov_g = _inv_checked(_sym3_g2o(eg[:, 5:]), rg, np.ones(eg.shape[0], bool), source, lines, "information")
    cov_t = _edge_text_cov(et[:, 5:], noise, rt, source, lines)
    (e_head, e_cov), e_line = merge([(eg[:, :5], cov_g), (et[:, :5], cov_t)], [rg, rt])
    # pose-point edges
    lg, rlg = arr("landmark_g2o")
    lt, rlt = arr("landmark_text")
    lb, rlb = arr("landmark_br")
    if lg.shape[0] + lt.shape[0] + lb.shape[0]:
        Ig = np.empty((lg.shape[0], 2, 2))
        Ig[:, 0, 0], Ig[:, 0, 1], Ig[:, 1, 0], Ig[:, 1, 1] = lg[:, 4], lg[:, 5], lg[:, 5], lg[:, 6]
        lcov_g = _inv_checked(Ig, rlg, np.ones(lg.shape[0], bool), source, lines, "information")
        lcov_t = _landmark_text_cov(lt[:, 4:], lt[:, 2:4], noise, rlt, source, lines)
        b_xy = np.column_stack([lb[:, 3] * np.cos(lb[:, 2]), lb[:, 3] * np.sin(lb[:, 2])])
        if lb.shape[0] and np.any((lb[:, 3] <= 0) | (lb[:, 4] <= 0) | (lb[:, 5] <= 0)):
            r = int(np.argmax((lb[:, 3] <= 0) | (lb[:, 4] <= 0) | (lb[:, 5] <= 0)))
            raise _fail(source, rlb.lines[r], lines[rlb.lines[r] - 1], "BR needs range > 0 and sigmas > 0")
        lcov_b = xy_cov_from_bearing_range(b_xy, lb[:, 4], lb[:, 5]) if lb.shape[0] else np.zeros((0, 2, 2))
        (l_head, l_xy, l_cov), l_line = merge(
            [(lg[:, :2], lg[:, 2:4], lcov_g), (lt[:, :2], lt[:, 2:4], lcov_t), (lb[:, :2], b_xy, lcov_b)],
            [rlg, rlt, rlb],
        )
    else:
        l_head, l_xy, l_cov, l_line = np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2, 2)), None

    skipped_t = tuple(
        SkippedTag(tag, cnt, first, tag in _KNOWN_IGNORED) for tag, (first, cnt) in sorted(skipped.items())
    )
    return G2oGraph(
        vertex_ids=v[:, 0].astype(np.int64),
        vertex_poses=v[:, 1:4],
        point_ids=p[:, 0].astype(np.int64),
        point_positions=p[:, 1:3],
        edge_i=e_head[:, 0].astype(np.int64),
        edge_j=e_head[:, 1].astype(np.int64),
        edge_measured=e_head[:, 2:5],
        edge_cov=e_cov,
        edge_line=e_line if e_line.size else None,
        landmark_pose=l_head[:, 0].astype(np.int64),
        landmark_id=l_head[:, 1].astype(np.int64),
        landmark_measured=l_xy,
        landmark_cov=l_cov,
        landmark_line=l_line,
        fixed_ids=fx[:, 0].astype(np.int64),
        skipped=skipped_t,
        source=source,
    )


def read_g2o_text(path: str | Path) -> str:
    """The text of a graph file, with every way it can be unreadable said as a G2oFormatError."""
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8", errors="strict")
    except FileNotFoundError:
        raise G2oFormatError(f"{path}: no such file") from None
    except OSError as e:  # a directory, no permission
        raise G2oFormatError(
            f"{path}: cannot read the file ({e.strerror or e}); pass a g2o text file"
        ) from None
    except UnicodeDecodeError as e:
        raise G2oFormatError(f"{path}: not a text file ({e.reason} at byte {e.start})") from None


def read_g2o(path: str | Path, noise: TextNoise = TextNoise.GTSAM_AUTO, strict: bool = False) -> G2oGraph:
    """Read a 2D g2o / TORO / iSAM text graph file."""
    return parse_g2o(read_g2o_text(path), source=str(Path(path)), noise=noise, strict=strict)
