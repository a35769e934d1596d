"""Condensed (Delassus) operator in block-CSR: w^{αβ} = Σ_{sides on a shared body} G^α_s W_body G^β_s'ᵀ.

W_body is dense per body in its W numbering (deformable: the type's boundary block B Mhat⁻¹ Bᵀ, shared by
all instances of a type and clamp set; rigid: diag(1/m, 1/m, 1/I) with driven dofs zeroed). Only pairs
of contacts that share a body appear; the cost is Σ_bodies (contacts on the body)² small products.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .solver.nlgs import BlockCSR


@njit(cache=True)
def _pair_blocks(order, ent_contact, ent_side, ent_body, starts, side_dofs, side_G, W_flat, W_offset, W_size):
    nb = starts.shape[0] - 1
    total = 0
    for b in range(nb):
        m = starts[b + 1] - starts[b]
        total += m * m
    rows = np.empty(total, dtype=np.int64)
    cols = np.empty(total, dtype=np.int64)
    blocks = np.zeros((total, 2, 2))
    k = 0
    GW = np.zeros((2, 4))
    for b in range(nb):
        off = W_offset[b]
        sz = W_size[b]
        for ia in range(starts[b], starts[b + 1]):
            ea = order[ia]
            a = ent_contact[ea]
            sa = ent_side[ea]
            # GW = G_a W[dofs_a, :] restricted later to dofs_c
            for ic in range(starts[b], starts[b + 1]):
                ec = order[ic]
                c = ent_contact[ec]
                sc = ent_side[ec]
                for r in range(2):
                    for j in range(4):
                        GW[r, j] = 0.0
                # (G_a W G_c^T)[r, q] = sum_i sum_j G_a[r, i] W[d_a[i], d_c[j]] G_c[q, j]
                for i in range(4):
                    di = side_dofs[a, sa, i]
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
                            GW[r, j] += side_G[a, sa, r, i] * w
                for r in range(2):
                    for q in range(2):
                        acc = 0.0
                        for j in range(4):
                            acc += GW[r, j] * side_G[c, sc, q, j]
                        blocks[k, r, q] = acc
                rows[k] = a
                cols[k] = c
                k += 1
    return rows, cols, blocks


def assemble(G, W_flat, W_offset, W_size, nb: int) -> BlockCSR:
    nc = G.side_body.shape[0]
    ent_body = G.side_body.ravel()
    ent_contact = np.repeat(np.arange(nc, dtype=np.int64), 2)
    ent_side = np.tile(np.array([0, 1], dtype=np.int64), nc)
    order = np.argsort(ent_body, kind="stable").astype(np.int64)
    starts = np.zeros(nb + 1, dtype=np.int64)
    starts[1:] = np.cumsum(np.bincount(ent_body, minlength=nb))
    rows, cols, blocks = _pair_blocks(order, ent_contact, ent_side, ent_body, starts, G.side_dofs, G.side_G,
                                      np.ascontiguousarray(W_flat, dtype=float),
                                      np.asarray(W_offset, dtype=np.int64), np.asarray(W_size, dtype=np.int64))
    # ensure diagonal, then sum duplicates (contacts sharing two bodies) and sort by (row, col)
    rows = np.concatenate([rows, np.arange(nc)])
    cols = np.concatenate([cols, np.arange(nc)])
    blocks = np.concatenate([blocks, np.zeros((nc, 2, 2))])
    key = rows * max(nc, 1) + cols
    o = np.argsort(key, kind="stable")
    key, blocks = key[o], blocks[o]
    first = np.ones(len(key), dtype=bool)
    first[1:] = key[1:] != key[:-1]
    starts_u = np.flatnonzero(first)
    summed = np.add.reduceat(blocks, starts_u, axis=0) if len(key) else blocks
    ukey = key[starts_u]
    r = ukey // max(nc, 1)
    c = ukey % max(nc, 1)
    indptr = np.zeros(nc + 1, dtype=np.int64)
    indptr[1:] = np.cumsum(np.bincount(r, minlength=nc))
    diag_pos = np.flatnonzero(r == c).astype(np.int64)
    return BlockCSR(indptr, c.astype(np.int64), np.ascontiguousarray(summed), diag_pos)


def dense(B: BlockCSR) -> np.ndarray:
    return B.to_scipy().toarray()
