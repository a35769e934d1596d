"""3D contact detection on plain arrays: candidate points on candidate faces, projected on antagonist faces.

Input (per body, architecture.md "3D contact"): boundary-node positions (n, 3) and boundary faces (nf, 3)
triangles or (nf, 4) quadrilaterals of body-local boundary-node ids, ordered so that the right-hand-rule
normal points OUT of the body. `flatten_boundaries` concatenates them into the flat arrays used here:
`bx (nbn, 3)`, `bnode_body`, `bnode_local`, `bfaces (nf, 4)` indices into bx (-1 in column 3 for a
triangle), `bface_body`.

Face geometry. A quad is the bilinear patch x(ξ, η) = Σ_k N_k(ξ, η) X_k on the reference square [-1, 1]²,
N_k = (1 ± ξ)(1 ± η)/4 with corners k = 0..3 at (-1,-1), (1,-1), (1,1), (-1,1); its outward normal is
x_ξ × x_η / |x_ξ × x_η|. A triangle is x = X_0 + λ_1 (X_1 - X_0) + λ_2 (X_2 - X_0), normal
(X_1 - X_0) × (X_2 - X_0) normalised.

Candidate points (per interface, `placement`):
* "positions": on a quad, the tensor product of the interface's relative positions p_i in (0, 1) along
  each edge (default 0.25, 0.75 -> the 4 points ξ, η = ±1/2 of thesis §7.2.1.c); on a triangle, the 3
  points (λ_1, λ_2) = (1/6, 1/6), (2/3, 1/6), (1/6, 2/3) (`tri_rule` 3) or the centroid (`tri_rule` 1).
  Tributary area of a quad point = ∫_cell |x_ξ × x_η| dξ dη over its cell of the reference square (cells
  bounded by the mid-points between consecutive positions and the square's sides; 4 x 4 Gauss points per
  cell: exact for a planar quad, whose Jacobian is bilinear; a composite rule of the surface-area integral
  for a warped one). A triangle point gets A/3 (the medians cut the triangle in 3 equal-area vertex regions,
  one point each) or A. The areas of a face's points sum to its area.
* "nodes": one point per face corner, tributary area ∫ N_k |x_ξ × x_η| (quads, same Gauss rule) or A/3
  (triangles). A node shared by several candidate faces gets one contact per antagonist body, its area the
  sum over the candidate faces whose nearest match lies on that body.

Projection of a candidate point p on an antagonist face: orthogonal projection, i.e. the stationary point of
|x(ξ, η) - p|² (triangle: exact 2 x 2 solve; quad: Newton on (ξ, η) with the exact Hessian
[x_ξ·x_ξ, x_ξ·x_η + x_ξη·(x - p); ., x_η·x_η], started from the planar solution, Gauss-Newton step if the
Hessian is not positive definite, |Δξ| <= 1e-14 to stop). Inside test: |ξ|, |η| <= 1 + tol (quad),
λ_1, λ_2 >= -tol, λ_1 + λ_2 <= 1 + tol (triangle); weights use the clamped coordinates.
Frame at the projection x_a: n = outward normal of the antagonist face at x_a (toward the candidate when
they are apart); t = x_ξ / |x_ξ| (quad, the tangent along the face's first edge direction, exactly ⊥ n),
t = (X_1 - X_0)/|X_1 - X_0| (triangle); s = n × t, so (n, t, s) is orthonormal and right-handed.
Gap g = (x_c - x_a)·n; thick joint: g0 = joint thickness.

A point is kept if it projects on a facing antagonist face (outward normals at the face centres within
`max_angle` of opposite) with -(reach) <= g <= g0 + alert, reach = reach_frac · min(√A_c, √A_a) + alert, and
d_out <= alert, d_out = the distance from the projection x_a to the face measured in its surface (0 inside, to
`inside_tol` on the reference coordinates; else |x_a - x(clamped coordinates)|): a point on an edge that the
deformation (Poisson expansion, ~1e-7 m) or a slide moves just past it stays in contact, with the antagonist
weights clamped onto the edge and g measured from the face's (bilinear) extension. Among several faces the
nearest is kept: smallest hypot(g - g0, d_out) (= |g - g0| inside), then the lower face index. Node points
("nodes") lie on edges of their candidate face, often on an edge between two antagonist faces (a head joint
above or below, a face flush with a neighbour's): before that distance, the faces are ranked by d_out of a
probe, the node moved PROBE = 1 % of the way toward its candidate face's centre, so that each candidate face
gives the node's share of its area to the antagonist face it actually faces (and 1e-7 m of deformation does
not swap the pairing, as the index tie-break did).

Candidate/antagonist (as in 2D, deterministic): the interface's `candidate` group if given and the two bodies
differ in group; else a deformable body is candidate against a rigid one; else the lower body index.
Interface id: pair_iface of the two groups; `split_head` swaps in the head-joint interface when the normal
is closer to horizontal than to vertical (|n·e_vertical| < √½, vertical axis z by default).

Broad phase: body boxes enlarged by max(g0 + alert) on a uniform 3D grid (`box_pairs`, contact/broadphase.py;
linear in the number of bodies); per body pair only the faces whose box meets the other body's enlarged box are
examined, and a point is projected only on antagonist faces whose enlarged box contains it. A rank's detection
(`detect(..., bodies=)`: the contacts of its own candidate bodies) examines the body pairs with one of its bodies
only, a subsequence of the whole set's pairs: the same contacts, bit for bit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..errors import InputError
from .tables import check_g0_alert, check_lengths, check_positions
from .broadphase import body_boxes, grid_pairs
from .detection_2d import MAX_ANGLE

PROBE = 1e-2  # node points: fraction of the way from the node toward its candidate face's centre (tie-break probe)

# 4-point Gauss-Legendre rule on [-1, 1]
_GX = np.array([-0.8611363115940526, -0.3399810435848563, 0.3399810435848563, 0.8611363115940526])
_GW = np.array([0.3478548451374538, 0.6521451548625461, 0.6521451548625461, 0.3478548451374538])


@dataclass
class InterfaceTable:
    """pair_iface[gi, gj] -> interface id (-1: no contact). `positions (ni, P)` relative positions along
    each edge of a quad (tensor product), padded with -1; `tri_rule` 3 (three interior points) or 1
    (centroid); `placement` 0 positions, 1 nodes; `split_head[i]` interface used instead of i when the
    normal is closer to horizontal (-1 none)."""

    pair_iface: np.ndarray
    g0: np.ndarray
    alert: np.ndarray
    placement: np.ndarray
    positions: np.ndarray
    tri_rule: np.ndarray
    cand_group: np.ndarray
    cos_max_angle: np.ndarray
    split_head: np.ndarray

    def validate(self):
        ni = len(self.g0)
        check_lengths(self, ("alert", "placement", "tri_rule", "cand_group", "cos_max_angle", "split_head"), ni)
        pi = np.asarray(self.pair_iface)
        if pi.ndim != 2 or pi.shape[0] != pi.shape[1] or np.any(pi >= ni) or np.any(pi < -1):
            raise InputError(f"interface table: pair_iface expected a square (ng, ng) array of ids in [-1, {ni})")
        check_g0_alert(self.g0, self.alert)
        if np.any((self.tri_rule != 1) & (self.tri_rule != 3)):
            raise InputError("interfaces.tri_rule: expected 1 (centroid) or 3 (three interior points)")
        if np.any((self.placement != 0) & (self.placement != 1)):
            raise InputError("interfaces.placement: expected 0 (positions) or 1 (nodes)")
        check_positions(self.positions, self.placement, ni)

    @classmethod
    def from_2d(cls, table, tri_rule=3) -> "InterfaceTable":
        """From the 2D `detection_2d.InterfaceTable` (built by `detection_2d.build_table`): same groups, g0, alert,
        placement, positions (used along both directions of a quad), candidate rule, max angle and bed/head
        split; `tri_rule` for triangular faces (scalar or per interface)."""
        ni = len(table.g0)
        return cls(pair_iface=np.asarray(table.pair_iface, dtype=np.int64), g0=np.asarray(table.g0, float),
                   alert=np.asarray(table.alert, float), placement=np.asarray(table.placement, np.int64),
                   positions=np.asarray(table.positions, float),
                   tri_rule=np.broadcast_to(np.asarray(tri_rule, dtype=np.int64), (ni,)).copy(),
                   cand_group=np.asarray(table.cand_group, np.int64),
                   cos_max_angle=np.asarray(table.cos_max_angle, float),
                   split_head=np.asarray(table.split_head, np.int64))


def simple_table(g0=0.0, alert=1e-3, positions=(0.25, 0.75), placement="positions", tri_rule=3,
                 max_angle=None) -> InterfaceTable:
    """One interface between all bodies (a single group 0)."""
    pos = np.asarray(positions, dtype=float).reshape(1, -1)
    return InterfaceTable(pair_iface=np.zeros((1, 1), dtype=np.int64), g0=np.array([float(g0)]),
                            alert=np.array([float(alert)]),
                            placement=np.array([0 if placement == "positions" else 1], dtype=np.int64),
                            positions=pos, tri_rule=np.array([tri_rule], dtype=np.int64),
                            cand_group=-np.ones(1, dtype=np.int64),
                            cos_max_angle=np.cos(np.deg2rad([MAX_ANGLE if max_angle is None else max_angle])),
                            split_head=-np.ones(1, dtype=np.int64))


@dataclass
class ContactSet:
    """One row per contact point (architecture.md "3D contact")."""

    cand_body: np.ndarray   # (nc,)
    ant_body: np.ndarray    # (nc,)
    cand_nodes: np.ndarray  # (nc, 4) body-local node ids (bnode_local), -1 padding
    cand_w: np.ndarray      # (nc, 4) interpolation weights of the candidate point (0 on padding)
    ant_nodes: np.ndarray   # (nc, 4)
    ant_w: np.ndarray       # (nc, 4) weights of the projection (clamped into the face)
    point: np.ndarray       # (nc, 3) candidate point x_c
    n: np.ndarray           # (nc, 3) antagonist outward normal at the projection
    t: np.ndarray           # (nc, 3)
    s: np.ndarray           # (nc, 3) = n x t
    gap: np.ndarray         # (nc,) (x_c - x_a)·n
    g0: np.ndarray          # (nc,)
    area: np.ndarray        # (nc,) tributary area
    interface: np.ndarray   # (nc,)
    cand_face: np.ndarray   # (nc,) index into bfaces (for a node point: the face that gave its geometry)
    ant_face: np.ndarray    # (nc,)
    ant_ref: np.ndarray     # (nc, 2) (ξ, η) on a quad, (λ_1, λ_2) on a triangle, unclamped
    key: np.ndarray         # (nc,) candidate point id: face * KP + k, or -(bx index) - 1 for node points

    def __len__(self):
        return len(self.gap)

    def subset(self, idx) -> "ContactSet":
        return ContactSet(**{k: v[idx] for k, v in self.__dict__.items()})


# ----------------------------------------------------------------------------- input
def flatten_boundaries(positions, faces, node_ids=None):
    """Flat arrays from per-body boundary data.

    positions[b] (n_b, 3) global positions of body b's boundary nodes; faces[b] (nf_b, 3|4) indices into
    positions[b], outward by the right-hand rule; node_ids[b] (n_b,) the body-local ids reported in
    cand_nodes/ant_nodes (default 0..n_b-1). Returns (bx, bnode_body, bnode_local, bfaces (nf, 4) with -1 in
    column 3 for triangles, bface_body)."""
    if len(positions) != len(faces):
        raise InputError(f"faces: expected one face array per body ({len(positions)}), got {len(faces)}")
    bx, nbody, nloc, fl, fbody = [], [], [], [], []
    off = 0
    for b, (X, F) in enumerate(zip(positions, faces)):
        X = np.asarray(X, dtype=float)
        F = np.asarray(F, dtype=np.int64)
        if X.ndim != 2 or X.shape[1] != 3:
            raise InputError(f"body {b}: boundary positions expected an (n, 3) array, got shape {X.shape}")
        if F.ndim != 2 or F.shape[1] not in (3, 4):
            raise InputError(f"body {b}: boundary faces expected an (nf, 3) or (nf, 4) array, got shape {F.shape}")
        if F.size and (F.min() < 0 or F.max() >= len(X)):
            raise InputError(f"body {b}: boundary face node ids expected in [0, {len(X)})")
        ids = np.arange(len(X)) if node_ids is None else np.asarray(node_ids[b], dtype=np.int64)
        if ids.shape != (len(X),):
            raise InputError(f"body {b}: node_ids expected shape ({len(X)},), got {ids.shape}")
        G = -np.ones((len(F), 4), dtype=np.int64)
        G[:, :F.shape[1]] = F + off
        bx.append(X)
        nbody.append(np.full(len(X), b, dtype=np.int64))
        nloc.append(ids)
        fl.append(G)
        fbody.append(np.full(len(F), b, dtype=np.int64))
        off += len(X)
    cat = (lambda L, shape: np.concatenate(L) if L else np.zeros(shape))
    return (cat(bx, (0, 3)).astype(float), cat(nbody, 0).astype(np.int64), cat(nloc, 0).astype(np.int64),
            cat(fl, (0, 4)).astype(np.int64), cat(fbody, 0).astype(np.int64))


# ----------------------------------------------------------------------------- face geometry (numba)
@njit(cache=True)
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def _face_data(bx, bfaces, gx, gw):
    """Per face: coef (nf, 4, 3) (quad: c0, a, b, d of x = c0 + ξa + ηb + ξηd; triangle: X0, X1-X0, X2-X0, 0),
    nv, unit normal at the centre, area (∫|x_ξ × x_η| by 4 x 4 Gauss; exact for a triangle), box lo/hi."""
    nf = bfaces.shape[0]
    coef = np.zeros((nf, 4, 3))
    nv = np.empty(nf, dtype=np.int64)
    nrm = np.zeros((nf, 3))
    area = np.zeros(nf)
    lo = np.empty((nf, 3))
    hi = np.empty((nf, 3))
    for f in range(nf):
        q = 4 if bfaces[f, 3] >= 0 else 3
        nv[f] = q
        for c in range(3):
            lo[f, c] = np.inf
            hi[f, c] = -np.inf
            for k in range(q):
                v = bx[bfaces[f, k], c]
                lo[f, c] = min(lo[f, c], v)
                hi[f, c] = max(hi[f, c], v)
        if q == 4:
            for c in range(3):
                X0 = bx[bfaces[f, 0], c]
                X1 = bx[bfaces[f, 1], c]
                X2 = bx[bfaces[f, 2], c]
                X3 = bx[bfaces[f, 3], c]
                coef[f, 0, c] = 0.25 * (X0 + X1 + X2 + X3)
                coef[f, 1, c] = 0.25 * (-X0 + X1 + X2 - X3)
                coef[f, 2, c] = 0.25 * (-X0 - X1 + X2 + X3)
                coef[f, 3, c] = 0.25 * (X0 - X1 + X2 - X3)
            a = coef[f, 1]
            b = coef[f, 2]
            m0, m1, m2 = _cross(a[0], a[1], a[2], b[0], b[1], b[2])
            A = 0.0
            for i in range(4):
                for j in range(4):
                    A += gw[i] * gw[j] * _jac(coef, f, gx[i], gx[j])
            area[f] = A
        else:
            for c in range(3):
                X0 = bx[bfaces[f, 0], c]
                coef[f, 0, c] = X0
                coef[f, 1, c] = bx[bfaces[f, 1], c] - X0
                coef[f, 2, c] = bx[bfaces[f, 2], c] - X0
            a = coef[f, 1]
            b = coef[f, 2]
            m0, m1, m2 = _cross(a[0], a[1], a[2], b[0], b[1], b[2])
            area[f] = 0.5 * np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
        L = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
        if L > 0:
            nrm[f, 0] = m0 / L
            nrm[f, 1] = m1 / L
            nrm[f, 2] = m2 / L
    return coef, nv, nrm, area, lo, hi


@njit(cache=True)
def _jac(coef, f, xi, eta):
    """|x_ξ × x_η| of quad f at (ξ, η)."""
    u0 = coef[f, 1, 0] + eta * coef[f, 3, 0]
    u1 = coef[f, 1, 1] + eta * coef[f, 3, 1]
    u2 = coef[f, 1, 2] + eta * coef[f, 3, 2]
    v0 = coef[f, 2, 0] + xi * coef[f, 3, 0]
    v1 = coef[f, 2, 1] + xi * coef[f, 3, 1]
    v2 = coef[f, 2, 2] + xi * coef[f, 3, 2]
    m0, m1, m2 = _cross(u0, u1, u2, v0, v1, v2)
    return np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)


@njit(cache=True)
def _cell_area(coef, f, xa, xb, ya, yb, gx, gw, node):
    """∫ over [xa, xb] x [ya, yb] of |x_ξ × x_η| (node < 0) or N_node |x_ξ × x_η| (4 x 4 Gauss)."""
    hx = 0.5 * (xb - xa)
    hy = 0.5 * (yb - ya)
    mx = 0.5 * (xa + xb)
    my = 0.5 * (ya + yb)
    A = 0.0
    for i in range(4):
        xi = mx + hx * gx[i]
        for j in range(4):
            eta = my + hy * gx[j]
            w = gw[i] * gw[j] * hx * hy * _jac(coef, f, xi, eta)
            if node >= 0:
                w *= _shape(node, xi, eta)
            A += w
    return A


@njit(cache=True)
def _shape(k, xi, eta):
    sx = -1.0 if (k == 0 or k == 3) else 1.0
    sy = -1.0 if k < 2 else 1.0
    return 0.25 * (1.0 + sx * xi) * (1.0 + sy * eta)


@njit(cache=True)
def _bilinear_point(coef, f, u, v):
    """Point x = c0 + u a + v b + u v d of the bilinear face f (coef[f] = c0, a, b, d) and its tangents
    x_,u = a + v d, x_,v = b + u d: (x, y, z, tu_x, tu_y, tu_z, tv_x, tv_y, tv_z)."""
    dx = coef[f, 3, 0]
    dy = coef[f, 3, 1]
    dz = coef[f, 3, 2]
    ax = coef[f, 1, 0] + v * dx
    ay = coef[f, 1, 1] + v * dy
    az = coef[f, 1, 2] + v * dz
    bx = coef[f, 2, 0] + u * dx
    by = coef[f, 2, 1] + u * dy
    bz = coef[f, 2, 2] + u * dz
    return (coef[f, 0, 0] + u * coef[f, 1, 0] + v * coef[f, 2, 0] + u * v * dx,
            coef[f, 0, 1] + u * coef[f, 1, 1] + v * coef[f, 2, 1] + u * v * dy,
            coef[f, 0, 2] + u * coef[f, 1, 2] + v * coef[f, 2, 2] + u * v * dz, ax, ay, az, bx, by, bz)


@njit(cache=True)
def _project(coef, nv, f, p0, p1, p2, out):
    """Orthogonal projection of p on face f. out[0:2] = reference coords (ξ, η) or (λ1, λ2), out[2:5] = x_a,
    out[5:8] = n, out[8:11] = t, out[11:14] = s, out[14] = gap. Returns False if Newton failed."""
    c0x = coef[f, 0, 0]
    c0y = coef[f, 0, 1]
    c0z = coef[f, 0, 2]
    ax = coef[f, 1, 0]
    ay = coef[f, 1, 1]
    az = coef[f, 1, 2]
    bxx = coef[f, 2, 0]
    by = coef[f, 2, 1]
    bz = coef[f, 2, 2]
    rx = p0 - c0x
    ry = p1 - c0y
    rz = p2 - c0z
    aa = ax * ax + ay * ay + az * az
    ab = ax * bxx + ay * by + az * bz
    bb = bxx * bxx + by * by + bz * bz
    ar = ax * rx + ay * ry + az * rz
    br = bxx * rx + by * ry + bz * rz
    det = aa * bb - ab * ab
    if not det > 0.0:
        return False
    u = (bb * ar - ab * br) / det
    v = (aa * br - ab * ar) / det
    if nv[f] == 3:
        xx = c0x + u * ax + v * bxx
        xy = c0y + u * ay + v * by
        xz = c0z + u * az + v * bz
        tux, tuy, tuz = ax, ay, az
        tvx, tvy, tvz = bxx, by, bz
    else:
        dx = coef[f, 3, 0]
        dy = coef[f, 3, 1]
        dz = coef[f, 3, 2]
        ok = False
        for it in range(60):
            xx, xy, xz, tux, tuy, tuz, tvx, tvy, tvz = _bilinear_point(coef, f, u, v)
            ex = xx - p0
            ey = xy - p1
            ez = xz - p2
            F0 = tux * ex + tuy * ey + tuz * ez
            F1 = tvx * ex + tvy * ey + tvz * ez
            H00 = tux * tux + tuy * tuy + tuz * tuz
            H11 = tvx * tvx + tvy * tvy + tvz * tvz
            H01 = tux * tvx + tuy * tvy + tuz * tvz
            H01n = H01 + dx * ex + dy * ey + dz * ez
            dt = H00 * H11 - H01n * H01n
            if dt > 1e-12 * H00 * H11:
                H01 = H01n
            else:  # Gauss-Newton step (Hessian not positive definite)
                dt = H00 * H11 - H01 * H01
            du = -(H11 * F0 - H01 * F1) / dt
            dv = -(H00 * F1 - H01 * F0) / dt
            m = max(abs(du), abs(dv))
            if m > 0.5:
                du *= 0.5 / m
                dv *= 0.5 / m
            u += du
            v += dv
            if abs(u) > 1e3 or abs(v) > 1e3:
                return False
            if m <= 1e-14 * (1.0 + abs(u) + abs(v)):
                ok = True
                break
        if not ok:
            return False
        xx, xy, xz, tux, tuy, tuz, tvx, tvy, tvz = _bilinear_point(coef, f, u, v)
    nx, ny, nz = _cross(tux, tuy, tuz, tvx, tvy, tvz)
    L = np.sqrt(nx * nx + ny * ny + nz * nz)
    if L == 0.0:
        return False
    nx /= L
    ny /= L
    nz /= L
    # t: the first tangent direction, made exactly orthogonal to n (exact already for both face kinds)
    tn = tux * nx + tuy * ny + tuz * nz
    tx = tux - tn * nx
    ty = tuy - tn * ny
    tz = tuz - tn * nz
    L = np.sqrt(tx * tx + ty * ty + tz * tz)
    tx /= L
    ty /= L
    tz /= L
    sx, sy, sz = _cross(nx, ny, nz, tx, ty, tz)
    out[0] = u
    out[1] = v
    out[2] = xx
    out[3] = xy
    out[4] = xz
    out[5] = nx
    out[6] = ny
    out[7] = nz
    out[8] = tx
    out[9] = ty
    out[10] = tz
    out[11] = sx
    out[12] = sy
    out[13] = sz
    out[14] = (p0 - xx) * nx + (p1 - xy) * ny + (p2 - xz) * nz
    return True


@njit(cache=True)
def _weights(nvf, u, v, tol, w):
    """Inside test (tolerance tol) and interpolation weights at the clamped reference coordinates."""
    if nvf == 4:
        if abs(u) > 1.0 + tol or abs(v) > 1.0 + tol:
            return False
        uc = min(max(u, -1.0), 1.0)
        vc = min(max(v, -1.0), 1.0)
        for k in range(4):
            w[k] = _shape(k, uc, vc)
        return True
    if u < -tol or v < -tol or u + v > 1.0 + tol:
        return False
    uc = max(u, 0.0)
    vc = max(v, 0.0)
    ssum = uc + vc
    if ssum > 1.0:
        uc /= ssum
        vc /= ssum
    w[0] = 1.0 - uc - vc
    w[1] = uc
    w[2] = vc
    w[3] = 0.0
    return True


@njit(cache=True)
def _outside(coef, nv, f, out, tol, w):
    """Distance d_out from the projection x_a = out[2:5] (reference coordinates out[0:2]) to the face f,
    measured in the face's surface: 0 if x_a is inside (tolerance tol on the reference coordinates), else
    |x_a - x(clamped coordinates)|. Writes the weights at the clamped coordinates (`_weights`) into w."""
    if _weights(nv[f], out[0], out[1], tol, w):
        return 0.0
    _weights(nv[f], out[0], out[1], np.inf, w)
    u = out[0]
    v = out[1]
    if nv[f] == 4:
        uc = min(max(u, -1.0), 1.0)
        vc = min(max(v, -1.0), 1.0)
        x0, x1, x2, _a, _b, _c, _d, _e, _g = _bilinear_point(coef, f, uc, vc)
    else:
        uc = w[1]
        vc = w[2]
        x0 = coef[f, 0, 0] + uc * coef[f, 1, 0] + vc * coef[f, 2, 0]
        x1 = coef[f, 0, 1] + uc * coef[f, 1, 1] + vc * coef[f, 2, 1]
        x2 = coef[f, 0, 2] + uc * coef[f, 1, 2] + vc * coef[f, 2, 2]
    d0 = out[2] - x0
    d1 = out[3] - x1
    d2 = out[4] - x2
    return np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


# ----------------------------------------------------------------------------- broad phase
def box_pairs(lo, hi, cell=None) -> np.ndarray:
    """All pairs (i, j), i < j, of axis-aligned boxes [lo_i, hi_i] that overlap (touching counts), sorted.

    Uniform grid, cell = median box size (at least 1/512 of the scene's extent so that the grid stays
    small): cost linear in the number of boxes for boxes of comparable sizes."""
    lo = np.ascontiguousarray(lo, dtype=float)
    hi = np.ascontiguousarray(hi, dtype=float)
    if lo.ndim != 2 or lo.shape[1] != 3 or hi.shape != lo.shape:
        raise InputError(f"box_pairs: lo, hi expected (n, 3) arrays, got {lo.shape} and {hi.shape}")
    if len(lo) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or np.any(hi < lo):
        raise InputError("box_pairs: expected finite boxes with lo <= hi")
    origin = lo.min(axis=0)
    ext = float(np.max(hi.max(axis=0) - origin))
    if cell is None:
        cell = float(np.median(np.max(hi - lo, axis=1)))
    cell = max(float(cell), ext / 512.0, 1e-12 * max(ext, 1.0), 1e-300)
    pairs = grid_pairs(lo, hi, np.arange(len(lo)), cell)
    if len(pairs):
        pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
    return pairs


# ----------------------------------------------------------------------------- narrow phase
@njit(cache=True)
def _narrow(bpairs, bx, bfaces, face_order, face_start, coef, nv, nrm, farea, flo, fhi, blo, bhi,
             kind, body_group, pair_iface, g0, alert, placement, positions, npos, tri_rule, cand_group, cos_max,
             reach_frac, tol, KP, gx, gw):
    """Raw matches: for each body pair, each candidate point of the candidate body's faces near the other
    body, the nearest antagonist face of the other body (node points: smallest d_out of the probe first; then
    smallest hypot(g - g0, d_out), then lower face index; module docstring)."""
    cap = 1024
    ri = np.empty((cap, 5), dtype=np.int64)    # cand face, k, ant face, key, interface
    rf = np.empty((cap, 26))                   # gap, area, x(3), n(3), t(3), s(3), wc(4), wa(4), ref(2), d_out,
    #                                            d_out of the probe (node points)
    m = 0
    out = np.empty(15)
    out2 = np.empty(15)
    wa = np.empty(4)
    wp = np.empty(4)
    wc = np.empty(4)
    cfl = np.empty(0, dtype=np.int64)
    afl = np.empty(0, dtype=np.int64)
    for p in range(bpairs.shape[0]):
        b1 = bpairs[p, 0]
        b2 = bpairs[p, 1]
        itf = pair_iface[body_group[b1], body_group[b2]]
        if itf < 0:
            continue
        cg = cand_group[itf]
        if cg >= 0 and body_group[b1] != body_group[b2] and (body_group[b1] == cg or body_group[b2] == cg):
            c1 = body_group[b1] == cg
        elif kind[b1] != kind[b2]:
            c1 = kind[b1] == 0
        else:
            c1 = b1 < b2
        cb = b1 if c1 else b2
        ab = b2 if c1 else b1
        srch = g0[itf] + alert[itf]
        # faces of each body near the other body's enlarged box
        nca = face_start[cb + 1] - face_start[cb]
        naa = face_start[ab + 1] - face_start[ab]
        if cfl.shape[0] < nca:
            cfl = np.empty(nca, dtype=np.int64)
        if afl.shape[0] < naa:
            afl = np.empty(naa, dtype=np.int64)
        nc_ = 0
        for q in range(face_start[cb], face_start[cb + 1]):
            f = face_order[q]
            if _boxes_meet(flo, fhi, f, blo, bhi, ab, srch):
                cfl[nc_] = f
                nc_ += 1
        na_ = 0
        for q in range(face_start[ab], face_start[ab + 1]):
            f = face_order[q]
            if _boxes_meet(flo, fhi, f, blo, bhi, cb, srch):
                afl[na_] = f
                na_ += 1
        if nc_ == 0 or na_ == 0:
            continue
        for ic in range(nc_):
            fc = cfl[ic]
            q = nv[fc]
            # number of candidate points on this face
            if placement[itf] == 1:
                npts = q
            elif q == 4:
                npts = npos[itf] * npos[itf]
            else:
                npts = tri_rule[itf]
            Lc = np.sqrt(farea[fc])
            for k in range(npts):
                # candidate point: reference coords, weights, tributary area
                for j in range(4):
                    wc[j] = 0.0
                if placement[itf] == 1:
                    wc[k] = 1.0
                    if q == 4:
                        trib = _cell_area(coef, fc, -1.0, 1.0, -1.0, 1.0, gx, gw, k)
                    else:
                        trib = farea[fc] / 3.0
                    key = -bfaces[fc, k] - 1
                elif q == 4:
                    P = npos[itf]
                    i = k // P
                    jj = k % P
                    xi = 2.0 * positions[itf, i] - 1.0
                    eta = 2.0 * positions[itf, jj] - 1.0
                    xa_ = -1.0 if i == 0 else positions[itf, i - 1] + positions[itf, i] - 1.0
                    xb_ = 1.0 if i == P - 1 else positions[itf, i] + positions[itf, i + 1] - 1.0
                    ya_ = -1.0 if jj == 0 else positions[itf, jj - 1] + positions[itf, jj] - 1.0
                    yb_ = 1.0 if jj == P - 1 else positions[itf, jj] + positions[itf, jj + 1] - 1.0
                    trib = _cell_area(coef, fc, xa_, xb_, ya_, yb_, gx, gw, -1)
                    for j in range(4):
                        wc[j] = _shape(j, xi, eta)
                    key = fc * KP + k
                else:
                    if tri_rule[itf] == 1:
                        l1 = 1.0 / 3.0
                        l2 = 1.0 / 3.0
                        trib = farea[fc]
                    else:
                        l1 = 2.0 / 3.0 if k == 1 else 1.0 / 6.0
                        l2 = 2.0 / 3.0 if k == 2 else 1.0 / 6.0
                        trib = farea[fc] / 3.0
                    wc[0] = 1.0 - l1 - l2
                    wc[1] = l1
                    wc[2] = l2
                    key = fc * KP + k
                px = 0.0
                py = 0.0
                pz = 0.0
                for j in range(q):
                    px += wc[j] * bx[bfaces[fc, j], 0]
                    py += wc[j] * bx[bfaces[fc, j], 1]
                    pz += wc[j] * bx[bfaces[fc, j], 2]
                # node points: a probe moved PROBE of the way toward the candidate face's centre tells which
                # antagonist face the node's tributary region faces when the node lies on an edge of several
                probe = placement[itf] == 1
                if probe:
                    qx = px + PROBE * (coef[fc, 0, 0] + (coef[fc, 1, 0] + coef[fc, 2, 0]) / 3.0 * (q == 3) - px)
                    qy = py + PROBE * (coef[fc, 0, 1] + (coef[fc, 1, 1] + coef[fc, 2, 1]) / 3.0 * (q == 3) - py)
                    qz = pz + PROBE * (coef[fc, 0, 2] + (coef[fc, 1, 2] + coef[fc, 2, 2]) / 3.0 * (q == 3) - pz)
                best = -1
                bscore = np.inf
                bprobe = np.inf
                for ia in range(na_):
                    fa = afl[ia]
                    if -(nrm[fa, 0] * nrm[fc, 0] + nrm[fa, 1] * nrm[fc, 1] + nrm[fa, 2] * nrm[fc, 2]) < cos_max[itf]:
                        continue
                    reach = reach_frac * min(Lc, np.sqrt(farea[fa])) + alert[itf]
                    pad = max(srch, reach)
                    if px < flo[fa, 0] - pad or px > fhi[fa, 0] + pad or py < flo[fa, 1] - pad \
                            or py > fhi[fa, 1] + pad or pz < flo[fa, 2] - pad or pz > fhi[fa, 2] + pad:
                        continue
                    if not _project(coef, nv, fa, px, py, pz, out):
                        continue
                    g = out[14]
                    if g > srch or g < -reach:
                        continue
                    dout = _outside(coef, nv, fa, out, tol, wa)
                    if dout > alert[itf]:
                        continue
                    sc = abs(g - g0[itf]) if dout == 0.0 else np.hypot(g - g0[itf], dout)
                    dp = 0.0
                    if probe:
                        dp = _outside(coef, nv, fa, out2, tol, wp) if _project(coef, nv, fa, qx, qy, qz, out2) \
                            else np.inf
                    if dp < bprobe or (dp == bprobe and (sc < bscore or (sc == bscore and fa < best))):
                        bprobe = dp
                        bscore = sc
                        best = fa
                        if m == cap:
                            cap *= 2
                            ri2 = np.empty((cap, 5), dtype=np.int64)
                            ri2[:m] = ri[:m]
                            ri = ri2
                            rf2 = np.empty((cap, 26))
                            rf2[:m] = rf[:m]
                            rf = rf2
                        ri[m, 0] = fc
                        ri[m, 1] = k
                        ri[m, 2] = fa
                        ri[m, 3] = key
                        ri[m, 4] = itf
                        rf[m, 0] = g
                        rf[m, 1] = trib
                        rf[m, 2] = px
                        rf[m, 3] = py
                        rf[m, 4] = pz
                        for j in range(9):
                            rf[m, 5 + j] = out[5 + j]
                        for j in range(4):
                            rf[m, 14 + j] = wc[j]
                            rf[m, 18 + j] = wa[j]
                        rf[m, 22] = out[0]
                        rf[m, 23] = out[1]
                        rf[m, 24] = dout
                        rf[m, 25] = dp
                if best >= 0:
                    m += 1
    return ri[:m], rf[:m]


@njit(cache=True)
def _boxes_meet(flo, fhi, f, blo, bhi, b, pad):
    for c in range(3):
        if flo[f, c] > bhi[b, c] + pad or fhi[f, c] < blo[b, c] - pad:
            return False
    return True


# ----------------------------------------------------------------------------- public API
def _check_flat(bx, bnode_body, bfaces, bface_body):
    bx = np.ascontiguousarray(bx, dtype=np.float64)
    if bx.ndim != 2 or bx.shape[1] != 3:
        raise InputError(f"bx: expected an (n, 3) array, got shape {bx.shape}")
    bfaces = np.asarray(bfaces, dtype=np.int64)
    if bfaces.ndim != 2 or bfaces.shape[1] not in (3, 4):
        raise InputError(f"bfaces: expected an (nf, 3) or (nf, 4) array, got shape {bfaces.shape}")
    if bfaces.shape[1] == 3:
        bfaces = np.column_stack([bfaces, -np.ones(len(bfaces), dtype=np.int64)])
    bfaces = np.ascontiguousarray(bfaces)
    bnode_body = np.asarray(bnode_body, dtype=np.int64)
    bface_body = np.asarray(bface_body, dtype=np.int64)
    if bnode_body.shape != (len(bx),) or bface_body.shape != (len(bfaces),):
        raise InputError("bnode_body / bface_body: expected one body id per boundary node / face")
    if len(bfaces):
        if bfaces[:, :3].min() < 0 or bfaces.max() >= len(bx):
            raise InputError(f"bfaces: expected node indices in [0, {len(bx)}) (-1 only in column 3)")
        used = bfaces >= 0
        if np.any(bnode_body[np.where(used, bfaces, 0)][used] != np.repeat(bface_body, used.sum(axis=1))):
            raise InputError("bfaces: every face must reference nodes of its own body (bface_body)")
    if not np.all(np.isfinite(bx)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(bx), axis=1))[0])
        raise InputError(f"body {int(bnode_body[bad])}: boundary node {bad} has a non-finite position")
    return bx, bnode_body, bfaces, bface_body


def face_geometry(bx, bfaces):
    """(coef, nv, normal at centre, area, lo, hi) per face (see `_face_data`)."""
    return _face_data(np.ascontiguousarray(bx, dtype=float), np.ascontiguousarray(bfaces, dtype=np.int64),
                      _GX, _GW)


def project_point(bx, bfaces, face: int, p):
    """Orthogonal projection of p on one face: dict(ref (2,), x (3,), n, t, s (3,), gap, inside (tol 1e-9),
    ok). For tests and diagnostics; the detection kernel uses the same code."""
    bfaces = np.asarray(bfaces, dtype=np.int64)
    if bfaces.shape[1] == 3:
        bfaces = np.column_stack([bfaces, -np.ones(len(bfaces), dtype=np.int64)])
    coef, nv, *_ = face_geometry(bx, bfaces)
    out = np.zeros(15)
    ok = _project(coef, nv, int(face), float(p[0]), float(p[1]), float(p[2]), out)
    w = np.zeros(4)
    inside = bool(ok and _weights(nv[face], out[0], out[1], 1e-9, w))
    return dict(ref=out[0:2].copy(), x=out[2:5].copy(), n=out[5:8].copy(), t=out[8:11].copy(),
                s=out[11:14].copy(), gap=float(out[14]), inside=inside, ok=bool(ok), w=w)


def detect(bx, bnode_body, bnode_local, bfaces, bface_body, kind, body_group, table: InterfaceTable,
           reach_frac: float = 0.25, inside_tol: float = 1e-9, vertical: int = 2, bodies=None) -> ContactSet:
    """Contact points between 3D bodies (module docstring). Flat inputs as returned by `flatten_boundaries`;
    kind[b] 0 deformable / 1 rigid; body_group[b] group id (rows of table.pair_iface).
    bodies: (nb,) bool, or None: only the contacts whose candidate body is one of `bodies` (a rank's own bodies),
    bitwise the rows of the whole detection that have such a candidate, in the same (key, antagonist body) order.
    The narrow phase runs on the body pairs with a body of `bodies` (a subsequence of the whole set's pairs) and keeps
    the matches of their candidates: every point of such a candidate keeps all its matches, in the whole detection's
    relative order, so the selections and the node points' area sums are the same."""
    bx, bnode_body, bfaces, bface_body = _check_flat(bx, bnode_body, bfaces, bface_body)
    bnode_local = np.asarray(bnode_local, dtype=np.int64)
    if bnode_local.shape != (len(bx),):
        raise InputError("bnode_local: expected one body-local id per boundary node")
    table.validate()
    kind = np.ascontiguousarray(kind, dtype=np.int64)
    body_group = np.ascontiguousarray(body_group, dtype=np.int64)
    nb = len(kind)
    if body_group.shape != (nb,):
        raise InputError(f"body_group: expected {nb} entries (one per body), got {body_group.shape}")
    if len(bface_body) and (bface_body.min() < 0 or bface_body.max() >= nb):
        raise InputError(f"bface_body: expected body ids in [0, {nb})")
    if nb and (body_group.min() < 0 or body_group.max() >= table.pair_iface.shape[0]):
        raise InputError(f"body_group: expected group ids in [0, {table.pair_iface.shape[0]})")
    if not 0 <= reach_frac <= 1:
        raise InputError("reach_frac: expected 0 <= reach_frac <= 1")
    if vertical not in (0, 1, 2):
        raise InputError(f"vertical: expected the index 0, 1 or 2 of the vertical axis, got {vertical!r}")
    if not 0 <= inside_tol < 0.5:
        raise InputError("inside_tol: expected 0 <= inside_tol < 0.5")
    if bodies is not None:
        bodies = np.asarray(bodies)
        if bodies.shape != (nb,) or bodies.dtype != bool:
            raise InputError(f"bodies: expected {nb} booleans (one per body), got {bodies.dtype} {bodies.shape}")
    coef, nv, nrm, farea, flo, fhi = _face_data(bx, bfaces, _GX, _GW)
    scale = max(1.0, float(np.ptp(bx))) if len(bx) else 1.0
    bad = farea <= 1e-12 * scale * scale
    if np.any(bad):
        f = int(np.flatnonzero(bad)[0])
        raise InputError(f"body {int(bface_body[f])}: boundary face {f} has zero area (degenerate face)")
    empty = _empty_set()
    if nb < 2 or len(bfaces) == 0:
        return empty
    # body boxes (of their faces' nodes) and body pairs
    blo, bhi = body_boxes(flo, fhi, bface_body, nb)
    ids = np.flatnonzero(np.isfinite(blo[:, 0]))  # the bodies with faces
    search = float(np.max(table.g0 + table.alert))
    bp = box_pairs(blo[ids] - 0.5 * search, bhi[ids] + 0.5 * search)
    bpairs = np.ascontiguousarray(ids[bp]) if len(bp) else np.zeros((0, 2), dtype=np.int64)
    if bodies is not None:  # (the pairs of a candidate of `bodies`, among others)
        bpairs = np.ascontiguousarray(bpairs[bodies[bpairs[:, 0]] | bodies[bpairs[:, 1]]])
    # positions sorted per interface
    pos = np.sort(np.where(table.positions >= 0, table.positions, np.inf), axis=1)
    npos = np.isfinite(pos).sum(axis=1).astype(np.int64)
    pos = np.ascontiguousarray(np.where(np.isfinite(pos), pos, -1.0))
    KP = int(max(3, np.max(npos) ** 2 if len(npos) else 1, 4))
    face_order = np.argsort(bface_body, kind="stable").astype(np.int64)  # faces grouped by body
    face_start = np.zeros(nb + 1, dtype=np.int64)
    face_start[1:] = np.cumsum(np.bincount(bface_body, minlength=nb))
    ri, rf = _narrow(bpairs, bx, bfaces, face_order, face_start, coef, nv, nrm, farea, flo, fhi, blo, bhi,
                      kind, body_group, np.ascontiguousarray(table.pair_iface, dtype=np.int64),
                      np.asarray(table.g0, float), np.asarray(table.alert, float),
                      np.asarray(table.placement, np.int64), pos, npos, np.asarray(table.tri_rule, np.int64),
                      np.asarray(table.cand_group, np.int64), np.asarray(table.cos_max_angle, float),
                      float(reach_frac), float(inside_tol), KP, _GX, _GW)
    if bodies is not None:  # the matches of the candidates of `bodies` (every match of their points)
        m = bodies[bface_body[ri[:, 0]]]
        ri, rf = ri[m], rf[m]
    if len(ri) == 0:
        return empty
    cf, ka, af, key, itf = ri.T
    ant_b = bface_body[af]
    score = np.hypot(rf[:, 0] - table.g0[itf], rf[:, 24])  # as in the kernel: |g - g0| and the distance outside
    # stage 1: one match per (key, candidate face) — the nearest over antagonist bodies
    probe = rf[:, 25]
    o = np.lexsort((af, score, probe, cf, key))
    first = np.ones(len(o), dtype=bool)
    first[1:] = (key[o][1:] != key[o][:-1]) | (cf[o][1:] != cf[o][:-1])
    s1 = o[first]
    # stage 2: one contact per (key, antagonist body); area summed over the candidate faces (node points)
    o2 = np.lexsort((af[s1], score[s1], probe[s1], ant_b[s1], key[s1]))
    s2 = s1[o2]
    head = np.ones(len(s2), dtype=bool)
    head[1:] = (key[s2][1:] != key[s2][:-1]) | (ant_b[s2][1:] != ant_b[s2][:-1])
    grp = np.cumsum(head) - 1
    area = np.zeros(int(head.sum()))
    np.add.at(area, grp, rf[s2, 1])
    sel = s2[head]
    cf, ka, af, key, itf = cf[sel], ka[sel], af[sel], key[sel], itf[sel]
    R = rf[sel]
    node_pt = table.placement[itf] == 1
    cnodes = np.where(bfaces[cf] >= 0, bnode_local[np.maximum(bfaces[cf], 0)], -1)
    cw = R[:, 14:18].copy()
    if np.any(node_pt):
        i = np.flatnonzero(node_pt)
        cnodes[i] = -1
        cnodes[i, 0] = bnode_local[bfaces[cf[i], ka[i]]]
        cw[i] = 0.0
        cw[i, 0] = 1.0
    anodes = np.where(bfaces[af] >= 0, bnode_local[np.maximum(bfaces[af], 0)], -1)
    n = R[:, 5:8]
    hsplit = table.split_head[itf]
    use_head = (hsplit >= 0) & (np.abs(n[:, vertical]) < np.sqrt(0.5))
    itf = np.where(use_head, hsplit, itf)
    return ContactSet(
        cand_body=bface_body[cf], ant_body=bface_body[af], cand_nodes=cnodes, cand_w=cw, ant_nodes=anodes,
        ant_w=R[:, 18:22].copy(), point=R[:, 2:5].copy(), n=n.copy(), t=R[:, 8:11].copy(), s=R[:, 11:14].copy(),
        gap=R[:, 0].copy(), g0=np.asarray(table.g0, float)[itf], area=area, interface=itf.astype(np.int64),
        cand_face=cf.astype(np.int64), ant_face=af.astype(np.int64), ant_ref=R[:, 22:24].copy(),
        key=key.astype(np.int64))


def _empty_set() -> ContactSet:
    z = np.zeros(0)
    zi = np.zeros(0, dtype=np.int64)
    return ContactSet(cand_body=zi, ant_body=zi, cand_nodes=np.zeros((0, 4), np.int64), cand_w=np.zeros((0, 4)),
                        ant_nodes=np.zeros((0, 4), np.int64), ant_w=np.zeros((0, 4)), point=np.zeros((0, 3)),
                        n=np.zeros((0, 3)), t=np.zeros((0, 3)), s=np.zeros((0, 3)), gap=z, g0=z, area=z,
                        interface=zi, cand_face=zi, ant_face=zi, ant_ref=np.zeros((0, 2)), key=zi)


@njit(cache=True)
def _update(bx, bfaces, coef, nv, cand_face, cand_slots, cand_w, ant_face, point, n, t, s, gap, ref, ant_w):
    """Candidate points from their weights, re-projected on the same antagonist faces (see update_geometry)."""
    out = np.empty(15)
    w = np.empty(4)
    bad = -1
    for c in range(cand_face.shape[0]):
        for d in range(3):
            acc = 0.0
            for k in range(4):
                node = cand_slots[c, k]
                if node >= 0:
                    acc += cand_w[c, k] * bx[node, d]
            point[c, d] = acc
        if not _project(coef, nv, ant_face[c], point[c, 0], point[c, 1], point[c, 2], out):
            bad = c
            continue
        _weights(nv[ant_face[c]], out[0], out[1], np.inf, w)
        for d in range(3):
            n[c, d] = out[5 + d]
            t[c, d] = out[8 + d]
            s[c, d] = out[11 + d]
        for k in range(4):
            ant_w[c, k] = w[k]
        gap[c] = out[14]
        ref[c, 0] = out[0]
        ref[c, 1] = out[1]
    return bad


def update_geometry(cs: ContactSet, bx, bfaces) -> ContactSet:
    """Same pairs, candidate weights and areas; candidate points, projections (same antagonist faces, weights
    clamped into the face), frames and gaps recomputed from the current positions `bx` (small-sliding mode).
    bfaces as given to `detect`."""
    bx = np.ascontiguousarray(bx, dtype=float)
    bfaces = np.asarray(bfaces, dtype=np.int64)
    if bfaces.shape[1] == 3:
        bfaces = np.column_stack([bfaces, -np.ones(len(bfaces), dtype=np.int64)])
    bfaces = np.ascontiguousarray(bfaces)
    coef, nv, *_ = _face_data(bx, bfaces, _GX, _GW)
    nc = len(cs)
    # bx slots of the candidate nodes: face corners for position points, the node itself for node points
    slots = bfaces[cs.cand_face].copy()
    node_pt = cs.key < 0
    slots[node_pt] = -1
    slots[node_pt, 0] = -cs.key[node_pt] - 1
    out = ContactSet(**dict(cs.__dict__))
    out.point, out.n, out.t, out.s = (np.zeros((nc, 3)) for _ in range(4))
    out.gap, out.ant_ref, out.ant_w = np.zeros(nc), np.zeros((nc, 2)), np.zeros((nc, 4))
    bad = _update(bx, bfaces, coef, nv, cs.cand_face, np.ascontiguousarray(slots), cs.cand_w, cs.ant_face,
                  out.point, out.n, out.t, out.s, out.gap, out.ant_ref, out.ant_w)
    if bad >= 0:
        raise InputError(f"contact {bad}: its projection on antagonist face {int(cs.ant_face[bad])} failed "
                         f"(degenerate face)")
    return out
