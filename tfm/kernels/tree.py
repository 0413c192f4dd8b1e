"""Barnes-Hut quadtree for the planar 1/r sum u_t = sum_s f_s / |x_t - x_s|.

Barnes & Hut, "A hierarchical O(N log N) force-calculation algorithm", Nature 324
(1986). All points lie in one plane, so the tree is a quadtree over Morton keys.

Layout (flat arrays, as pytreegrav and pynndescent do):

* points are held in Morton order; a node owns the contiguous range
  ``start[k]:end[k]`` of them;
* nodes are stored in depth-first preorder, so the first child of node k is k + 1
  and ``skip[k]`` (the next node outside k's subtree) threads the walk: descending
  is ``k += 1``, accepting or finishing a leaf is ``k = skip[k]``; no stack;
* a node whose points all fall into one quadrant is not stored (the level is skipped),
  so every internal node has two to four children and there are < 2 n / leaf nodes;
* each node keeps the tight bounding box of its points; its geometric centre (the box
  centre) is the expansion centre; its size ``s`` is the box's longer side.

Moments are Cartesian, about the geometric centre (not the centre of mass, which is
undefined for forces of mixed sign): ``M_ij = sum f x'^i y'^j`` for i + j <= order,
stored at column ``n (n + 1) / 2 + j`` with n = i + j. Orders 1 to 4 are supported.

Evaluation walks the tree once per *group* of targets (a leaf of a target tree) and
applies every accepted node, or every point of an opened leaf (the exact near field),
to all targets of the group. A node is accepted when ``s < theta * d`` with d the
distance from its centre to the group's box (and its radius is < 0.75 d, which only
binds for theta > 1.06). For every target, every source of an accepted node then lies
within q d_t of the centre, q = min(theta / sqrt 2, 0.75), and the Legendre bound on
the truncated series gives, per target,

    |u_tree - u_exact| <= q^(order + 1) (1 + q) / (1 - q) * sum_s |f_s| / r_ts.

Determinism: the build and the moments are sequential; each
target's sum runs over the walk of its group in a fixed order. Nothing depends on the
number of threads.
"""
import numpy as np
from numba import njit, prange

from ..config import NUMBA_OPTS as _BASE_OPTS, PARALLEL_OPTS as _BASE_PARALLEL

# error_model="numpy": a division never raises, so the per-target loops vectorize
# (with the default "python" model each 1/sqrt(r2) carries a zero check and stays scalar).
NUMBA_OPTS = dict(_BASE_OPTS, error_model="numpy")
PARALLEL_OPTS = dict(_BASE_PARALLEL, error_model="numpy")

MORTON_BITS = 20          # per axis: 2^20 cells a side, far finer than any spring layout
MAX_ORDER = 4


def n_moments(order):
    return (order + 1) * (order + 2) // 2


# ------------------------------------------------------------------ Morton keys
@njit(**NUMBA_OPTS)
def _spread2(v):
    """Insert one zero bit between the low 31 bits of v (2D interleave)."""
    v &= 0x7FFFFFFF
    v = (v | (v << 16)) & 0x0000FFFF0000FFFF
    v = (v | (v << 8)) & 0x00FF00FF00FF00FF
    v = (v | (v << 4)) & 0x0F0F0F0F0F0F0F0F
    v = (v | (v << 2)) & 0x3333333333333333
    v = (v | (v << 1)) & 0x5555555555555555
    return v


@njit(**NUMBA_OPTS)
def morton_keys(x, y, x0, y0, side, bits):
    """2D Morton keys of the points in the square [x0, x0 + side)^2 (x in the low bit)."""
    n = x.size
    keys = np.empty(n, dtype=np.int64)
    top = (1 << bits) - 1
    scale = (1 << bits) / side
    for i in range(n):
        ix = int((x[i] - x0) * scale)
        iy = int((y[i] - y0) * scale)
        ix = min(max(ix, 0), top)
        iy = min(max(iy, 0), top)
        keys[i] = _spread2(np.int64(ix)) | (_spread2(np.int64(iy)) << 1)
    return keys


@njit(**NUMBA_OPTS)
def subset_order(order, sub, n_all):
    """Positions into ``sub`` (distinct spring indices) that put it in Morton order.

    ``order`` is the Morton order of all springs, computed once; a subset is sorted
    by one O(n_all) scan, with no comparison sort."""
    where = np.full(n_all, -1, dtype=np.int64)
    for s in range(sub.size):
        where[sub[s]] = s
    out = np.empty(sub.size, dtype=np.int64)
    k = 0
    for i in range(n_all):
        s = where[order[i]]
        if s >= 0:
            out[k] = s
            k += 1
    return out[:k]


# ------------------------------------------------------------------ tree build
@njit(**NUMBA_OPTS)
def _digit(key, level, bits):
    return (key >> (2 * (bits - 1 - level))) & 3


@njit(**NUMBA_OPTS)
def build_nodes(keys, leaf_size, bits):
    """Threaded preorder quadtree over sorted keys.

    Returns start, end, skip, parent (int64) and is_leaf (bool), one entry per node."""
    n = keys.size
    cap = 2 * n + 1                          # every internal node has >= 2 children
    start = np.empty(cap, dtype=np.int64)
    end = np.empty(cap, dtype=np.int64)
    parent = np.empty(cap, dtype=np.int64)
    leaf = np.zeros(cap, dtype=np.bool_)
    # explicit DFS stack of (start, end, level, parent); depth <= bits, 4 per level
    st_s = np.empty(4 * bits + 8, dtype=np.int64)
    st_e = np.empty(4 * bits + 8, dtype=np.int64)
    st_l = np.empty(4 * bits + 8, dtype=np.int64)
    st_p = np.empty(4 * bits + 8, dtype=np.int64)
    top = 0
    count = 0
    bounds = np.empty(5, dtype=np.int64)
    if n > 0:
        st_s[0] = 0
        st_e[0] = n
        st_l[0] = 0
        st_p[0] = -1
        top = 1
    while top > 0:
        top -= 1
        a = st_s[top]
        b = st_e[top]
        lev = st_l[top]
        k = count
        count += 1
        if count > cap:                      # cannot happen for < 2 n nodes; grow anyway
            cap2 = 2 * cap
            start = _grow(start, cap2)
            end = _grow(end, cap2)
            parent = _grow(parent, cap2)
            lb = np.zeros(cap2, dtype=np.bool_)
            lb[:cap] = leaf
            leaf = lb
            cap = cap2
        start[k] = a
        end[k] = b
        parent[k] = st_p[top]
        if b - a <= leaf_size:
            leaf[k] = True
            continue
        # skip levels at which every point falls into one quadrant
        while lev < bits and _digit(keys[a], lev, bits) == _digit(keys[b - 1], lev, bits):
            lev += 1
        if lev >= bits:                      # coincident cells: keep as one leaf
            leaf[k] = True
            continue
        # child ranges by binary search on the digit at this level; push 3..0
        bounds[0] = a
        bounds[4] = b
        for c in range(1, 4):
            lo = bounds[c - 1]
            hi = b
            while lo < hi:
                mid = (lo + hi) >> 1
                if _digit(keys[mid], lev, bits) < c:
                    lo = mid + 1
                else:
                    hi = mid
            bounds[c] = lo
        for c in range(3, -1, -1):
            if bounds[c + 1] > bounds[c]:
                st_s[top] = bounds[c]
                st_e[top] = bounds[c + 1]
                st_l[top] = lev + 1
                st_p[top] = k
                top += 1
    nn = count
    skip = np.ones(nn, dtype=np.int64)       # subtree sizes first
    for k in range(nn - 1, 0, -1):
        skip[parent[k]] += skip[k]
    for k in range(nn):
        skip[k] += k
    return start[:nn].copy(), end[:nn].copy(), skip, parent[:nn].copy(), leaf[:nn].copy()


@njit(**NUMBA_OPTS)
def _grow(a, cap):
    out = np.empty(cap, dtype=a.dtype)
    out[: a.size] = a
    return out


@njit(**NUMBA_OPTS)
def node_boxes(start, end, parent, leaf, px, py):
    """Tight bounding box of each node's points: (xmin, xmax, ymin, ymax) rows."""
    nn = start.size
    box = np.empty((nn, 4))
    for k in range(nn):
        box[k, 0] = np.inf
        box[k, 1] = -np.inf
        box[k, 2] = np.inf
        box[k, 3] = -np.inf
    for k in range(nn - 1, -1, -1):
        if leaf[k]:
            for i in range(start[k], end[k]):
                box[k, 0] = min(box[k, 0], px[i])
                box[k, 1] = max(box[k, 1], px[i])
                box[k, 2] = min(box[k, 2], py[i])
                box[k, 3] = max(box[k, 3], py[i])
        p = parent[k]
        if p >= 0:
            box[p, 0] = min(box[p, 0], box[k, 0])
            box[p, 1] = max(box[p, 1], box[k, 1])
            box[p, 2] = min(box[p, 2], box[k, 2])
            box[p, 3] = max(box[k, 3], box[p, 3])
    return box


@njit(**NUMBA_OPTS)
def node_geometry(box):
    """Centre (cx, cy), size s (longer side) and radius (half diagonal) of each node."""
    nn = box.shape[0]
    geo = np.empty((nn, 4))
    for k in range(nn):
        w = box[k, 1] - box[k, 0]
        h = box[k, 3] - box[k, 2]
        geo[k, 0] = 0.5 * (box[k, 0] + box[k, 1])
        geo[k, 1] = 0.5 * (box[k, 2] + box[k, 3])
        geo[k, 2] = max(w, h)
        geo[k, 3] = 0.5 * np.sqrt(w * w + h * h)
    return geo


# ------------------------------------------------------------------ moments
@njit(**NUMBA_OPTS)
def _binom(n, k):
    r = 1.0
    for i in range(k):
        r = r * (n - i) / (i + 1)
    return r


@njit(**NUMBA_OPTS)
def node_moments(start, end, skip, leaf, geo, px, py, pf, order):
    """Cartesian moments M_ij = sum f x'^i y'^j about each node's centre.

    Leaves from their points, internal nodes from their children by the binomial shift
    (children before parents). Serial: it costs a few percent of the walk, and one
    parallel region fewer per application matters on busy cores."""
    nn = start.size
    nm = (order + 1) * (order + 2) // 2
    mom = np.zeros((nn, nm))
    leaves = np.flatnonzero(leaf)
    for q in range(leaves.size):
        k = leaves[q]
        cx = geo[k, 0]
        cy = geo[k, 1]
        xp = np.empty(order + 1)
        yp = np.empty(order + 1)
        for i in range(start[k], end[k]):
            dx = px[i] - cx
            dy = py[i] - cy
            xp[0] = pf[i]
            yp[0] = 1.0
            for a in range(1, order + 1):
                xp[a] = xp[a - 1] * dx
                yp[a] = yp[a - 1] * dy
            c = 0
            for n in range(order + 1):
                for j in range(n + 1):
                    mom[k, c] += xp[n - j] * yp[j]
                    c += 1
    # binomial shift of each child's moments to its parent's centre
    xp = np.empty(order + 1)
    yp = np.empty(order + 1)
    for k in range(nn - 1, -1, -1):
        if leaf[k]:
            continue
        ch = k + 1
        while ch < skip[k]:
            ddx = geo[ch, 0] - geo[k, 0]
            ddy = geo[ch, 1] - geo[k, 1]
            xp[0] = 1.0
            yp[0] = 1.0
            for a in range(1, order + 1):
                xp[a] = xp[a - 1] * ddx
                yp[a] = yp[a - 1] * ddy
            c = 0
            for n in range(order + 1):
                for j in range(n + 1):
                    i = n - j
                    acc = 0.0
                    for a in range(i + 1):
                        for b in range(j + 1):
                            acc += (_binom(i, a) * _binom(j, b) * xp[i - a] * yp[j - b]
                                    * mom[ch, (a + b) * (a + b + 1) // 2 + b])
                    mom[k, c] += acc
                    c += 1
            ch = skip[ch]
    return mom


# ------------------------------------------------------------------ evaluation
@njit(**NUMBA_OPTS)
def _m2p(mom, k, order, cx, cy, gx, gy, acc, m):
    """Add node k's expansion (about (cx, cy)) at the m targets (gx, gy) of a group.

    Taylor series of 1/|d - s'| in the source offset s' (d = target - centre); the
    loops over targets are independent, so they vectorize."""
    m00 = mom[k, 0]
    m10 = mom[k, 1]
    m01 = mom[k, 2]
    if order == 1:
        for t in range(m):
            dx = gx[t] - cx
            dy = gy[t] - cy
            inv = 1.0 / np.sqrt(dx * dx + dy * dy)
            inv2 = inv * inv
            acc[t] += inv * (m00 + (m10 * dx + m01 * dy) * inv2)
        return
    m20 = mom[k, 3]
    m11 = mom[k, 4]
    m02 = mom[k, 5]
    tr = m20 + m02
    if order == 2:
        for t in range(m):
            dx = gx[t] - cx
            dy = gy[t] - cy
            inv = 1.0 / np.sqrt(dx * dx + dy * dy)
            inv2 = inv * inv
            qd = m20 * dx * dx + 2.0 * m11 * dx * dy + m02 * dy * dy
            acc[t] += inv * (m00 + inv2 * ((m10 * dx + m01 * dy) - 0.5 * tr + 1.5 * qd * inv2))
        return
    m30 = mom[k, 6]
    m21 = mom[k, 7]
    m12 = mom[k, 8]
    m03 = mom[k, 9]
    tx3 = m30 + m12
    ty3 = m21 + m03
    if order == 3:
        for t in range(m):
            dx = gx[t] - cx
            dy = gy[t] - cy
            dx2 = dx * dx
            dy2 = dy * dy
            inv = 1.0 / np.sqrt(dx2 + dy2)
            inv2 = inv * inv
            qd = m20 * dx2 + 2.0 * m11 * dx * dy + m02 * dy2
            oc = (m30 * dx2 + 3.0 * m12 * dy2) * dx + (3.0 * m21 * dx2 + m03 * dy2) * dy
            acc[t] += inv * (m00 + inv2 * ((m10 * dx + m01 * dy) - 0.5 * tr
                                           + inv2 * (1.5 * qd - 1.5 * (tx3 * dx + ty3 * dy)
                                                     + 2.5 * oc * inv2)))
        return
    m40 = mom[k, 10]
    m31 = mom[k, 11]
    m22 = mom[k, 12]
    m13 = mom[k, 13]
    m04 = mom[k, 14]
    wxx = m40 + m22
    wxy = m31 + m13
    wyy = m22 + m04
    z4 = m40 + 2.0 * m22 + m04
    for t in range(m):
        dx = gx[t] - cx
        dy = gy[t] - cy
        dx2 = dx * dx
        dy2 = dy * dy
        dxy = dx * dy
        inv = 1.0 / np.sqrt(dx2 + dy2)
        inv2 = inv * inv
        qd = m20 * dx2 + 2.0 * m11 * dxy + m02 * dy2
        oc = (m30 * dx2 + 3.0 * m12 * dy2) * dx + (3.0 * m21 * dx2 + m03 * dy2) * dy
        hx = (m40 * dx2 * dx2 + 4.0 * m31 * dx2 * dxy + 6.0 * m22 * dxy * dxy
              + 4.0 * m13 * dxy * dy2 + m04 * dy2 * dy2)
        w4 = wxx * dx2 + 2.0 * wxy * dxy + wyy * dy2
        acc[t] += inv * (m00 + inv2 * ((m10 * dx + m01 * dy) - 0.5 * tr + 0.375 * z4 * inv2
                                       + inv2 * (1.5 * qd - 1.5 * (tx3 * dx + ty3 * dy)
                                                 - 3.75 * w4 * inv2
                                                 + inv2 * (2.5 * oc + 4.375 * hx * inv2))))


@njit(**NUMBA_OPTS)
def _p2p(px, py, pf, a, b, gx, gy, acc, m):
    """Exact near field: sources a:b at the m targets; a coincident pair (a spring and
    itself) is skipped here, its self term is added by the caller."""
    for j in range(a, b):
        xj = px[j]
        yj = py[j]
        fj = pf[j]
        for t in range(m):
            dx = gx[t] - xj
            dy = gy[t] - yj
            r2 = dx * dx + dy * dy
            w = fj if r2 > 0.0 else 0.0
            acc[t] += w / np.sqrt(r2 if r2 > 0.0 else 1.0)


@njit(**PARALLEL_OPTS)
def evaluate(start, end, skip, leaf, geo, mom, order, theta, px, py, pf,
             gstart, gend, gbox, tx, ty, tself):
    """u at the targets (in target-tree order), one group of targets per iteration.

    Sources: points px, py, pf in source-tree order. Groups: target ranges gstart:gend
    with boxes gbox (xmin, xmax, ymin, ymax). ``tself`` (C_tt F_t, zero where the
    target carries no force) starts each target's sum; then the walk, in tree order."""
    nt = tx.size
    out = np.empty(nt)
    nn = start.size
    th2 = theta * theta
    for g in prange(gstart.size):
        g0 = gstart[g]
        m = gend[g] - g0
        gx = np.empty(m)
        gy = np.empty(m)
        acc = np.empty(m)
        for t in range(m):
            gx[t] = tx[g0 + t]
            gy[t] = ty[g0 + t]
            acc[t] = tself[g0 + t]
        bx0 = gbox[g, 0]
        bx1 = gbox[g, 1]
        by0 = gbox[g, 2]
        by1 = gbox[g, 3]
        k = 0
        while k < nn:
            cx = geo[k, 0]
            cy = geo[k, 1]
            ex = max(bx0 - cx, cx - bx1, 0.0)
            ey = max(by0 - cy, cy - by1, 0.0)
            d2 = ex * ex + ey * ey
            s = geo[k, 2]
            rad = geo[k, 3]
            if s * s < th2 * d2 and rad * rad < 0.5625 * d2:
                _m2p(mom, k, order, cx, cy, gx, gy, acc, m)
                k = skip[k]
            elif leaf[k]:
                _p2p(px, py, pf, start[k], end[k], gx, gy, acc, m)
                k = skip[k]
            else:
                k += 1
        for t in range(m):
            out[g0 + t] = acc[t]
    return out


# ------------------------------------------------------------------ neighbour list
@njit(**PARALLEL_OPTS)
def csr_apply(indptr, indices, weights, diag, ffull, tgt):
    """u[t] = diag[i] F_i + sum_j w_ij F_j over i's neighbour list (i = tgt[t]).

    The truncated kernel as a sparse matrix: each row summed in its stored order."""
    out = np.empty(tgt.size)
    for t in prange(tgt.size):
        i = tgt[t]
        acc = diag[i] * ffull[i]
        for q in range(indptr[i], indptr[i + 1]):
            acc += weights[q] * ffull[indices[q]]
        out[t] = acc
    return out
