"""Broad phase of the contact detection, both dimensions: all pairs of axis-aligned boxes that overlap.

Boxes [lo_i, hi_i] (n, d), d = 2 (boundary edges, contact/detection_2d.py; bodies, find_overlap) or 3 (bodies,
contact/detection_3d.py), closed (touching counts). Uniform grid of cells of size `cell` from origin = min lo:
box i covers the cells floor((lo_i - origin) / cell) .. floor((hi_i - origin) / cell) per axis; the boxes of one
cell are tested pairwise and a pair (i, j), i < j, of different groups is reported only from the cell holding the
min corner max(lo_i, lo_j) of their intersection, so each pair once. Cost linear in n for boxes of comparable
size and cell about that size.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _cell_of(x, o, cell, n):
    return min(max(int((x - o) / cell), 0), n - 1)


@njit(cache=True)
def _grid_pairs(lo, hi, group, cell, origin, dims):
    n, d = lo.shape
    rng = np.empty((n, 2 * d), dtype=np.int64)
    cnt = np.ones(n, dtype=np.int64)
    for e in range(n):
        for c in range(d):
            rng[e, 2 * c] = _cell_of(lo[e, c], origin[c], cell, dims[c])
            rng[e, 2 * c + 1] = _cell_of(hi[e, c], origin[c], cell, dims[c])
            cnt[e] *= rng[e, 2 * c + 1] - rng[e, 2 * c] + 1
    total = cnt.sum()
    keys = np.empty(total, dtype=np.int64)
    vals = np.empty(total, dtype=np.int64)
    idx = np.empty(d, dtype=np.int64)
    k = 0
    for e in range(n):
        # the cells of box e, last axis fastest; key = (i_0 dims_1 + i_1) dims_2 + i_2 ...
        for c in range(d):
            idx[c] = rng[e, 2 * c]
        for _ in range(cnt[e]):
            key = 0
            for c in range(d):
                key = key * dims[c] + idx[c]
            keys[k] = key
            vals[k] = e
            k += 1
            c = d - 1
            while c >= 0:
                idx[c] += 1
                if idx[c] <= rng[e, 2 * c + 1]:
                    break
                idx[c] = rng[e, 2 * c]
                c -= 1
    order = np.argsort(keys, kind="mergesort")
    keys = keys[order]
    vals = vals[order]
    cap = 1024
    out = np.empty((cap, 2), dtype=np.int64)
    m = 0
    s = 0
    while s < total:
        t = s
        while t < total and keys[t] == keys[s]:
            t += 1
        for a in range(s, t):
            ea = vals[a]
            for b in range(a + 1, t):
                eb = vals[b]
                if group[ea] == group[eb]:
                    continue
                sep = False
                for c in range(d):
                    if lo[ea, c] > hi[eb, c] or lo[eb, c] > hi[ea, c]:
                        sep = True
                if sep:
                    continue
                key = 0
                for c in range(d):
                    key = key * dims[c] + _cell_of(max(lo[ea, c], lo[eb, c]), origin[c], cell, dims[c])
                if key != keys[s]:
                    continue
                if m == cap:
                    cap *= 2
                    new = np.empty((cap, 2), dtype=np.int64)
                    new[:m] = out[:m]
                    out = new
                out[m, 0] = min(ea, eb)
                out[m, 1] = max(ea, eb)
                m += 1
        s = t
    return out[:m]


def grid_pairs(lo, hi, group, cell: float, origin=None, top=None) -> np.ndarray:
    """(m, 2) int64: every pair (i, j), i < j, of overlapping boxes [lo_i, hi_i] (n, d) with group[i] != group[j],
    once, in the order of their grid cells (cells of size `cell`, see the module docstring); n >= 1.
    origin, top: the grid's corners (default: the boxes' min lo and max hi). A subset of the boxes on the grid of the
    whole set (the whole set's origin and top) gives the pairs of the subset in the whole set's relative order: each
    pair is reported from the same cell, and the boxes of a cell keep their increasing order."""
    lo = np.ascontiguousarray(lo, dtype=float)
    hi = np.ascontiguousarray(hi, dtype=float)
    origin = lo.min(axis=0) if origin is None else np.ascontiguousarray(origin, dtype=float)
    top = hi.max(axis=0) if top is None else np.asarray(top, dtype=float)
    dims = np.floor((top - origin) / cell).astype(np.int64) + 1
    return _grid_pairs(lo, hi, np.ascontiguousarray(group, dtype=np.int64), float(cell), origin, dims)


def body_boxes(lo, hi, body, nb: int):
    """(blo, bhi) (nb, d): each body's box, spanning the boxes lo/hi (n, d) of its items (nodes, edges, faces; body:
    the body of each item, in any order); +inf / -inf for a body without items. Min and max are exact: the same
    numbers whatever the grouping (reduceat over the items grouped by body, not ufunc.at: 0.1 s per 2D detection of the
    10^4-brick wall)."""
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    body = np.asarray(body, dtype=np.int64)
    if np.any(np.diff(body) < 0):  # (the scenes list the items grouped by body: no sort then)
        o = np.argsort(body, kind="stable")
        lo, hi, body = lo[o], hi[o], body[o]
    blo = np.full((nb, lo.shape[1]), np.inf)
    bhi = np.full((nb, lo.shape[1]), -np.inf)
    ids, first = np.unique(body, return_index=True)  # the bodies with items, their first item
    if ids.size:
        blo[ids] = np.minimum.reduceat(lo, first, axis=0)
        bhi[ids] = np.maximum.reduceat(hi, first, axis=0)
    return blo, bhi


def body_pairs(lo, hi, body, nb: int) -> np.ndarray:
    """(m, 2) int64: the pairs of bodies whose boxes overlap, a body's box spanning the boxes lo/hi (n, d) of its
    items (nodes, edges, faces; `body_boxes`): the grid broad phase on the bodies' boxes, cells of the median body
    size. Bodies without items have no box."""
    blo, bhi = body_boxes(lo, hi, body, nb)
    ids = np.flatnonzero(np.isfinite(blo[:, 0]))  # the bodies with items
    if ids.size < 2:
        return np.zeros((0, 2), dtype=np.int64)
    blo, bhi = blo[ids], bhi[ids]
    size = float(np.median(np.max(bhi - blo, axis=1)))
    return ids[grid_pairs(blo, bhi, ids, max(size, 1e-12))]


def near_bodies(pairs, bodies) -> np.ndarray:
    """(nb,) bool: the bodies of `bodies` (bool mask) and every body paired with one of them in `pairs` (m, 2) (e.g.
    `body_pairs` of boxes enlarged by the search distance: every body one of `bodies` can be in contact with)."""
    near = np.array(bodies, dtype=bool)
    mine = near[pairs]
    near[pairs[mine[:, 0], 1]] = True
    near[pairs[mine[:, 1], 0]] = True
    return near
