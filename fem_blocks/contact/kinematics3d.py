"""3D contact kinematics G^α (docs/method.md §3): local relative velocity from body velocities, and its transpose H.

Each contact α has two sides s = 0 (candidate, sign +) and s = 1 (antagonist, sign −):

    v_loc^α = Σ_s side_G[α, s] @ u_{side_body[α, s]}[side_dofs[α, s]]      (normal first: (v_N, v_T, v_S))

with u a body's velocity in its *W numbering*:
* deformable body: interleaved nodal dofs 3*i + c of its W numbering, i = bnode_index_flat[bnode_offset[b] +
  node] (identity numbering i = node if no index is given), in the body's type frame: for the interpolation
  weights w_k of the contact point on the nodes k and the rotation R (type frame -> global), the 3 x 3 block
  of node k is ±w_k [nᵀR ; tᵀR ; sᵀR] (12 columns for a quad, padding dofs −1);
* rigid body: 6 dofs (v_x, v_y, v_z, ω_x, ω_y, ω_z) at its reference point c, the velocity of a material
  point x being v + ω × (x − c), so the row of a frame vector f is [fᵀ, ((x − c) × f)ᵀ]; the candidate
  point is x_c = point, the antagonist point x_a = point − gap·n.
H = Gᵀ: `accumulate_impulse` scatters Σ_α H^α P^α into the flat W-numbered vector (u_offset[b] locates body
b), so that (G u)·P = u·(H P) exactly.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..delassus import _row_pattern, body_entities
from ..errors import InputError
from . import kinematics as _kin2

ND = 12  # padded dofs per side: 4 nodes x 3 components (rigid: 6)


@dataclass
class GBlocks3D:
    side_body: np.ndarray  # (nc, 2) int64
    side_dofs: np.ndarray  # (nc, 2, 12) int64, -1 padding
    side_G: np.ndarray     # (nc, 2, 3, 12) float64, rows (n, t, s)


@njit(cache=True)
def _build(side_body, nodes, wts, xs, frame, kind, rot, center, bidx, boff, identity, side_dofs, side_G):
    """Fills side_dofs/side_G; returns -1, or the index of a contact referencing a non-boundary node."""
    nc = side_body.shape[0]
    for a in range(nc):
        for s in range(2):
            sign = 1.0 if s == 0 else -1.0
            b = side_body[a, s]
            if kind[b] == 0:
                for k in range(4):
                    nd = nodes[a, s, k]
                    if nd < 0:
                        continue
                    bi = nd if identity else bidx[boff[b] + nd]
                    if bi < 0:
                        return a
                    w = sign * wts[a, s, k]
                    for c in range(3):
                        side_dofs[a, s, 3 * k + c] = 3 * bi + c
                    for r in range(3):
                        for c in range(3):
                            # (f^T R)_c = sum_i f_i R[i, c]
                            acc = 0.0
                            for i in range(3):
                                acc += frame[a, r, i] * rot[b, i, c]
                            side_G[a, s, r, 3 * k + c] = w * acc
            else:
                d0 = xs[a, s, 0] - center[b, 0]
                d1 = xs[a, s, 1] - center[b, 1]
                d2 = xs[a, s, 2] - center[b, 2]
                for j in range(6):
                    side_dofs[a, s, j] = j
                for r in range(3):
                    f0 = frame[a, r, 0]
                    f1 = frame[a, r, 1]
                    f2 = frame[a, r, 2]
                    side_G[a, s, r, 0] = sign * f0
                    side_G[a, s, r, 1] = sign * f1
                    side_G[a, s, r, 2] = sign * f2
                    side_G[a, s, r, 3] = sign * (d1 * f2 - d2 * f1)
                    side_G[a, s, r, 4] = sign * (d2 * f0 - d0 * f2)
                    side_G[a, s, r, 5] = sign * (d0 * f1 - d1 * f0)
    return -1


def build_G(cs, kind, rot=None, center=None, bnode_index_flat=None, bnode_offset=None) -> GBlocks3D:
    """G blocks of a ContactSet3D. kind[b] 0 deformable / 1 rigid; rot (nb, 3, 3) type frame -> global of the
    deformable bodies (default identity); center (nb, 3) reference point of the rigid bodies; optional
    boundary numbering (bnode_index_flat, bnode_offset) as in the 2D scene (default: dof 3*node + c)."""
    nc = len(cs.gap)
    kind = np.ascontiguousarray(kind, dtype=np.int64)
    nb = len(kind)
    rot = np.tile(np.eye(3), (nb, 1, 1)) if rot is None else np.ascontiguousarray(rot, dtype=float)
    center = np.zeros((nb, 3)) if center is None else np.ascontiguousarray(center, dtype=float)
    if rot.shape != (nb, 3, 3):
        raise InputError(f"rot: expected shape ({nb}, 3, 3), got {rot.shape}")
    if center.shape != (nb, 3):
        raise InputError(f"center: expected shape ({nb}, 3), got {center.shape}")
    identity = bnode_index_flat is None
    bidx = np.zeros(1, dtype=np.int64) if identity else np.ascontiguousarray(bnode_index_flat, dtype=np.int64)
    boff = np.zeros(nb, dtype=np.int64) if identity else np.ascontiguousarray(bnode_offset, dtype=np.int64)
    side_body = np.ascontiguousarray(np.stack([cs.cand_body, cs.ant_body], axis=1), dtype=np.int64)
    if nc and (side_body.min() < 0 or side_body.max() >= nb):
        raise InputError(f"contact bodies: expected body ids in [0, {nb})")
    nodes = np.ascontiguousarray(np.stack([cs.cand_nodes, cs.ant_nodes], axis=1), dtype=np.int64)
    wts = np.ascontiguousarray(np.stack([cs.cand_w, cs.ant_w], axis=1), dtype=float)
    xs = np.ascontiguousarray(np.stack([cs.point, cs.point - cs.gap[:, None] * cs.n], axis=1), dtype=float)
    frame = np.ascontiguousarray(np.stack([cs.n, cs.t, cs.s], axis=1), dtype=float)
    side_dofs = -np.ones((nc, 2, ND), dtype=np.int64)
    side_G = np.zeros((nc, 2, 3, ND))
    bad = _build(side_body, nodes, wts, xs, frame, kind, rot, center, bidx, boff, identity, side_dofs, side_G)
    if bad >= 0:
        raise InputError(f"contact {bad}: references a node that is not a boundary node of its body")
    return GBlocks3D(side_body, side_dofs, side_G)


@njit(cache=True)
def _local_velocity(side_body, side_dofs, side_G, U, U_offset, out):
    nc = side_body.shape[0]
    for a in range(nc):
        v0 = 0.0
        v1 = 0.0
        v2 = 0.0
        for s in range(2):
            off = U_offset[side_body[a, s]]
            for j in range(side_dofs.shape[2]):
                d = side_dofs[a, s, j]
                if d >= 0:
                    u = U[off + d]
                    v0 += side_G[a, s, 0, j] * u
                    v1 += side_G[a, s, 1, j] * u
                    v2 += side_G[a, s, 2, j] * u
        out[a, 0] = v0
        out[a, 1] = v1
        out[a, 2] = v2


@njit(cache=True)
def _accumulate(side_body, side_dofs, side_G, P, U_offset, out):
    nc = side_body.shape[0]
    for a in range(nc):
        for s in range(2):
            off = U_offset[side_body[a, s]]
            for j in range(side_dofs.shape[2]):
                d = side_dofs[a, s, j]
                if d >= 0:
                    out[off + d] += side_G[a, s, 0, j] * P[a, 0] + side_G[a, s, 1, j] * P[a, 1] \
                        + side_G[a, s, 2, j] * P[a, 2]


def local_velocity(G: GBlocks3D, U_flat, U_offset) -> np.ndarray:
    """(nc, 3) local velocities (v_N, v_T, v_S) = G u from the flat W-numbered body velocities."""
    return _kin2.local_velocity(G, U_flat, U_offset, _local_velocity)


def accumulate_impulse(G: GBlocks3D, P, n_total: int, U_offset) -> np.ndarray:
    """H P: flat W-numbered vector of the contact impulses (nc, 3) on the bodies."""
    return _kin2.accumulate_impulse(G, P, n_total, U_offset, _accumulate)


# ----------------------------------------------------------------------------- Delassus operator (3D)
@njit(cache=True)
def _assemble_rows3(nc, order, ent_contact, ent_side, starts, side_body, side_dofs, side_G, W_flat, W_offset,
                    W_size):
    """Row-by-row block-CSR assembly of w^{ab} = Σ_{shared body} G^a_s W_b G^b_s'ᵀ (3 x 3 blocks), columns
    sorted (pattern: delassus._row_pattern), duplicates (both sides on one body) summed in place."""
    nd = side_dofs.shape[2]
    indptr, indices, diag_pos = _row_pattern(nc, order, ent_contact, starts, side_body)
    blocks = np.zeros((indptr[nc], 3, 3))
    pos_of = -np.ones(nc, dtype=np.int64)
    maxsz = 0
    for b in range(W_size.shape[0]):
        maxsz = max(maxsz, W_size[b])
    GW = np.zeros((3, maxsz))
    for a in range(nc):
        for kk in range(indptr[a], indptr[a + 1]):
            pos_of[indices[kk]] = kk
        for s in range(2):
            b = side_body[a, s]
            off = W_offset[b]
            sz = W_size[b]
            # GW = G^a_s W_b over all of body b's dofs (once per side), then one 3 x 3 product per neighbour
            for r in range(3):
                for j in range(sz):
                    GW[r, j] = 0.0
            for i in range(nd):
                di = side_dofs[a, s, i]
                if di < 0:
                    continue
                g0 = side_G[a, s, 0, i]
                g1 = side_G[a, s, 1, i]
                g2 = side_G[a, s, 2, i]
                base = off + di * sz
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
                for j in range(nd):
                    dj = side_dofs[c, sc, j]
                    if dj < 0:
                        continue
                    for r in range(3):
                        gw = GW[r, dj]
                        for q in range(3):
                            blocks[kk, r, q] += gw * side_G[c, sc, q, j]
    return indptr, indices, blocks, diag_pos


def assemble_delassus(G: GBlocks3D, W_flat, W_offset, W_size, nb: int):
    """Block-CSR 3D Delassus operator w^{ab} = G^a W H^b (3 x 3 blocks, local order (n, t, s)) from the G blocks
    and the per-body dense W stored flat (row-major square block of size W_size[b] at W_offset[b]; deformable:
    3 dofs per boundary node, rigid: 6 x 6). Returns solver.nlgs.BlockCSR."""
    from ..solver.nlgs import BlockCSR

    nc = G.side_body.shape[0]
    W_size = np.asarray(W_size, dtype=np.int64)
    if len(W_size) != nb or np.asarray(W_offset).shape != (nb,):
        raise InputError(f"W_offset / W_size: expected {nb} entries (one per body)")
    if nc and np.any(G.side_dofs.max(axis=2) >= W_size[G.side_body]):
        raise InputError("G blocks: a dof index exceeds its body's W size")
    ent_contact, ent_side, order, starts = body_entities(G.side_body, nb)
    indptr, indices, blocks, diag_pos = _assemble_rows3(
        nc, order, ent_contact, ent_side, starts, np.ascontiguousarray(G.side_body, dtype=np.int64),
        np.ascontiguousarray(G.side_dofs, dtype=np.int64), np.ascontiguousarray(G.side_G, dtype=np.float64),
        np.ascontiguousarray(W_flat, dtype=float), np.asarray(W_offset, dtype=np.int64), W_size)
    return BlockCSR(indptr, indices, blocks, diag_pos)
