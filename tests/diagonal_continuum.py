"""An INDEPENDENT estimate of the diagonal-compression panel's modulus of rigidity G (tests/test_lab_diagonal.py):
one continuum of the same brick-joint pattern, the joints as thin elastic layers, linear elasticity (plane stress,
fem_backend.assemble_stiffness_cells, two materials by cell tags), the same corner loads, read out by the same
formulas (S_s = 0.707 P / A_n, gamma = (dV + dH)/g).

The discrete model (expanded bricks, zero-thickness interfaces k_n, k_s) has, across a joint region of thickness
t_j, the brick's material over t_j in series with the interface. The equivalent layer of thickness t_j (centred on
the interface line) has the same compliances:

    normal:  t_j / M_j = t_j / E_b + 1 / k_n     (a thin layer bonded between stiff bricks is laterally constrained:
                                                   its normal modulus is M_j = E_j / (1 - nu_j²), plane stress;
                                                   the brick strip it replaces is not: E_b)
    shear:   t_j / G_j = t_j / G_b + 1 / k_s,    G_b = E_b / (2 (1 + nu_b))
    isotropic layer:  M_j = 2 G_j / (1 - nu_j)  ->  nu_j = 1 - 2 G_j / M_j,  E_j = 2 G_j (1 + nu_j).

(The term nu_j nu_b t_j / E_b of the brick's lateral strain is neglected: 0.1 % of the normal compliance with the
demo's values.) The panel's outer half-joints are brick material in both models (no interface there).

Mesh: a rectilinear grid of Q1 quads (BlockMesh.from_cells) whose lines follow every joint layer's faces, the
shoes' ends and the panel's sides, each interval divided into ceil(length / size) cells; a cell is joint when its
centre lies in a bed-joint strip (|y - y_k| < t_j/2 at the internal course boundaries y_k) or in a head-joint strip
of its course. Loads: a frictionless rigid shoe = the normal displacement prescribed on the face's nodes it
covers, the tangential free: lower-left shoe u_y = 0 on the bottom face x <= s and u_x = 0 on the left face
y <= s; upper-right shoe u = -delta e on the top face (u_y) for x >= w - s and the right face (u_x) for y >= h - s.
P = -(f_top + f_right) . e with f = K u the nodal forces of the prescribed dofs.
"""
from __future__ import annotations

import math

import numpy as np
import scipy.sparse.linalg as spla

from fem_blocks.fem_backend import assemble_stiffness_cells
from fem_blocks.meshing import BlockMesh


def equivalent_layer(k_n, k_s, t_j, E_b, nu_b):
    """(E_j, nu_j, G_j, M_j) of the thin joint layer (module docstring)."""
    G_b = E_b / (2 * (1 + nu_b))
    M_j = t_j / (t_j / E_b + 1.0 / k_n)
    G_j = t_j / (t_j / G_b + 1.0 / k_s)
    nu_j = 1.0 - 2.0 * G_j / M_j
    return 2.0 * G_j * (1.0 + nu_j), nu_j, G_j, M_j


def _breaks(points, lo, hi, size):
    p = np.unique(np.round(np.clip(np.asarray(points, dtype=float), lo, hi), 12))
    out = [p[0]]
    for a, b in zip(p[:-1], p[1:]):
        n = max(1, int(math.ceil((b - a) / size - 1e-9)))
        out += list(a + (b - a) * np.arange(1, n + 1) / n)
    return np.array(out)


def continuum_G(bricks, w, h, t_j, shoe, gauges, g, E_b, nu_b, k_n, k_s, thickness, size, delta=1e-4):
    """G [Pa] of the continuum panel (module docstring). `bricks`: [(name, x0, y0, lx, ly, ...)] of the expanded
    bricks (whole bricks: no crack); `gauges`: {"V1", "V2", "H1", "H2": (x, y, ...)}; SI. Returns dict(G, S_s,
    gamma, P, n_cells, n_joint_cells, layer)."""
    ys = sorted({round(b[2], 12) for b in bricks} | {round(b[2] + b[4], 12) for b in bricks})
    inner_y = [y for y in ys if 1e-12 < y < h - 1e-12]
    heads = []   # (y0, y1, x) of the internal head joints
    for b in bricks:
        if b[1] > 1e-12:
            heads.append((b[2], b[2] + b[4], b[1]))
    xb = [0.0, w, shoe, w - shoe] + [x + d for _, _, x in heads for d in (-0.5 * t_j, 0.5 * t_j)]
    yb = [0.0, h, shoe, h - shoe] + [y + d for y in inner_y for d in (-0.5 * t_j, 0.5 * t_j)]
    X, Y = _breaks(xb, 0.0, w, size), _breaks(yb, 0.0, h, size)
    nx, ny = len(X), len(Y)
    PX, PY = np.meshgrid(X, Y)                     # node (j, i) = j * nx + i
    pts = np.column_stack([PX.ravel(), PY.ravel()])
    J, I = np.meshgrid(np.arange(ny - 1), np.arange(nx - 1), indexing="ij")
    n0 = (J * nx + I).ravel()
    cells = np.column_stack([n0, n0 + 1, n0 + 1 + nx, n0 + nx])
    xc, yc = 0.5 * (X[I] + X[I + 1]).ravel(), 0.5 * (Y[J] + Y[J + 1]).ravel()
    joint = np.zeros(len(cells), dtype=bool)
    for y in inner_y:
        joint |= np.abs(yc - y) < 0.5 * t_j
    for y0, y1, x in heads:
        joint |= (yc > y0) & (yc < y1) & (np.abs(xc - x) < 0.5 * t_j)
    mesh = BlockMesh.from_cells(pts, cells, "quad", source="continuum panel")
    E_j, nu_j, G_j, M_j = equivalent_layer(k_n, k_s, t_j, E_b, nu_b)
    K = assemble_stiffness_cells(mesh, np.where(joint, E_j, E_b), np.where(joint, nu_j, nu_b), thickness, "stress")
    e = np.array([w, h]) / math.hypot(w, h)
    tol = 1e-9 * max(w, h)
    x, y = pts[:, 0], pts[:, 1]
    fixed = {}   # dof -> value
    for n in np.flatnonzero((np.abs(y) < tol) & (x <= shoe + tol)):
        fixed[2 * n + 1] = 0.0
    for n in np.flatnonzero((np.abs(x) < tol) & (y <= shoe + tol)):
        fixed[2 * n] = 0.0
    top = np.flatnonzero((np.abs(y - h) < tol) & (x >= w - shoe - tol))
    right = np.flatnonzero((np.abs(x - w) < tol) & (y >= h - shoe - tol))
    for n in top:
        fixed[2 * n + 1] = -delta * e[1]
    for n in right:
        fixed[2 * n] = -delta * e[0]
    dofs = np.array(sorted(fixed), dtype=np.int64)
    vals = np.array([fixed[d] for d in dofs])
    free = np.setdiff1d(np.arange(K.shape[0]), dofs)
    K = K.tocsr()
    u = np.zeros(K.shape[0])
    u[dofs] = vals
    u[free] = spla.spsolve(K[free][:, free].tocsc(), -K[free][:, dofs] @ vals)
    f = K @ u
    P = -(f[2 * top + 1].sum() * e[1] + f[2 * right].sum() * e[0])

    def disp(p):   # bilinear interpolation in the grid cell holding p
        i = min(max(int(np.searchsorted(X, p[0]) - 1), 0), nx - 2)
        j = min(max(int(np.searchsorted(Y, p[1]) - 1), 0), ny - 2)
        a, b = (p[0] - X[i]) / (X[i + 1] - X[i]), (p[1] - Y[j]) / (Y[j + 1] - Y[j])
        U = u.reshape(-1, 2)
        return ((1 - a) * (1 - b) * U[j * nx + i] + a * (1 - b) * U[j * nx + i + 1]
                + a * b * U[(j + 1) * nx + i + 1] + (1 - a) * b * U[(j + 1) * nx + i])

    D = {k: disp(np.array(v[:2])) for k, v in gauges.items()}
    e_h = np.array([-w, h]) / math.hypot(w, h)
    dV = -(D["V2"] - D["V1"]) @ e
    dH = (D["H2"] - D["H1"]) @ e_h
    gamma = (dV + dH) / g
    S_s = 0.707 * P / (0.5 * (w + h) * thickness)
    return dict(G=S_s / gamma, S_s=S_s, gamma=gamma, P=P, n_cells=len(cells), n_joint_cells=int(joint.sum()),
                layer=dict(E_j=E_j, nu_j=nu_j, G_j=G_j, M_j=M_j))
