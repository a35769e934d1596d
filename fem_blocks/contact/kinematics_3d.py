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

from ..errors import InputError
from . import kinematics_2d as _kin2

ND = 12  # padded dofs per side: 4 nodes x 3 components (rigid: 6)


@dataclass
class GBlocks:
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


def build_G(cs, kind, rot=None, center=None, bnode_index_flat=None, bnode_offset=None) -> GBlocks:
    """G blocks of a ContactSet. kind[b] 0 deformable / 1 rigid; rot (nb, 3, 3) type frame -> global of the
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
    return GBlocks(side_body, side_dofs, side_G)


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


def local_velocity(G: GBlocks, U_flat, U_offset) -> np.ndarray:
    """(nc, 3) local velocities (v_N, v_T, v_S) = G u from the flat W-numbered body velocities."""
    return _kin2.local_velocity(G, U_flat, U_offset, _local_velocity)


def accumulate_impulse(G: GBlocks, P, n_total: int, U_offset) -> np.ndarray:
    """H P: flat W-numbered vector of the contact impulses (nc, 3) on the bodies."""
    return _kin2.accumulate_impulse(G, P, n_total, U_offset, _accumulate)
