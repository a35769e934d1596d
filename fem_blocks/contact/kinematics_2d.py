"""Contact kinematics G^α (docs/method.md §3): local relative velocity from body velocities, and its transpose.

Each contact α has two sides s = 0 (candidate, sign +) and s = 1 (antagonist, sign −):

    v_loc^α = Σ_s side_G[α, s] @ u_{side_body[α, s]}[side_dofs[α, s]]     (normal first: (v_N, v_T))

with u a body's velocity in its *W numbering*: deformable body = type-frame boundary dofs 2*bi + c,
so for node weights w_k and rotation R (type -> global), the rows are ±w_k [Rᵀn ; Rᵀt]; rigid body =
(vx, vy, ω) at its centre c, v(x) = (vx, vy) + ω (−(x−c)_y, (x−c)_x). Padding dofs are −1.
H = Gᵀ: `accumulate_impulse` scatters (H P) into the flat W-numbered vector.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit


@dataclass
class GBlocks:
    side_body: np.ndarray  # (nc, 2) int64
    side_dofs: np.ndarray  # (nc, 2, 4) int64, -1 padding
    side_G: np.ndarray     # (nc, 2, 2, 4) float64


def build_G(cs, kind, rot, center, bnode_index_flat, bnode_offset) -> GBlocks:
    nc = len(cs.gap)
    side_body = np.stack([cs.cand_body, cs.ant_body], axis=1).astype(np.int64)
    side_dofs = -np.ones((nc, 2, 4), dtype=np.int64)
    side_G = np.zeros((nc, 2, 2, 4))
    frame = np.stack([cs.n, cs.t], axis=1)  # (nc, 2 rows, 2 comps)
    x_side = [cs.point, cs.point - cs.gap[:, None] * cs.n]
    for s, (nodes, w, sign) in enumerate(((cs.cand_nodes, cs.cand_w, 1.0), (cs.ant_nodes, cs.ant_w, -1.0))):
        b = side_body[:, s]
        dfm = kind[b] == 0
        if np.any(dfm):
            i = np.flatnonzero(dfm)
            bi = bnode_index_flat[bnode_offset[b[i]][:, None] + nodes[i]]  # (k, 2)
            if np.any(bi < 0):
                raise ValueError("contact on a node that is not a boundary node of its body")
            side_dofs[i, s, 0::2] = 2 * bi
            side_dofs[i, s, 1::2] = 2 * bi + 1
            FR = np.einsum("krc,kcd->krd", frame[i], rot[b[i]])  # rows (n, t) . R  -> type frame
            for k in range(2):
                side_G[i, s, :, 2 * k:2 * k + 2] = sign * w[i, k][:, None, None] * FR
        rig = ~dfm
        if np.any(rig):
            i = np.flatnonzero(rig)
            d = x_side[s][i] - center[b[i]]
            side_dofs[i, s, :3] = [0, 1, 2]
            for r in range(2):
                f = frame[i, r]
                side_G[i, s, r, 0] = sign * f[:, 0]
                side_G[i, s, r, 1] = sign * f[:, 1]
                side_G[i, s, r, 2] = sign * (f[:, 1] * d[:, 0] - f[:, 0] * d[:, 1])
    return GBlocks(side_body, side_dofs, side_G)


@njit(cache=True)
def _local_velocity(side_body, side_dofs, side_G, U, U_offset, out):
    nc = side_body.shape[0]
    for a in range(nc):
        v0 = 0.0
        v1 = 0.0
        for s in range(2):
            off = U_offset[side_body[a, s]]
            for j in range(4):
                d = side_dofs[a, s, j]
                if d >= 0:
                    u = U[off + d]
                    v0 += side_G[a, s, 0, j] * u
                    v1 += side_G[a, s, 1, j] * u
        out[a, 0] = v0
        out[a, 1] = v1


@njit(cache=True)
def _accumulate(side_body, side_dofs, side_G, P, U_offset, out):
    nc = side_body.shape[0]
    for a in range(nc):
        for s in range(2):
            off = U_offset[side_body[a, s]]
            for j in range(4):
                d = side_dofs[a, s, j]
                if d >= 0:
                    out[off + d] += side_G[a, s, 0, j] * P[a, 0] + side_G[a, s, 1, j] * P[a, 1]


def local_velocity(G, U_flat, U_offset, kernel=None) -> np.ndarray:
    """(nc, d) local velocities G u from the flat W-numbered body velocities; d = G.side_G.shape[2]. `kernel`:
    the compiled loop for that d (default the 2D `_local_velocity`; kinematics_3d passes its own: a kernel
    generic in d measured 3x slower on the 2D case, so each dimension keeps its unrolled loop)."""
    out = np.zeros((G.side_body.shape[0], G.side_G.shape[2]))
    (kernel or _local_velocity)(G.side_body, G.side_dofs, G.side_G, np.ascontiguousarray(U_flat, dtype=float),
                                np.asarray(U_offset, dtype=np.int64), out)
    return out


def accumulate_impulse(G, P, n_total: int, U_offset, kernel=None) -> np.ndarray:
    """H P: flat W-numbered vector of the contact impulses P (nc, d) on the bodies (`kernel` as in
    local_velocity)."""
    out = np.zeros(int(n_total))
    (kernel or _accumulate)(G.side_body, G.side_dofs, G.side_G,
                            np.ascontiguousarray(P, dtype=float).reshape(-1, G.side_G.shape[2]),
                            np.asarray(U_offset, dtype=np.int64), out)
    return out
