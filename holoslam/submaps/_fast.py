"""Compiled kernels of the front end (numba, ``cache=True``): exact nearest neighbours on a bucket grid.

ICP (``localize.register_points``) asks, every iteration, for the nearest map point of each scan point within
a gate. :func:`grid_nearest` answers exactly what scipy's ``cKDTree.query(x, k=1, distance_upper_bound=gate)``
answers (a point counts when its squared distance is below gate squared; the distance is the square root of
``dx * dx + dy * dy``), searching the map's buckets in rings of growing Chebyshev radius around the query's
bucket and stopping once no unvisited bucket can hold a nearer point or one within the gate. Without the
k-d tree's per-call overhead this is several times faster for the few hundred points of a scan. Two map
points at exactly the same distance may be told apart differently (the lower index wins here).

Imported lazily by ``localize.NearestIndex``; the first call compiles (a few seconds, once per machine), later
processes load the kernel from numba's on-disk cache next to this file.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from holoslam._common_fast import argsort_stable, csr_group
from holoslam._jit import JIT


@nb.njit(**JIT)
def bucket_grid(px, py, cell, max_cells):  # pragma: no cover - compiled
    """Buckets of the points (px, py): (x0, y0, cell, nx, ny, start (nx * ny + 1,), order (M,)), the points of
    bucket b being ``order[start[b]:start[b + 1]]`` in index order. The cell doubles while the extent would
    need more than ``max_cells`` buckets (a few far outliers)."""
    m = px.size
    x0, y0, x1, y1 = 0.0, 0.0, 0.0, 0.0
    if m:
        x0, y0, x1, y1 = px[0], py[0], px[0], py[0]
        for k in range(1, m):
            x0, x1 = min(x0, px[k]), max(x1, px[k])
            y0, y1 = min(y0, py[k]), max(y1, py[k])
    while (math.floor((x1 - x0) / cell) + 1.0) * (math.floor((y1 - y0) / cell) + 1.0) > max_cells:
        cell *= 2.0
    nx, ny = int(math.floor((x1 - x0) / cell)) + 1, int(math.floor((y1 - y0) / cell)) + 1
    bucket = np.empty(m, dtype=np.int64)
    for k in range(m):
        cx = min(max(int(math.floor((px[k] - x0) / cell)), 0), nx - 1)
        cy = min(max(int(math.floor((py[k] - y0) / cell)), 0), ny - 1)
        bucket[k] = cy * nx + cx
    start, order = csr_group(bucket, nx * ny)
    return x0, y0, cell, nx, ny, start, order


@nb.njit(**JIT)
def grid_nearest(qx, qy, px, py, x0, y0, cell, nx, ny, start, order, gate, out_j, out_d):  # pragma: no cover
    """For every query (qx[i], qy[i]): out_j[i] the nearest of the points (px, py) bucketed by
    :func:`bucket_grid` and out_d[i] its distance when the squared distance is below gate**2, else
    out_j[i] = len(px) and out_d[i] = inf (cKDTree's convention)."""
    m = px.size
    g2 = gate * gate
    for i in range(qx.size):
        x, y = qx[i], qy[i]
        if not (math.isfinite(x) and math.isfinite(y)):
            out_j[i] = m
            out_d[i] = np.inf
            continue
        fx, fy = (x - x0) / cell, (y - y0) / cell
        # the query's bucket (may lie outside the grid), clamped far outside so the ring loop stays finite
        cx = int(math.floor(min(max(fx, -1e9), 1e9)))
        cy = int(math.floor(min(max(fy, -1e9), 1e9)))
        best, bj = np.inf, m
        r = 0
        while True:
            j_lo, j_hi = max(cy - r, 0), min(cy + r, ny - 1)
            for jj in range(j_lo, j_hi + 1):
                edge_row = jj == cy - r or jj == cy + r
                i_lo, i_hi = max(cx - r, 0), min(cx + r, nx - 1)
                ii = i_lo
                while ii <= i_hi:
                    if edge_row or ii == cx - r or ii == cx + r:
                        b = jj * nx + ii
                        for k in range(start[b], start[b + 1]):
                            p = order[k]
                            dx = x - px[p]
                            dy = y - py[p]
                            s = dx * dx + dy * dy
                            if s < best or (s == best and p < bj):
                                best, bj = s, p
                        ii += 1
                    else:  # inside the ring: already visited, jump to its right column
                        ii = cx + r if cx + r <= i_hi else i_hi + 1
            # every point outside the square of rings 0..r is at least `lb` away
            lb = min(x - (x0 + (cx - r) * cell), (x0 + (cx + r + 1) * cell) - x,
                     y - (y0 + (cy - r) * cell), (y0 + (cy + r + 1) * cell) - y) - 1e-9
            covered = cx - r <= 0 and cx + r >= nx - 1 and cy - r <= 0 and cy + r >= ny - 1
            if covered or lb >= gate or (lb > 0.0 and best <= lb * lb):
                break
            r += 1
        if best < g2:
            out_j[i] = bj
            out_d[i] = math.sqrt(best)
        else:
            out_j[i] = m
            out_d[i] = np.inf


@nb.njit(**JIT)
def icp_terms(px, py, c, s, tx, ty, qx, qy, nqx, nqy, x0, y0, cell, nx, ny, start, order, gate, huber,
              j, d, J, w, r):  # pragma: no cover - compiled
    """One point-to-line ICP iteration's terms, the arithmetic of ``localize.register_points`` point by point:
    the scan points moved by (tx, ty, angle with cosine c and sine s), their nearest map points within ``gate``
    (j, d as :func:`grid_nearest`), and for the m matched ones in scan order the rows of the Jacobian J (m, 3)
    of the left perturbation, the residuals r along the map normals and their Huber weights w. Returns m."""
    n = px.size
    pax = np.empty(n, dtype=np.float64)
    pay = np.empty(n, dtype=np.float64)
    for i in range(n):
        pax[i] = tx + c * px[i] - s * py[i]
        pay[i] = ty + s * px[i] + c * py[i]
    grid_nearest(pax, pay, qx, qy, x0, y0, cell, nx, ny, start, order, gate, j, d)
    g2 = gate * gate
    m = 0
    for i in range(n):
        if d[i] * d[i] < g2:
            k = j[i]
            nx_, ny_ = nqx[k], nqy[k]
            rr = nx_ * (pax[i] - qx[k]) + ny_ * (pay[i] - qy[k])
            J[m, 0] = nx_
            J[m, 1] = ny_
            J[m, 2] = nx_ * -pay[i] + ny_ * pax[i]
            ar = abs(rr)
            w[m] = 1.0 if ar <= huber else huber / max(ar, 1e-12)
            r[m] = rr
            m += 1
    return m


@nb.njit(**JIT)
def free_counts(tx, ty, ca, sa, nk, step, lo_x, lo_y, resolution, W, H):  # pragma: no cover - compiled
    """How many free samples fall in each cell of an H x W grid (row-major) with lower-left corner (lo_x, lo_y):
    ray i samples tx[i] + d * ca[i], ty[i] + d * sa[i] at d = k * step for k < nk[i] (``segment.local_grid``'s
    arithmetic, without the array of samples)."""
    out = np.zeros(H * W, dtype=np.int64)
    for i in range(tx.size):
        for k in range(nk[i]):
            d = k * step
            c = int(math.floor((tx[i] + d * ca[i] - lo_x) / resolution))
            r = int(math.floor((ty[i] + d * sa[i] - lo_y) / resolution))
            out[r * W + c] += 1
    return out


@nb.njit(**JIT)
def split_pieces(x, y, run_start, run_end, tol):  # pragma: no cover - compiled
    """Split-and-merge's split step (``features._split``, the same arithmetic) on every run [run_start[i],
    run_end[i]) of the ordered points (x, y) at once: (start, end) of the pieces, sorted by start."""
    ps = np.empty(x.size + run_start.size, dtype=np.int64)
    pe = np.empty(x.size + run_start.size, dtype=np.int64)
    n = 0
    stack = np.empty((x.size + 2, 2), dtype=np.int64)
    for i in range(run_start.size):
        stack[0, 0], stack[0, 1] = run_start[i], run_end[i]
        top = 1
        while top:
            top -= 1
            a, b = stack[top, 0], stack[top, 1]
            if b - a < 3:
                ps[n], pe[n] = a, b
                n += 1
                continue
            x0, y0 = x[a], y[a]
            chx, chy = x[b - 1] - x0, y[b - 1] - y0
            L = np.hypot(chx, chy)
            k, best = 0, -np.inf
            for t in range(b - a):
                sx, sy = x[a + t] - x0, y[a + t] - y0
                dist = abs(sx * chy - sy * chx) / L if L > 1e-9 else np.hypot(sx, sy)
                if dist != dist:  # NaN: np.argmax stops at the first one (and NaN > tol is False)
                    k, best = t, dist
                    break
                if dist > best:
                    k, best = t, dist
            if best > tol and 0 < k < b - a - 1:
                stack[top, 0], stack[top, 1] = a + k, b
                stack[top + 1, 0], stack[top + 1, 1] = a, a + k + 1
                top += 2
            else:
                ps[n], pe[n] = a, b
                n += 1
    key = np.empty(n, dtype=np.float64)  # the starts as float64 (exact below 2**53): the branch and bound's argsort_stable, one
    for i in range(n):  # specialisation of it to compile instead of two
        key[i] = ps[i]
    order = argsort_stable(key)  # np.argsort(ps[:n], kind="mergesort")
    return ps[:n][order], pe[:n][order]
