"""Condensed (Delassus) operator in block-CSR, both dimensions:

    w^{αβ} = Σ_{sides on a shared body} G^α_s W_body G^β_s'ᵀ

with d x d blocks (d = 2: local order (n, t); d = 3: (n, t, s)) and the G blocks of contact/kinematics_2d.py (2D)
or contact/kinematics_3d.py (3D).

W_body is dense per body in its W numbering (deformable: the type's boundary block B Mhat⁻¹ Bᵀ, shared by
all instances of a type and clamp set; rigid: diag(1/m, 1/m, 1/I) in 2D, the 6 x 6 inverse mass in 3D, with
driven dofs zeroed). Only pairs of contacts that share a body appear; the cost is Σ_bodies (contacts on the
body)² small products.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .errors import InputError
from .linalg import BlockCSR


@njit(cache=True)
def _row_pattern(nc, rows, dest, order, ent_contact, starts, side_body):
    """Block-CSR pattern of the rows `rows` of the Delassus operator (any block size): contact rows[i]'s row is
    output row dest[i] (a permutation of 0..len(rows)-1) and holds every contact sharing a body with it (once,
    columns = contact numbers 0..nc-1), columns sorted. `order`/`starts` list the (contact, side) entities of each
    body (see body_entities). Returns indptr, indices, diag_pos (position of the diagonal block of each output
    row)."""
    nr = rows.shape[0]
    marker = -np.ones(nc, dtype=np.int64)
    counts = np.zeros(nr, dtype=np.int64)
    for i in range(nr):
        a = rows[i]
        for s in range(2):
            b = side_body[a, s]
            for e in range(starts[b], starts[b + 1]):
                c = ent_contact[order[e]]
                if marker[c] != a:
                    marker[c] = a
                    counts[dest[i]] += 1
    indptr = np.zeros(nr + 1, dtype=np.int64)
    for i in range(nr):
        indptr[i + 1] = indptr[i] + counts[i]
    indices = np.empty(indptr[nr], dtype=np.int64)
    diag_pos = np.empty(nr, dtype=np.int64)
    marker[:] = -1
    for i in range(nr):
        a = rows[i]
        o = dest[i]
        k = indptr[o]
        for s in range(2):
            b = side_body[a, s]
            for e in range(starts[b], starts[b + 1]):
                c = ent_contact[order[e]]
                if marker[c] != a:
                    marker[c] = a
                    indices[k] = c
                    k += 1
        row = indices[indptr[o]:indptr[o + 1]]
        row.sort()
        for kk in range(indptr[o], indptr[o + 1]):
            if indices[kk] == a:
                diag_pos[o] = kk
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
def _assemble_rows(nc, rows, dest, order, ent_contact, ent_side, starts, side_body, side_dofs, side_G, W_flat,
                   W_offset, W_size):
    """Row-by-row block-CSR assembly of w^{αβ} = Σ_{shared body b} G^α_s W_b G^β_s'ᵀ (d x d blocks, d =
    side_G.shape[2]): the pattern of _row_pattern (contact rows[i]'s row is output row dest[i]); per side s of row
    α, GW = G^α_s W_b over all of body b's dofs once (GW[r, j] = Σ_i G^α_s[r, i] W_b[d_i, j], i in slot order),
    then one d x d product per entity (β, s') of b. Duplicates (β meeting α on both bodies) are summed in place;
    memory is the final number of blocks only.

    The loops are unrolled per dimension (a loop over d measured 2x slower in 3D; the 2D product runs over the 4
    slots of a 2D side, a loop over nd measured 20 % slower). Summation order of an entry,
    kept from the former per-dimension kernels so that outputs stay bitwise the same (the two orders differ
    only by rounding): 2D adds each entity's product Σ_j GW[r, d_j] G^β_s'[q, j] to the block as one sum, 3D
    adds its terms one by one."""
    d = side_G.shape[2]
    nd = side_dofs.shape[2]
    nr = rows.shape[0]
    indptr, indices, diag_pos = _row_pattern(nc, rows, dest, order, ent_contact, starts, side_body)
    blocks = np.zeros((indptr[nr], d, d))
    pos_of = -np.ones(nc, dtype=np.int64)
    maxsz = 0
    for b in range(W_size.shape[0]):
        maxsz = max(maxsz, W_size[b])
    GW = np.zeros((d, maxsz))
    for i in range(nr):
        a = rows[i]
        o = dest[i]
        for kk in range(indptr[o], indptr[o + 1]):
            pos_of[indices[kk]] = kk
        for s in range(2):
            b = side_body[a, s]
            off = W_offset[b]
            sz = W_size[b]
            for r in range(d):
                for j in range(sz):
                    GW[r, j] = 0.0
            for i in range(nd):
                di = side_dofs[a, s, i]
                if di < 0:
                    continue
                base = off + di * sz
                g0 = side_G[a, s, 0, i]
                g1 = side_G[a, s, 1, i]
                if d == 2:
                    for j in range(sz):
                        w = W_flat[base + j]
                        GW[0, j] += g0 * w
                        GW[1, j] += g1 * w
                else:
                    g2 = side_G[a, s, 2, i]
                    for j in range(sz):
                        w = W_flat[base + j]
                        GW[0, j] += g0 * w
                        GW[1, j] += g1 * w
                        GW[2, j] += g2 * w
            for e in range(starts[b], starts[b + 1]):
                ee = order[e]
                c = ent_contact[ee]
                sc = ent_side[ee]
                kk = pos_of[c]
                if d == 2:
                    for r in range(2):
                        for q in range(2):
                            acc = 0.0
                            for j in range(4):
                                dj = side_dofs[c, sc, j]
                                if dj >= 0:
                                    acc += GW[r, dj] * side_G[c, sc, q, j]
                            blocks[kk, r, q] += acc
                else:
                    for j in range(nd):
                        dj = side_dofs[c, sc, j]
                        if dj < 0:
                            continue
                        for r in range(3):
                            gw = GW[r, dj]
                            for q in range(3):
                                blocks[kk, r, q] += gw * side_G[c, sc, q, j]
    return indptr, indices, blocks, diag_pos


@njit(cache=True)
def _drop_zero_blocks(indptr, indices, blocks, diag_pos):
    """In place: the off-diagonal blocks whose entries are all exactly zero removed from block-CSR rows, the others
    moved forward in their order (indptr, diag_pos updated). Returns the number of blocks kept: the first ones of
    indices and blocks."""
    d = blocks.shape[1]
    w = 0
    start = indptr[0]
    for i in range(indptr.shape[0] - 1):
        end = indptr[i + 1]
        for kk in range(start, end):
            keep = kk == diag_pos[i]
            if not keep:
                for r in range(d):
                    for q in range(d):
                        if blocks[kk, r, q] != 0.0:
                            keep = True
            if keep:
                if kk == diag_pos[i]:
                    diag_pos[i] = w
                if w != kk:
                    indices[w] = indices[kk]
                    blocks[w] = blocks[kk]
                w += 1
        start = end
        indptr[i + 1] = w
    return w


def assemble(G, W_flat, W_offset, W_size, nb: int, rows=None, couplings: bool = False) -> BlockCSR:
    """Block-CSR Delassus operator w^{αβ} = G^α W H^β (d x d blocks, local order (n, t) or (n, t, s)) from the G
    blocks of either dimension (side_body (nc, 2), side_dofs (nc, 2, nd), side_G (nc, 2, d, nd)) and the per-body
    dense W stored flat (row-major square block of size W_size[b] at W_offset[b], in the body's W numbering).
    rows: the contacts (distinct, in any order) whose rows to assemble, None for all; row i of the result is row
    rows[i] of the whole operator, bitwise (columns: all nc contacts; diag_pos: the position of block (rows[i],
    rows[i])), so a rank of a distributed run assembles only the rows of its own contacts, and in the order it sweeps
    them (distributed/colour.sweep_plan). The rows are computed in increasing contact number whatever their output
    order (neighbouring contacts share bodies: their data is read while in cache; docs/scaling.md "Rows assembled in
    sweep order") and each is written at its output position.
    couplings: keep only the blocks that couple (the diagonal blocks and the off-diagonal blocks with a nonzero
    entry): the blocks of zeros between contacts that share only a body held in every dof (W_b = 0: a fixed
    foundation, O(contacts on it²) of them) are dropped as the rows are assembled, so the result is
    `distributed.colour.coupling_rows` of the whole operator, bitwise, without a second copy of the rows. The
    colour-order sweeps read these rows only; the other solvers keep the whole pattern (Newton's elimination order
    and NLGS's sums depend on it)."""
    nc = G.side_body.shape[0]
    d = G.side_G.shape[2]
    W_size = np.asarray(W_size, dtype=np.int64)
    if len(W_size) != nb or np.asarray(W_offset).shape != (nb,):
        raise InputError(f"W_offset / W_size: expected {nb} entries (one per body)")
    nd = G.side_dofs.shape[2]
    if d not in (2, 3) or G.side_G.shape[1:] != (2, d, nd) or (d == 2 and nd != 4):
        raise ValueError(f"G blocks: expected side_G (nc, 2, d, nd), d = 2 with nd = 4 or d = 3; got {G.side_G.shape}")
    if nc and np.any(G.side_dofs.max(axis=2) >= W_size[G.side_body]):
        raise InputError("G blocks: a dof index exceeds its body's W size")
    ent_contact, ent_side, order, starts = body_entities(G.side_body, nb)
    rows = np.arange(nc, dtype=np.int64) if rows is None else np.ascontiguousarray(rows, dtype=np.int64)
    dest = np.argsort(rows, kind="stable").astype(np.int64)  # computed in increasing contact number, row dest[i]
    srt = rows[dest]
    if srt.size and (srt[0] < 0 or srt[-1] >= nc or np.any(srt[1:] == srt[:-1])):
        raise ValueError(f"rows: expected distinct contact numbers in 0..{nc - 1}")
    indptr, indices, blocks, diag_pos = _assemble_rows(
        nc, srt, dest, order, ent_contact, ent_side, starts, np.ascontiguousarray(G.side_body, dtype=np.int64),
        np.ascontiguousarray(G.side_dofs, dtype=np.int64), np.ascontiguousarray(G.side_G, dtype=np.float64),
        np.ascontiguousarray(W_flat, dtype=float), np.asarray(W_offset, dtype=np.int64), W_size)
    if couplings:
        k = _drop_zero_blocks(indptr, indices, blocks, diag_pos)
        indices, blocks = indices[:k], blocks[:k]  # views: the dropped tail is not copied (nor freed)
    return BlockCSR(indptr, indices, blocks, diag_pos)


def dense(B: BlockCSR) -> np.ndarray:
    return B.to_scipy().toarray()
