"""Condensed (Delassus) operator in block-CSR: w^{αβ} = Σ_{sides on a shared body} G^α_s W_body G^β_s'ᵀ.

W_body is dense per body in its W numbering (deformable: the type's boundary block B Mhat⁻¹ Bᵀ, shared by
all instances of a type and clamp set; rigid: diag(1/m, 1/m, 1/I) with driven dofs zeroed). Only pairs
of contacts that share a body appear; the cost is Σ_bodies (contacts on the body)² small products.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .linalg import BlockCSR


@njit(cache=True)
def _row_pattern(nc, order, ent_contact, starts, side_body):
    """Block-CSR pattern of the Delassus operator (any block size): row α holds every contact sharing a body
    with α (once), columns sorted. `order`/`starts` list the (contact, side) entities of each body (see
    body_entities). Returns indptr, indices, diag_pos (position of the diagonal block of each row)."""
    marker = -np.ones(nc, dtype=np.int64)
    counts = np.zeros(nc, dtype=np.int64)
    for a in range(nc):
        for s in range(2):
            b = side_body[a, s]
            for e in range(starts[b], starts[b + 1]):
                c = ent_contact[order[e]]
                if marker[c] != a:
                    marker[c] = a
                    counts[a] += 1
    indptr = np.zeros(nc + 1, dtype=np.int64)
    for a in range(nc):
        indptr[a + 1] = indptr[a] + counts[a]
    indices = np.empty(indptr[nc], dtype=np.int64)
    diag_pos = np.empty(nc, dtype=np.int64)
    marker[:] = -1
    for a in range(nc):
        k = indptr[a]
        for s in range(2):
            b = side_body[a, s]
            for e in range(starts[b], starts[b + 1]):
                c = ent_contact[order[e]]
                if marker[c] != a:
                    marker[c] = a
                    indices[k] = c
                    k += 1
        row = indices[indptr[a]:indptr[a + 1]]
        row.sort()
        for kk in range(indptr[a], indptr[a + 1]):
            if indices[kk] == a:
                diag_pos[a] = kk
    return indptr, indices, diag_pos


def body_entities(side_body, nb: int):
    """(contact, side) entities grouped by body: ent_contact, ent_side (2 nc,), order (entities sorted by
    body, stable) and starts (nb + 1,): body b's entities are order[starts[b]:starts[b + 1]]."""
    nc = side_body.shape[0]
    ent_body = side_body.ravel()
    ent_contact = np.repeat(np.arange(nc, dtype=np.int64), 2)
    ent_side = np.tile(np.array([0, 1], dtype=np.int64), nc)
    order = np.argsort(ent_body, kind="stable").astype(np.int64)
    starts = np.zeros(nb + 1, dtype=np.int64)
    starts[1:] = np.cumsum(np.bincount(ent_body, minlength=nb))
    return ent_contact, ent_side, order, starts


@njit(cache=True)
def _assemble_rows(nc, order, ent_contact, ent_side, starts, side_body, side_dofs, side_G, W_flat, W_offset, W_size):
    """Row-by-row block-CSR assembly (2 x 2 blocks): the pattern of _row_pattern, duplicates (both sides on
    one body) summed in place; memory is the final number of blocks only."""
    indptr, indices, diag_pos = _row_pattern(nc, order, ent_contact, starts, side_body)
    blocks = np.zeros((indptr[nc], 2, 2))
    pos_of = -np.ones(nc, dtype=np.int64)
    GW = np.zeros((2, 4))
    for a in range(nc):
        for kk in range(indptr[a], indptr[a + 1]):
            pos_of[indices[kk]] = kk
        for s in range(2):
            b = side_body[a, s]
            off = W_offset[b]
            sz = W_size[b]
            for e in range(starts[b], starts[b + 1]):
                ee = order[e]
                c = ent_contact[ee]
                sc = ent_side[ee]
                for r in range(2):
                    for j in range(4):
                        GW[r, j] = 0.0
                for i in range(4):
                    di = side_dofs[a, s, i]
                    if di < 0:
                        continue
                    for j in range(4):
                        dj = side_dofs[c, sc, j]
                        if dj < 0:
                            continue
                        w = W_flat[off + di * sz + dj]
                        if w == 0.0:
                            continue
                        for r in range(2):
                            GW[r, j] += side_G[a, s, r, i] * w
                kk = pos_of[c]
                for r in range(2):
                    for q in range(2):
                        acc = 0.0
                        for j in range(4):
                            acc += GW[r, j] * side_G[c, sc, q, j]
                        blocks[kk, r, q] += acc
    return indptr, indices, blocks, diag_pos


def assemble(G, W_flat, W_offset, W_size, nb: int) -> BlockCSR:
    """Block-CSR Delassus operator from the G blocks and the per-body dense W (see module docstring)."""
    nc = G.side_body.shape[0]
    ent_contact, ent_side, order, starts = body_entities(G.side_body, nb)
    indptr, indices, blocks, diag_pos = _assemble_rows(
        nc, order, ent_contact, ent_side, starts, np.ascontiguousarray(G.side_body, dtype=np.int64),
        np.ascontiguousarray(G.side_dofs, dtype=np.int64), np.ascontiguousarray(G.side_G, dtype=np.float64),
        np.ascontiguousarray(W_flat, dtype=float), np.asarray(W_offset, dtype=np.int64),
        np.asarray(W_size, dtype=np.int64))
    return BlockCSR(indptr, indices, blocks, diag_pos)


def dense(B: BlockCSR) -> np.ndarray:
    return B.to_scipy().toarray()
