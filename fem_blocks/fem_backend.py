"""Finite-element operators of a block type: THE ONLY module of fem_blocks that imports dolfinx.

dolfinx 0.5.2 API (Debian bookworm). A newer dolfinx (0.7–0.9) changes this file only.

Linear elasticity, small strain, P1 (triangles) / Q1 (quads), 2D:

    K = t ∫ sigma(u) : eps(v) dx,   sigma = lambda* tr(eps) I + 2 mu eps,
    plane strain lambda* = lambda, plane stress lambda* = 2 lambda mu / (lambda + 2 mu),
    M = t rho ∫ u . v dx  (consistent),  lumped: vertex quadrature on triangles, row sum on quads,
    Q1 integrated with 2 x 2 Gauss points,

with t the thickness. Returned as scipy CSR in the BlockMesh node order, dof `2*node + c`.
The cell-centroid stress operator S (3 nc x 2n) is plain numpy (no dolfinx).
3D (BlockMesh3D, P1 tetrahedra / Q1 hexahedra, dof `3*node + c`): assemble_operators_3d, stress_operator_3d.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .errors import InputError, check_range


@dataclass
class FEOperators:
    K: sp.csr_matrix
    M_consistent: sp.csr_matrix
    M_lumped: sp.csr_matrix


def check_elastic(E, nu, plane):
    """E > 0, -1 < nu < 0.5, plane in {"stress", "strain"}; InputError naming the field otherwise."""
    check_range("E", E, 0.0, lo_open=True, expected="E > 0 [Pa]")
    check_range("nu", nu, -1.0, 0.5, lo_open=True, hi_open=True, expected="-1 < nu < 0.5")
    if plane not in ("stress", "strain"):
        raise InputError(f"plane = {plane!r}: expected 'stress' or 'strain'")


def check_material(E, nu, rho, thickness, plane):
    check_elastic(E, nu, plane)
    check_range("rho", rho, 0.0, lo_open=True, expected="rho > 0 [kg/m^3]")
    check_range("thickness", thickness, 0.0, lo_open=True, expected="thickness > 0 [m]")


def lame(E, nu, plane):
    """(lambda*, mu) of the 2D model."""
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    if plane == "stress":
        lam = 2 * lam * mu / (lam + 2 * mu)
    return lam, mu


def _petsc_to_scipy(A, perm) -> sp.csr_matrix:
    """PETSc AIJ (dolfinx dof order) -> scipy CSR in BlockMesh dof order: A_ours[perm[i], perm[j]] = A[i, j]."""
    indptr, indices, data = A.getValuesCSR()
    n = len(indptr) - 1
    rows = np.repeat(np.arange(n), np.diff(indptr))
    B = sp.coo_matrix((data, (perm[rows], perm[indices])), shape=(n, n)).tocsr()
    B.sum_duplicates()
    B.eliminate_zeros()
    return B


class _quiet_jit:
    """Drop the INFO records ("running build_ext", gcc command lines) that a JIT cache miss logs on the root
    logger (setuptools resets the root level during the build, so a filter is used, not the level)."""

    @staticmethod
    def filter(record):
        return record.levelno >= 30  # logging.WARNING

    def __enter__(self):
        import logging
        logging.getLogger().addFilter(self.filter)

    def __exit__(self, *exc):
        import logging
        logging.getLogger().removeFilter(self.filter)
        return False


def assemble_operators(mesh, E, nu, rho, thickness=1.0, plane="stress") -> FEOperators:
    """K, M (consistent and lumped) of a BlockMesh with dolfinx, in the BlockMesh dof order."""
    check_material(E, nu, rho, thickness, plane)
    lam_, mu_ = lame(E, nu, plane)
    # Q1: standard 2x2 Gauss (basix degree 2 and 3 on quadrilaterals), exact for K on parallelograms and for M
    # on any quadrilateral (N_a N_b det J is cubic per direction)
    return _assemble_fe(mesh, 2, lam_, mu_, float(thickness), float(thickness) * float(rho), (2, 3))


def _function_space(mesh, gdim):
    """(dolfinx mesh, P1/Q1 vector space, perm): `perm[i]` = the BlockMesh dof (gdim*node + c) of dolfinx dof i;
    the dolfinx cells keep the BlockMesh cell order through `msh.topology.original_cell_index`."""
    from mpi4py import MPI
    from dolfinx import cpp, fem, mesh as dmesh
    from dolfinx.io import gmshio

    tensor = mesh.cell_type in ("quad", "hexahedron")
    gmsh_type = {"triangle": 2, "quad": 3, "tetrahedron": 4, "hexahedron": 5}[mesh.cell_type]
    cells = np.asarray(mesh.cells, dtype=np.int64)
    if tensor:  # gmsh -> dolfinx (tensor-product) vertex order
        dcell = cpp.mesh.CellType.quadrilateral if gdim == 2 else cpp.mesh.CellType.hexahedron
        cells = cells[:, cpp.io.perm_gmsh(dcell, cells.shape[1])]
    domain = gmshio.ufl_mesh(gmsh_type, gdim)  # one ufl.Mesh per dolfinx mesh (0.5.2 requirement)
    msh = dmesh.create_mesh(MPI.COMM_SELF, cells, np.ascontiguousarray(mesh.points, dtype=np.float64), domain)
    with _quiet_jit():
        V = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
    n = mesh.points.shape[0]
    if V.dofmap.index_map.size_local != n:
        raise InputError(f"{mesh.source}: dolfinx built {V.dofmap.index_map.size_local} nodes for {n} mesh nodes")
    # dolfinx node j -> geometry node d2g[j] -> input (BlockMesh) node igi[d2g[j]]
    d2g = np.empty(n, dtype=np.int64)
    d2g[V.dofmap.list.array] = msh.geometry.dofmap.array
    node = np.asarray(msh.geometry.input_global_indices, dtype=np.int64)[d2g]
    perm = (gdim * node[:, None] + np.arange(gdim)[None, :]).ravel()
    return msh, V, perm


def _assemble_fe(mesh, gdim, lam_, mu_, k_scale, m_scale, tensor_degrees) -> FEOperators:
    """K = k_scale ∫ sigma(u) : eps(v) dx (k_scale None: no factor), M = m_scale ∫ u . v dx and the lumped M
    (vertex quadrature on simplices, row sum on quadrangles/hexahedra) of a linear Lagrange space on `mesh`
    (gdim 2: triangle|quad, 3: tetrahedron|hexahedron) with dolfinx; scipy CSR in the mesh dof order
    gdim*node + c. tensor_degrees: (K, M) quadrature degrees on quadrangles/hexahedra (simplices: the degrees
    estimated by ufl, exact for P1)."""
    import ufl
    from dolfinx import fem
    from dolfinx.fem.petsc import assemble_matrix

    tensor = mesh.cell_type in ("quad", "hexahedron")
    msh, V, perm = _function_space(mesh, gdim)

    # material data as dolfinx Constants (not literals): the generated kernels do not depend on the material,
    # so they are JIT-compiled once per cell type and found in the cache for every other material
    lam, mu = fem.Constant(msh, float(lam_)), fem.Constant(msh, float(mu_))
    mc = fem.Constant(msh, float(m_scale))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    eps = lambda w: ufl.sym(ufl.grad(w))  # noqa: E731
    sig = lambda w: lam * ufl.tr(eps(w)) * ufl.Identity(gdim) + 2 * mu * eps(w)  # noqa: E731
    if tensor:
        dx_k = ufl.dx(metadata={"quadrature_degree": tensor_degrees[0]})
        dx_m = ufl.dx(metadata={"quadrature_degree": tensor_degrees[1]})
    else:
        dx_k = dx_m = ufl.dx  # P1: exact by the estimated degrees (0 and 2)
    k_int = ufl.inner(sig(u), eps(v))
    if k_scale is not None:
        k_int = fem.Constant(msh, float(k_scale)) * k_int
    with _quiet_jit():
        k_form = fem.form(k_int * dx_k)
        m_form = fem.form(mc * ufl.inner(u, v) * dx_m)
    mats = []
    for f in (k_form, m_form):
        A = assemble_matrix(f)
        A.assemble()
        mats.append(_petsc_to_scipy(A, perm))
        A.destroy()
    Ks, Ms = mats
    if not tensor:
        import warnings
        with warnings.catch_warnings(), _quiet_jit():
            warnings.simplefilter("ignore", UserWarning)  # "requested degree 2" of the vertex rule
            ml_form = fem.form(mc * ufl.inner(u, v) * ufl.dx(metadata={"quadrature_rule": "vertex"}))
        ML = assemble_matrix(ml_form)
        ML.assemble()
        Ml = sp.diags(_petsc_to_scipy(ML, perm).diagonal()).tocsr()
        ML.destroy()
    else:
        Ml = sp.diags(np.asarray(Ms.sum(axis=1)).ravel()).tocsr()  # row-sum lumping (Q1)
    return FEOperators(Ks, Ms, Ml)


def assemble_stiffness_cells(mesh, E, nu, thickness=1.0, plane="stress") -> sp.csr_matrix:
    """K = t ∫ sigma(u) : eps(v) dx of a 2D BlockMesh with a piecewise-constant material: `E`, `nu` arrays of one
    value per cell of `mesh` (e.g. two materials by cell tags: E = np.where(tag, E_joint, E_brick)), sigma as in
    the module docstring with lambda*(E, nu, plane), mu(E, nu) per cell (DG0 coefficients); Q1 with 2 x 2 Gauss.
    scipy CSR (2n x 2n) in the BlockMesh dof order 2*node + c. Not used by the time stepping (one material per
    block there): the continuum estimate of a brick-joint pattern (fem_blocks/lab/diagonal.py's check)."""
    import ufl
    from dolfinx import fem
    from dolfinx.fem.petsc import assemble_matrix

    E, nu = np.asarray(E, dtype=float).ravel(), np.asarray(nu, dtype=float).ravel()
    nc = len(mesh.cells)
    if E.size != nc or nu.size != nc:
        raise InputError(f"{mesh.source}: expected one E and one nu per cell ({nc}), got {E.size} and {nu.size}")
    for e, n in {(float(a), float(b)) for a, b in zip(E, nu)}:
        check_elastic(e, n, plane)
    check_range("thickness", thickness, 0.0, lo_open=True, expected="thickness > 0 [m]")
    lam_c, mu_c = lame(E, nu, plane)
    msh, V, perm = _function_space(mesh, 2)
    with _quiet_jit():
        Q = fem.FunctionSpace(msh, ("DG", 0))
    orig = np.asarray(msh.topology.original_cell_index, dtype=np.int64)   # dolfinx cell i = BlockMesh cell orig[i]
    dofs = np.asarray(Q.dofmap.list.array, dtype=np.int64)   # DG0: the one dof of each dolfinx cell
    lam, mu = fem.Function(Q), fem.Function(Q)
    lam.x.array[dofs], mu.x.array[dofs] = lam_c[orig], mu_c[orig]
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    eps = lambda w: ufl.sym(ufl.grad(w))  # noqa: E731
    dx = ufl.dx(metadata={"quadrature_degree": 2}) if mesh.cell_type == "quad" else ufl.dx
    form = fem.Constant(msh, float(thickness)) * ufl.inner(lam * ufl.tr(eps(u)) * ufl.Identity(2)
                                                          + 2 * mu * eps(u), eps(v)) * dx
    with _quiet_jit():
        k_form = fem.form(form)
    A = assemble_matrix(k_form)
    A.assemble()
    K = _petsc_to_scipy(A, perm)
    A.destroy()
    return K


# ----------------------------------------------------------------------------- stresses (numpy)
def elasticity_matrix(E, nu, plane) -> np.ndarray:
    """D with (sxx, syy, sxy) = D (exx, eyy, gxy), gxy = du/dy + dv/dx."""
    if plane == "stress":
        c = E / (1 - nu * nu)
        return c * np.array([[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]])
    c = E / ((1 + nu) * (1 - 2 * nu))
    return c * np.array([[1 - nu, nu, 0], [nu, 1 - nu, 0], [0, 0, (1 - 2 * nu) / 2]])


def centroid_gradients(mesh) -> np.ndarray:
    """dN_a/dx at each cell centroid: (nc, nv, 2) (exact constant for P1, centroid value for Q1)."""
    P = mesh.points[mesh.cells]  # (nc, nv, 2)
    if mesh.cell_type == "triangle":
        dN = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])  # d/dxi, d/deta
    else:  # bilinear on [-1,1]^2, CCW nodes (-1,-1), (1,-1), (1,1), (-1,1), at xi = eta = 0
        dN = 0.25 * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    J = np.einsum("cai,aj->cij", P, dN)  # dx_i / dxi_j
    Jinv = np.linalg.inv(J)
    return np.einsum("aj,cji->cai", dN, Jinv)


def stress_operator(mesh, E, nu, plane="stress") -> sp.csr_matrix:
    """S (3 nc x 2n): cell-centroid Cauchy stress (sxx, syy, sxy) = D B(centroid) q."""
    check_elastic(E, nu, plane)
    G = centroid_gradients(mesh)
    nc, nv = mesh.cells.shape
    B = np.zeros((nc, 3, 2 * nv))
    B[:, 0, 0::2] = G[:, :, 0]
    B[:, 1, 1::2] = G[:, :, 1]
    B[:, 2, 0::2] = G[:, :, 1]
    B[:, 2, 1::2] = G[:, :, 0]
    DB = np.einsum("ij,cjk->cik", elasticity_matrix(E, nu, plane), B)
    dofs = np.empty((nc, 2 * nv), dtype=np.int64)
    dofs[:, 0::2], dofs[:, 1::2] = 2 * mesh.cells, 2 * mesh.cells + 1
    rows = np.broadcast_to((3 * np.arange(nc))[:, None, None] + np.arange(3)[None, :, None], DB.shape)
    cols = np.broadcast_to(dofs[:, None, :], DB.shape)
    return sp.csr_matrix((DB.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * nc, 2 * mesh.points.shape[0]))


def von_mises(s: np.ndarray, nu=0.0, plane_strain=False) -> np.ndarray:
    """von Mises stress of Voigt stress rows, both dimensions (the only definition):

        sigma_vm = sqrt(((sxx - syy)² + (syy - szz)² + (szz - sxx)²) / 2 + 3 (syz² + sxz² + sxy²))

    3D rows (..., 6) = (sxx, syy, szz, syz, sxz, sxy); 2D rows (..., 3) = (sxx, syy, sxy) with syz = sxz = 0 and
    szz = nu (sxx + syy) in plane strain, 0 in plane stress (`nu`, `plane_strain`: scalars or one per row).
    Returns (n,) for the n rows."""
    s = np.asarray(s, dtype=float)
    s = s.reshape(-1, s.shape[-1])
    if s.shape[1] == 6:
        return np.sqrt(0.5 * ((s[:, 0] - s[:, 1]) ** 2 + (s[:, 1] - s[:, 2]) ** 2 + (s[:, 2] - s[:, 0]) ** 2)
                       + 3.0 * (s[:, 3] ** 2 + s[:, 4] ** 2 + s[:, 5] ** 2))
    if s.shape[1] != 3:
        raise ValueError(f"von_mises: expected Voigt rows of 3 (2D) or 6 (3D) components, got {s.shape[1]}")
    szz = np.where(plane_strain, nu * (s[:, 0] + s[:, 1]), 0.0)
    return np.sqrt(0.5 * ((s[:, 0] - s[:, 1]) ** 2 + (s[:, 1] - szz) ** 2 + (szz - s[:, 0]) ** 2) + 3.0 * s[:, 2] ** 2)


# ============================================================================= 3D
# Linear elasticity, small strain, P1 tetrahedra / Q1 hexahedra (BlockMesh3D):
#     K = ∫ sigma(u) : eps(v) dx,  sigma = lambda tr(eps) I + 2 mu eps,
#     lambda = E nu / ((1 + nu)(1 - 2 nu)),  mu = E / (2 (1 + nu)),
#     M = rho ∫ u . v dx (consistent); lumped: vertex quadrature on tetrahedra, row sum on hexahedra.
# Q1: K with 2x2x2 Gauss (exact on parallelepipeds, the standard full integration), M with 3x3x3 Gauss (exact on
# any trilinear hexahedron: N_a N_b det J is of degree 4 per reference direction). Dofs `3*node + c`.

def check_elastic_3d(E, nu):
    """E > 0, -1 < nu < 0.5; InputError naming the field otherwise."""
    check_range("E", E, 0.0, lo_open=True, expected="E > 0 [Pa]")
    check_range("nu", nu, -1.0, 0.5, lo_open=True, hi_open=True, expected="-1 < nu < 0.5")


def lame_3d(E, nu):
    """(lambda, mu) of 3D isotropic elasticity."""
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def _check_mesh3d(mesh):
    if getattr(mesh, "gdim", 2) != 3 or mesh.cell_type not in ("tetrahedron", "hexahedron"):
        raise InputError(f"{getattr(mesh, 'source', 'mesh')}: expected a 3D mesh (BlockMesh3D of tetrahedra or "
                         f"hexahedra), got cell_type {getattr(mesh, 'cell_type', None)!r}")


def assemble_operators_3d(mesh, E, nu, rho) -> FEOperators:
    """K, M (consistent and lumped) of a BlockMesh3D with dolfinx, scipy CSR (3n x 3n) in the BlockMesh3D
    node order, dof 3*node + c."""
    check_elastic_3d(E, nu)
    check_range("rho", rho, 0.0, lo_open=True, expected="rho > 0 [kg/m^3]")
    _check_mesh3d(mesh)
    lam_, mu_ = lame_3d(E, nu)
    # Q1: K with 2 Gauss points per direction, M with 3 (quadrature degrees 2 and 4)
    return _assemble_fe(mesh, 3, lam_, mu_, None, float(rho), (2, 4))


def elasticity_matrix_3d(E, nu) -> np.ndarray:
    """D (6x6) with (sxx, syy, szz, syz, sxz, sxy) = D (exx, eyy, ezz, gyz, gxz, gxy), g = engineering shear."""
    lam, mu = lame_3d(E, nu)
    D = np.zeros((6, 6))
    D[:3, :3] = lam
    D[np.arange(3), np.arange(3)] += 2 * mu
    D[np.arange(3, 6), np.arange(3, 6)] = mu
    return D


def centroid_gradients_3d(mesh) -> np.ndarray:
    """dN_a/dx at each cell centroid: (nc, nv, 3) (exact constant for P1, value at xi = 0 for Q1)."""
    from .meshing import hex_shape_gradients
    P = mesh.points[mesh.cells]  # (nc, nv, 3)
    if mesh.cell_type == "tetrahedron":
        dN = np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    else:
        dN = hex_shape_gradients(np.zeros((1, 3)))[0]
    J = np.einsum("cai,aj->cij", P, dN)  # dx_i / dxi_j
    return np.einsum("aj,cji->cai", dN, np.linalg.inv(J))


def strain_operator_3d(mesh) -> np.ndarray:
    """Element B matrices at the centroids (nc, 6, 3 nv): (exx, eyy, ezz, gyz, gxz, gxy) = B q_e,
    q_e = (u_x, u_y, u_z) per cell node."""
    G = centroid_gradients_3d(mesh)
    nc, nv = mesh.cells.shape
    B = np.zeros((nc, 6, 3 * nv))
    for i in range(3):
        B[:, i, i::3] = G[:, :, i]
    B[:, 3, 1::3], B[:, 3, 2::3] = G[:, :, 2], G[:, :, 1]  # gyz = du_y/dz + du_z/dy
    B[:, 4, 0::3], B[:, 4, 2::3] = G[:, :, 2], G[:, :, 0]  # gxz
    B[:, 5, 0::3], B[:, 5, 1::3] = G[:, :, 1], G[:, :, 0]  # gxy
    return B


def stress_operator_3d(mesh, E, nu) -> sp.csr_matrix:
    """S (6 nc x 3n): cell-centroid Cauchy stress (sxx, syy, szz, syz, sxz, sxy) = D B(centroid) q."""
    check_elastic_3d(E, nu)
    _check_mesh3d(mesh)
    DB = np.einsum("ij,cjk->cik", elasticity_matrix_3d(E, nu), strain_operator_3d(mesh))
    nc, nv = mesh.cells.shape
    dofs = (3 * mesh.cells[:, :, None] + np.arange(3)[None, None, :]).reshape(nc, 3 * nv)
    rows = np.broadcast_to((6 * np.arange(nc))[:, None, None] + np.arange(6)[None, :, None], DB.shape)
    cols = np.broadcast_to(dofs[:, None, :], DB.shape)
    return sp.csr_matrix((DB.ravel(), (rows.ravel(), cols.ravel())), shape=(6 * nc, 3 * mesh.points.shape[0]))
