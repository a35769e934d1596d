"""Pure geometry of block input (numpy only, no meshing): the corners of a box, the check of a hexahedral block
given by its 8 corners (gmsh order), rotation matrices. The case-file layer (case.py) validates input with
these; meshing.py and bodies.py use them too (and re-export them under their old names).

Hexahedron corners, gmsh order: 0-3 the bottom face counter-clockwise seen from the top face 4-7, corner 4+i above
corner i, i.e. reference coordinates HEX_XI in [-1, 1]^3; the trilinear map x(xi) = sum_a N_a(xi) x_a,
N_a = prod_j (1 + xi_a,j xi_j) / 8.
"""
from __future__ import annotations

import numpy as np

from .errors import InputError

# reference coordinates of the gmsh hexahedron nodes
HEX_XI = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                   [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=np.float64)


def hex_shape_gradients(xi: np.ndarray) -> np.ndarray:
    """dN_a/dxi_j of the trilinear hexahedron at reference points xi (k,3): (k, 8, 3),
    N_a = prod_j (1 + xi_a,j xi_j) / 8."""
    xi = np.atleast_2d(xi)
    f = 1.0 + HEX_XI[None, :, :] * xi[:, None, :]  # (k, 8, 3)
    dN = np.empty_like(f)
    for j in range(3):
        dN[:, :, j] = HEX_XI[None, :, j] / 8.0 * np.prod(np.delete(f, j, axis=2), axis=2)
    return dN


def check_hex_corners(corners, name: str = "hexahedron") -> np.ndarray:
    """(8,3) float corners of a hexahedral block in the gmsh order (0-3 the bottom face, counter-clockwise
    seen from the top face 4-7, corner 4+i above corner i); InputError if the trilinear block is inverted,
    folded or flat (det J checked on a 5x5x5 grid of the reference cube)."""
    C = np.asarray(corners, dtype=np.float64)
    if C.shape != (8, 3) or not np.all(np.isfinite(C)):
        raise InputError(f"{name}.corners: expected 8 finite (x, y, z) points, got shape {np.shape(corners)}")
    g = np.linspace(-1, 1, 5)
    xi = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    d = np.linalg.det(np.einsum("ai,kaj->kij", C, hex_shape_gradients(xi)))
    scale = np.ptp(C, axis=0).max() ** 3
    if np.all(d < 0):
        raise InputError(f"{name}.corners: the block is inverted (corners 0-3 run clockwise seen from corners "
                         f"4-7); expected the bottom face 0-3 counter-clockwise seen from the top face 4-7")
    if np.any(d <= 1e-10 * scale):
        raise InputError(f"{name}.corners: the hexahedral block is folded or flat (det J <= 0 inside); expected "
                         f"a convex-like block with corners in the gmsh order")
    return C


def box_corners(lx: float, ly: float, lz: float, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Corners of [0,lx]x[0,ly]x[0,lz] + origin in the gmsh hexahedron order."""
    return np.asarray(origin, dtype=np.float64).reshape(3) + HEX_XI.clip(0, 1) * np.array([lx, ly, lz], float)


def rotation3d(axis, angle: float | None = None) -> np.ndarray:
    """Rotation matrix exp([w]x) (Rodrigues): `rotation3d(w)` for a rotation vector w (angle |w| about w/|w|),
    or `rotation3d(axis, angle)`."""
    w = np.asarray(axis, dtype=float).reshape(3)
    if angle is not None:
        nrm = np.linalg.norm(w)
        if nrm == 0.0:
            raise InputError(f"rotation axis = {axis!r}: expected a non-zero vector")
        w = w / nrm * float(angle)
    th = np.linalg.norm(w)
    if th == 0.0:
        return np.eye(3)
    k = w / th
    Kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(th) * Kx + (1.0 - np.cos(th)) * (Kx @ Kx)
