"""Displacement gauges: the displacement of a material point of a deformable block (`[output] gauges`).

A gauge at the reference position x of a block lies in one cell of the block's mesh; its displacement is the
finite-element interpolation u(x) = Σ_a N_a(ξ) u_a over that cell's nodes a, ξ the cell's local coordinates of x:

* triangle / tetrahedron (linear): N = barycentric coordinates, solved from x = Σ N_a X_a, Σ N_a = 1;
* quadrilateral / hexahedron (bilinear / trilinear, ξ in [-1, 1]^d): N_a(ξ) = Π_i (1 + ξ_i ξ_i^a) / 2, ξ found by
  Newton on x(ξ) = Σ N_a(ξ) X_a from ξ = 0 (exact for a parallelogram after one iteration).

The cell and its weights N_a are found once, in the block's reference configuration (`locate`); every row of
history.csv then costs one small dot product per gauge (`gauge_values`). Pure functions on arrays.
"""
from __future__ import annotations

import numpy as np

# local node coordinates of the linear quad (counter-clockwise) and hexahedron (gmsh/dolfinx VTK order)
_QUAD = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)
_HEX = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                 [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=np.float64)


def _tensor_shape(xi: np.ndarray, ref: np.ndarray):
    """N_a(ξ) and dN_a/dξ (nv, d) of the bilinear/trilinear cell with local nodes `ref`."""
    f = 0.5 * (1.0 + ref * xi)             # (nv, d)
    N = np.prod(f, axis=1)
    dN = np.empty_like(ref)
    for i in range(ref.shape[1]):
        others = np.prod(np.delete(f, i, axis=1), axis=1)
        dN[:, i] = 0.5 * ref[:, i] * others
    return N, dN


def cell_weights(X: np.ndarray, x: np.ndarray, cell_type: str, tol: float = 1e-9):
    """Weights N_a of point x in the cell of node coordinates X (nv, d), or None if x is outside the cell (by more
    than `tol` in local coordinates)."""
    d = X.shape[1]
    if cell_type in ("triangle", "tetrahedron"):
        A = np.vstack([X.T, np.ones(len(X))])
        try:
            N = np.linalg.solve(A, np.append(x, 1.0))
        except np.linalg.LinAlgError:
            return None
        return N if N.min() >= -tol else None
    ref = _QUAD if cell_type == "quad" else _HEX
    xi = np.zeros(d)
    for _ in range(20):
        N, dN = _tensor_shape(xi, ref)
        r = N @ X - x
        J = X.T @ dN                         # dx/dξ
        try:
            dxi = np.linalg.solve(J, r)
        except np.linalg.LinAlgError:
            return None
        xi -= dxi
        if np.max(np.abs(dxi)) < 1e-14:
            break
    if np.max(np.abs(xi)) > 1.0 + tol:
        return None
    return _tensor_shape(xi, ref)[0]


def locate(points: np.ndarray, cells: np.ndarray, cell_type: str, x) -> tuple[int, np.ndarray] | None:
    """(cell index, weights) of the first cell of the mesh (node coordinates `points`, connectivity `cells`) that
    holds point x; None if no cell does. Candidate cells by bounding box, then `cell_weights`."""
    x = np.asarray(x, dtype=np.float64)
    P = points[cells]                                   # (nc, nv, d)
    h = np.max(P.max(axis=1) - P.min(axis=1), axis=1)   # cell sizes (bounding-box tolerance)
    near = np.flatnonzero(np.all((P.min(axis=1) - 1e-9 * h[:, None] <= x)
                                 & (x <= P.max(axis=1) + 1e-9 * h[:, None]), axis=1))
    for c in near:
        w = cell_weights(P[c], x, cell_type)
        if w is not None:
            return int(c), w
    return None


def gauge_values(disp: np.ndarray, nodes: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """u(x) = Σ_a N_a u_a: `disp` (n_nodes, d) the block's nodal displacements, `nodes` the cell's nodes."""
    return weights @ disp[nodes]
