"""Compiled kernels of the submap probability grids (numba, ``cache=True``): scan insertion, bicubic lookup with
gradient, the continuous least-squares scan matcher and the brute-force correlative window search.

Grid convention (shared with :mod:`holoslam.submaps.probgrid`): cell (r, c) covers
x in [ox + c res, ox + (c + 1) res), y in [oy + r res, oy + (r + 1) res); a cell's value is sampled at its
centre. Log-odds grids are float32; ``0`` with ``known == 0`` is an unknown cell.

Imported lazily by :mod:`holoslam.submaps.probgrid` and :mod:`holoslam.submaps.scanmatch`; the first call
compiles (a few seconds, once per machine), later processes load from numba's on-disk cache.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from holoslam._jit import JIT, JIT_INNER


@nb.njit(**JIT)
def insert_scan(logodds, prob, known, marker, stamp, ox, oy, res, sx, sy, ex, ey, hit, l_hit, l_miss, l_max, p_min,
                p_max):  # pragma: no cover
    """Insert one scan: beams from the sensor at (sx, sy) to the end points (ex, ey) (grid frame, metres).
    Every end cell with ``hit`` gets ``l_hit`` once, every other cell a beam crosses gets ``l_miss`` once per
    scan (``marker`` holds the last scan ``stamp`` that updated a cell; hits first, so a cell that holds a
    return is never cleared by the same scan, Cartographer's rule). Log-odds are clamped to +-``l_max``."""
    rows, cols = logodds.shape
    n = ex.size
    for k in range(n):
        if not hit[k]:
            continue
        c = int(math.floor((ex[k] - ox) / res))
        r = int(math.floor((ey[k] - oy) / res))
        if 0 <= r < rows and 0 <= c < cols and marker[r, c] != stamp:
            marker[r, c] = stamp
            v = min(max(logodds[r, c] + l_hit, -l_max), l_max)
            logodds[r, c] = v
            prob[r, c] = min(max(1.0 / (1.0 + math.exp(-v)), p_min), p_max)
            known[r, c] = 1
    c0 = int(math.floor((sx - ox) / res))
    r0 = int(math.floor((sy - oy) / res))
    for k in range(n):
        c1 = int(math.floor((ex[k] - ox) / res))
        r1 = int(math.floor((ey[k] - oy) / res))
        # Bresenham from the sensor cell to the end cell, the end cell excluded
        dc, dr = abs(c1 - c0), -abs(r1 - r0)
        scx = 1 if c0 < c1 else -1
        scy = 1 if r0 < r1 else -1
        err = dc + dr
        c, r = c0, r0
        while not (c == c1 and r == r1):
            if 0 <= r < rows and 0 <= c < cols and marker[r, c] != stamp:
                marker[r, c] = stamp
                v = min(max(logodds[r, c] + l_miss, -l_max), l_max)
                logodds[r, c] = v
                prob[r, c] = min(max(1.0 / (1.0 + math.exp(-v)), p_min), p_max)
                known[r, c] = 1
            e2 = 2 * err
            if e2 >= dr:
                err += dr
                c += scx
            if e2 <= dc:
                err += dc
                r += scy


@nb.njit(**JIT)
def endpoints(ranges, c, s, x, y, max_range, missing_length):  # pragma: no cover
    """Beam end points (ex, ey) from the sensor at (x, y) along directions (c, s) (cosine and sine of each
    beam's angle in the grid frame), which are returns (a finite range in (0, max_range]; any other beam
    reaches ``missing_length`` of free space), and the box (x0, y0, x1, y1) of the end points and the sensor.
    ``probgrid.scan_endpoints``'s arithmetic; numpy's eight calls cost 10x this work at every insertion."""
    n = ranges.size
    ex = np.empty(n, dtype=np.float64)
    ey = np.empty(n, dtype=np.float64)
    hit = np.empty(n, dtype=np.bool_)
    x0, y0, x1, y1 = x, y, x, y
    for k in range(n):
        r = ranges[k]
        h = math.isfinite(r) and r > 0 and r <= max_range
        length = r if h else missing_length
        hit[k] = h
        ex[k] = x + length * c[k]
        ey[k] = y + length * s[k]
        x0, x1 = min(x0, ex[k]), max(x1, ex[k])
        y0, y1 = min(y0, ey[k]), max(y1, ey[k])
    return ex, ey, hit, x0, y0, x1, y1


@nb.njit(**JIT)
def _select(r, k):  # pragma: no cover
    """The k-th smallest of r (0-based), r reordered so that r[:k] <= r[k] <= r[k + 1:] (Hoare's quickselect,
    the middle element as pivot): what a sort would put at k, without numba's sort (a second of compiling)."""
    lo, hi = 0, r.size - 1
    while lo < hi:
        pivot = r[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while r[i] < pivot:
                i += 1
            while r[j] > pivot:
                j -= 1
            if i <= j:
                r[i], r[j] = r[j], r[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    return r[k]


@nb.njit(**JIT)
def angular_step(px, py, res, quantile):  # pragma: no cover
    """``scanmatch.angular_step`` of the points (px, py): the rotation that moves the ``quantile`` range (numpy's
    linear quantile, its arithmetic) by about one cell of ``res``. One compiled call instead of five numpy ones
    (they cost 10x this work at every match)."""
    n = px.size
    if n == 0:
        d = 1.0
    else:
        r = np.empty(n, dtype=np.float64)
        for k in range(n):
            r[k] = math.hypot(px[k], py[k])
        v = (n - 1) * quantile  # numpy's virtual index of its linear method
        lo = min(max(int(math.floor(v)), 0), n - 1)
        a = _select(r, lo)  # the lo-th smallest; the next one is the least of those after it
        b = a
        if lo + 1 < n:
            b = r[lo + 1]
            for k in range(lo + 2, n):
                b = min(b, r[k])
        t = min(max(v - math.floor(v), 0.0), 1.0) if 0.0 <= v < n - 1 else (0.0 if v < 0.0 else 1.0)
        diff = b - a
        d = b - diff * (1.0 - t) if t >= 0.5 else a + diff * t
    d = max(d, 2.0 * res)
    return math.acos(max(-1.0, 1.0 - res ** 2 / (2.0 * d * d)))


@nb.njit(**JIT_INNER)
def _cubic(p0, p1, p2, p3, t):  # pragma: no cover
    """Catmull-Rom cubic through p1 (t = 0) and p2 (t = 1): value and derivative in t."""
    a = -p0 + 3.0 * p1 - 3.0 * p2 + p3
    b = 2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3
    c = -p0 + p2
    v = 0.5 * (((a * t + b) * t + c) * t + 2.0 * p1)
    d = 0.5 * ((3.0 * a * t + 2.0 * b) * t + c)
    return v, d


@nb.njit(**JIT)
def _cell(prob, r, c, outside):  # pragma: no cover
    rows, cols = prob.shape
    if 0 <= r < rows and 0 <= c < cols:
        return prob[r, c]
    return outside


@nb.njit(**JIT)
def bicubic(prob, u, v, outside):  # pragma: no cover
    """Bicubic (Catmull-Rom) interpolation of ``prob`` at continuous cell coordinates (u along columns, v along
    rows, integers at cell centres): value, d/du, d/dv. Where the 4 x 4 cells lie inside the grid (nearly every
    lookup) they are read without a bounds check per cell, as float64 like ``_cell``'s (float32 arithmetic would
    change the result); the same values and arithmetic, equal to the last bit, 13 % less of the matcher's time."""
    c = int(math.floor(u))
    r = int(math.floor(v))
    tu = u - c
    tv = v - r
    rows, cols = prob.shape
    if r >= 1 and c >= 1 and r + 2 < rows and c + 2 < cols:
        f8 = np.float64
        v0, d0 = _cubic(f8(prob[r - 1, c - 1]), f8(prob[r - 1, c]), f8(prob[r - 1, c + 1]), f8(prob[r - 1, c + 2]), tu)
        v1, d1 = _cubic(f8(prob[r, c - 1]), f8(prob[r, c]), f8(prob[r, c + 1]), f8(prob[r, c + 2]), tu)
        v2, d2 = _cubic(f8(prob[r + 1, c - 1]), f8(prob[r + 1, c]), f8(prob[r + 1, c + 1]), f8(prob[r + 1, c + 2]), tu)
        v3, d3 = _cubic(f8(prob[r + 2, c - 1]), f8(prob[r + 2, c]), f8(prob[r + 2, c + 1]), f8(prob[r + 2, c + 2]), tu)
    else:
        v0, d0 = _cubic(_cell(prob, r - 1, c - 1, outside), _cell(prob, r - 1, c, outside),
                        _cell(prob, r - 1, c + 1, outside), _cell(prob, r - 1, c + 2, outside), tu)
        v1, d1 = _cubic(_cell(prob, r, c - 1, outside), _cell(prob, r, c, outside),
                        _cell(prob, r, c + 1, outside), _cell(prob, r, c + 2, outside), tu)
        v2, d2 = _cubic(_cell(prob, r + 1, c - 1, outside), _cell(prob, r + 1, c, outside),
                        _cell(prob, r + 1, c + 1, outside), _cell(prob, r + 1, c + 2, outside), tu)
        v3, d3 = _cubic(_cell(prob, r + 2, c - 1, outside), _cell(prob, r + 2, c, outside),
                        _cell(prob, r + 2, c + 1, outside), _cell(prob, r + 2, c + 2, outside), tu)
    value, dv = _cubic(v0, v1, v2, v3, tv)
    du, _ = _cubic(d0, d1, d2, d3, tv)
    return value, du, dv


@nb.njit(**JIT)
def _lsq_terms(prob, ox, oy, res, px, py, s, px_, py_, pt_, w_trans, w_rot, outside, x, y, t, H, g, Hocc,
               want):  # pragma: no cover
    """``lsq_match``'s cost at (x, y, t) and its occupied-space part; with ``want`` also the Gauss-Newton
    gradient ``g`` and Hessian ``H`` of the whole cost and the Hessian ``Hocc`` of the occupied term (into the
    buffers given). The sums are kept in locals and written once (the same additions in the same order as
    adding into the buffers point by point; H's lower triangle is its upper one, j_a j_b = j_b j_a exactly)."""
    n = px.size
    ct, st = math.cos(t), math.sin(t)
    cost_occ = 0.0
    g0 = g1 = g2 = 0.0
    h00 = h01 = h02 = h11 = h12 = h22 = 0.0
    for k in range(n):
        wx = ct * px[k] - st * py[k] + x
        wy = st * px[k] + ct * py[k] + y
        u = (wx - ox) / res - 0.5
        v = (wy - oy) / res - 0.5
        val, du, dv = bicubic(prob, u, v, outside)
        r = s * (1.0 - val)
        cost_occ += r * r
        if want:
            j0 = -s * du / res
            j1 = -s * dv / res
            j2 = j0 * (-st * px[k] - ct * py[k]) + j1 * (ct * px[k] - st * py[k])
            g0 += j0 * r
            g1 += j1 * r
            g2 += j2 * r
            h00 += j0 * j0
            h01 += j0 * j1
            h02 += j0 * j2
            h11 += j1 * j1
            h12 += j1 * j2
            h22 += j2 * j2
    dt = math.atan2(math.sin(t - pt_), math.cos(t - pt_))
    cost = cost_occ + w_trans * w_trans * ((x - px_) ** 2 + (y - py_) ** 2) + w_rot * w_rot * dt * dt
    if want:
        Hocc[0, 0], Hocc[0, 1], Hocc[0, 2] = h00, h01, h02
        Hocc[1, 0], Hocc[1, 1], Hocc[1, 2] = h01, h11, h12
        Hocc[2, 0], Hocc[2, 1], Hocc[2, 2] = h02, h12, h22
        H[0, 0], H[0, 1], H[0, 2] = h00 + w_trans * w_trans, h01, h02
        H[1, 0], H[1, 1], H[1, 2] = h01, h11 + w_trans * w_trans, h12
        H[2, 0], H[2, 1], H[2, 2] = h02, h12, h22 + w_rot * w_rot
        g[0] = g0 + w_trans * w_trans * (x - px_)
        g[1] = g1 + w_trans * w_trans * (y - py_)
        g[2] = g2 + w_rot * w_rot * dt
    return cost, cost_occ


@nb.njit(**JIT)
def _solve3(A, b):  # pragma: no cover
    """x with A x = b for a 3x3 A: Gaussian elimination with partial pivoting (LAPACK getrf + getrs's
    algorithm, unrolled). ``np.linalg.solve`` does the same through LAPACK, but compiling numba's binding of it
    took 5 s of a first run's CPU for this one 3x3 system (its solution agrees to 1e-14)."""
    a = A.copy()
    x = b.copy()
    for k in range(3):  # L U with row swaps, the multipliers scaled by the pivot's reciprocal (as getrf2)
        p = k
        for r in range(k + 1, 3):
            if abs(a[r, k]) > abs(a[p, k]):
                p = r
        if p != k:
            for c in range(3):
                a[k, c], a[p, c] = a[p, c], a[k, c]
            x[k], x[p] = x[p], x[k]
        inv = 1.0 / a[k, k]
        for r in range(k + 1, 3):
            f = a[r, k] * inv
            for c in range(k + 1, 3):
                a[r, c] -= f * a[k, c]
            x[r] -= f * x[k]
    for k in range(2, -1, -1):  # U x = y by columns (as trsm)
        x[k] /= a[k, k]
        for r in range(k):
            x[r] -= x[k] * a[r, k]
    return x


@nb.njit(**JIT)
def lsq_match(prob, ox, oy, res, px, py, x0, y0, t0, px_, py_, pt_, w_occ, w_trans, w_rot, iters, outside):  # pragma: no cover
    """Continuous scan-to-grid matching: Gauss-Newton with Levenberg damping on
    sum_i (w_occ / sqrt(N) (1 - P(T p_i)))^2 + w_trans^2 |t - t_pred|^2 + w_rot^2 (theta - theta_pred)^2,
    P bicubic. Starts at (x0, y0, t0), prior at (px_, py_, pt_). Returns x, y, theta, the final cost, the
    occupied-space cost alone, the 3x3 Gauss-Newton Hessian of the occupied term and the iterations used."""
    n = px.size
    s = w_occ / math.sqrt(max(n, 1))
    x, y, t = x0, y0, t0
    lam = 1e-3
    H = np.zeros((3, 3), dtype=np.float64)
    g = np.zeros(3, dtype=np.float64)
    Hocc = np.zeros((3, 3), dtype=np.float64)
    cost, cost_occ = _lsq_terms(prob, ox, oy, res, px, py, s, px_, py_, pt_, w_trans, w_rot, outside, x, y, t, H, g,
                                Hocc, True)
    # a trial step is evaluated with its gradient and Hessian (into the spare buffers): accepted, they are the
    # next iteration's; one pass over the points per iteration instead of a value pass and a gradient pass
    H2 = np.zeros((3, 3), dtype=np.float64)
    g2 = np.zeros(3, dtype=np.float64)
    Hocc2 = np.zeros((3, 3), dtype=np.float64)
    used = 0
    for it in range(iters):
        used = it + 1
        A = H.copy()
        for a in range(3):
            A[a, a] += lam * (H[a, a] + 1e-9)
        step = _solve3(A, -g)
        nx, ny, nt = x + step[0], y + step[1], t + step[2]
        ncost, nocc = _lsq_terms(prob, ox, oy, res, px, py, s, px_, py_, pt_, w_trans, w_rot, outside, nx, ny, nt,
                                 H2, g2, Hocc2, True)
        if ncost < cost:
            # converged: a step under 0.1 mm and 0.006 deg, or a relative decrease under 1e-6
            small = abs(cost - ncost) < 1e-6 * max(cost, 1e-12) or (
                abs(step[0]) < 1e-4 and abs(step[1]) < 1e-4 and abs(step[2]) < 1e-4)
            x, y, t = nx, ny, nt
            lam = max(lam * 0.3, 1e-7)
            cost, cost_occ = ncost, nocc
            H, H2 = H2, H
            g, g2 = g2, g
            Hocc, Hocc2 = Hocc2, Hocc
            if small:
                break
        else:
            lam *= 10.0
            if lam > 1e6 or (abs(step[0]) < 1e-4 and abs(step[1]) < 1e-4 and abs(step[2]) < 1e-4):
                break
    t = math.atan2(math.sin(t), math.cos(t))
    return x, y, t, cost, cost_occ, Hocc, used


@nb.njit(**JIT)
def window_scores(prob, ox, oy, res, px, py, cx, cy, ct, nxy, angles, outside):  # pragma: no cover
    """Mean probability of the points at every pose of a window: translations cx + i res, cy + j res for
    i, j in [-nxy, nxy] and rotations ct + angles[a]. Returns (len(angles), 2 nxy + 1, 2 nxy + 1) scores
    (axis 1 along y, axis 2 along x). Points snap to the cell holding them (Olson's lookup)."""
    rows, cols = prob.shape
    na = angles.size
    m = 2 * nxy + 1
    out = np.zeros((na, m, m), dtype=np.float64)
    n = px.size
    inv = 1.0 / max(n, 1)
    for a in range(na):
        th = ct + angles[a]
        c, s = math.cos(th), math.sin(th)
        for k in range(n):
            wx = c * px[k] - s * py[k] + cx
            wy = s * px[k] + c * py[k] + cy
            c0 = int(math.floor((wx - ox) / res)) - nxy
            r0 = int(math.floor((wy - oy) / res)) - nxy
            if r0 >= 0 and c0 >= 0 and r0 + m <= rows and c0 + m <= cols:  # the whole block inside: no checks
                for j in range(m):
                    for i in range(m):
                        out[a, j, i] += prob[r0 + j, c0 + i]
                continue
            for j in range(m):
                r = r0 + j
                if r < 0 or r >= rows:
                    for i in range(m):
                        out[a, j, i] += outside
                    continue
                for i in range(m):
                    cc = c0 + i
                    if 0 <= cc < cols:
                        out[a, j, i] += prob[r, cc]
                    else:
                        out[a, j, i] += outside
    for a in range(na):
        for j in range(m):
            for i in range(m):
                out[a, j, i] *= inv
    return out


@nb.njit(**JIT)
def line_scores(prob, ox, oy, res, ax, ay, ux, uy, shifts, outside):  # pragma: no cover
    """Mean probability of the points (ax, ay) (grid frame, metres) moved by d (ux, uy) for every d of ``shifts``:
    ``window_scores``' nearest-cell lookup along one line (``holoslam.submaps.periodic``). numpy's version built
    five (shifts, points) arrays: 1.3 ms a closure, 0.7 s of the household run."""
    rows, cols = prob.shape
    n = ax.size
    inv = 1.0 / max(n, 1)
    out = np.zeros(shifts.size, dtype=np.float64)
    for k in range(shifts.size):
        dx, dy = shifts[k] * ux - ox, shifts[k] * uy - oy
        tot = 0.0
        for i in range(n):
            c = int(math.floor((ax[i] + dx) / res))
            r = int(math.floor((ay[i] + dy) / res))
            tot += prob[r, c] if 0 <= r < rows and 0 <= c < cols else outside
        out[k] = tot * inv
    return out


@nb.njit(**JIT)
def window_seed(S, res, angles, w_trans, w_rot, seed_margin):  # pragma: no cover
    """The seed (angle, y, x indices) of a correlative window's scores S (``window_scores``): the best score
    discounted by exp(-(w_trans d^2 + w_rot a^2)) for its offset d (m) and angle a (rad) from the window's
    centre (the first of equals, in numpy's argmax order); the centre cell of that angle instead when the best
    gains less than ``seed_margin`` over it. numpy's version cost 5x its arithmetic, at every match."""
    na, m = S.shape[0], S.shape[1]
    nxy = (m - 1) // 2
    best = -np.inf
    ba = bj = bi = 0
    for a in range(na):
        ra = w_rot * angles[a] ** 2
        for j in range(m):
            oj = (j - nxy) * res
            for i in range(m):
                oi = (i - nxy) * res
                v = S[a, j, i] * math.exp(-(w_trans * (oj ** 2 + oi ** 2) + ra))
                if v > best:
                    best, ba, bj, bi = v, a, j, i
    if S[ba, bj, bi] - S[ba, nxy, nxy] < seed_margin:
        bj = bi = nxy
    return ba, bj, bi


@nb.njit(**JIT)
def mean_bicubic(prob, ox, oy, res, px, py, x, y, t, outside):  # pragma: no cover
    """Mean bicubic probability of the points at pose (x, y, t)."""
    c, s = math.cos(t), math.sin(t)
    tot = 0.0
    n = px.size
    for k in range(n):
        wx = c * px[k] - s * py[k] + x
        wy = s * px[k] + c * py[k] + y
        tot += bicubic(prob, (wx - ox) / res - 0.5, (wy - oy) / res - 0.5, outside)[0]
    return tot / max(n, 1)


@nb.njit(**JIT)
def surface_covariance(S, p0, p1, p2, off, angles, a0, a1, a2, kappa, res, step):  # pragma: no cover
    """The covariance of a match from its score surface, in one pass: the weighted second moment of the window's
    poses (scores S (A, M, M): angle, y, x offsets ``off`` about the prediction (p0, p1, p2)) about the refined
    pose (a0, a1, a2), weights exp(kappa (s - max s)), floored by the lattice's uniform variance (spacing^2 / 12)
    and turned into the pose's own frame. (numpy's version of the same sums agreed to 4e-15; its set-up cost
    ~10x its arithmetic on a window of a few hundred poses, at every match.)"""
    na, m = S.shape[0], S.shape[1]
    top = -np.inf
    for a in range(na):
        for j in range(m):
            for i in range(m):
                if S[a, j, i] > top:
                    top = S[a, j, i]
    e = np.empty((na, m, m), dtype=np.float64)
    tot = 0.0
    for a in range(na):
        for j in range(m):
            for i in range(m):
                e[a, j, i] = math.exp(kappa * (S[a, j, i] - top))
                tot += e[a, j, i]
    cxx = cxy = cxt = cyy = cyt = ctt = 0.0
    two_pi = 2.0 * math.pi
    for a in range(na):
        dt = (p2 + angles[a] - a2 + math.pi) % two_pi - math.pi  # geometry.wrap's arithmetic
        if dt >= math.pi:
            dt = -math.pi
        for j in range(m):
            dy = p1 + off[j] - a1
            for i in range(m):
                w = e[a, j, i]
                dx = p0 + off[i] - a0
                cxx += dx * w * dx
                cxy += dx * w * dy
                cxt += dx * w * dt
                cyy += dy * w * dy
                cyt += dy * w * dt
                ctt += dt * w * dt
    cxx, cxy, cxt, cyy, cyt, ctt = cxx / tot, cxy / tot, cxt / tot, cyy / tot, cyt / tot, ctt / tot
    cxx += res * res / 12.0
    cyy += res * res / 12.0
    ctt += step * step / 12.0
    # the surface is in the grid frame; the pose's covariance in its own frame: J cov J^T, J = diag(R^T, 1)
    c, s = math.cos(a2), math.sin(a2)
    out = np.empty((3, 3), dtype=np.float64)
    out[0, 0] = c * c * cxx + 2.0 * c * s * cxy + s * s * cyy
    out[1, 1] = s * s * cxx - 2.0 * c * s * cxy + c * c * cyy
    out[0, 1] = out[1, 0] = -c * s * cxx + (c * c - s * s) * cxy + c * s * cyy
    out[0, 2] = out[2, 0] = c * cxt + s * cyt
    out[1, 2] = out[2, 1] = -s * cxt + c * cyt
    out[2, 2] = ctt
    return out
