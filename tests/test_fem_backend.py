"""fem_backend: dolfinx K, M in BlockMesh node order, against closed forms and a numpy element assembly."""
import numpy as np
import pytest
import scipy.sparse as sp

from fem_blocks.errors import InputError
from fem_blocks.fem_backend import assemble_operators, elasticity_matrix, stress_operator, von_mises
from fem_blocks.meshing import BlockMesh, mesh_polygon, mesh_rectangle

E, NU, RHO, T = 12e9, 0.2, 1900.0, 0.11


# ----------------------------------------------------------------------------- meshes
def shuffled(m: BlockMesh, seed: int) -> BlockMesh:
    """Same geometry, random node numbering, cells starting at a random vertex (still CCW)."""
    rng = np.random.default_rng(seed)
    perm = rng.permutation(m.n_nodes)  # new index of old node i is perm[i]
    P = np.empty_like(m.points)
    P[perm] = m.points
    C = perm[m.cells]
    C = np.array([np.roll(c, -rng.integers(len(c))) for c in C], dtype=np.int64)
    C = C[rng.permutation(len(C))]
    return BlockMesh.from_cells(P, C, m.cell_type, "shuffled")


def distorted_quads(seed=3) -> BlockMesh:
    m = mesh_rectangle(0.5, 0.3, 0.1, "quad")  # 5 x 3, convex after +-20 % interior jitter
    rng = np.random.default_rng(seed)
    P = m.points.copy()
    inner = np.flatnonzero((P[:, 0] > 1e-9) & (P[:, 0] < 0.5 - 1e-9) & (P[:, 1] > 1e-9) & (P[:, 1] < 0.3 - 1e-9))
    P[inner] += rng.uniform(-0.02, 0.02, size=(inner.size, 2))
    return shuffled(BlockMesh.from_cells(P, m.cells, "quad"), seed)


def random_triangles(seed=5) -> BlockMesh:
    return shuffled(mesh_polygon([[0, 0], [0.6, 0.05], [0.7, 0.4], [0.2, 0.5]], 0.12, "triangle"), seed)


MESHES = {"quad": distorted_quads, "triangle": random_triangles}


# ----------------------------------------------------------------------------- numpy reference
def reference_operators(m: BlockMesh, E, nu, rho, t, plane):
    """Element-by-element numpy assembly: Q1 with 2x2 Gauss (exact for M), P1 exact; dofs 2*node + c."""
    D = elasticity_matrix(E, nu, plane)
    n = m.n_nodes
    K = np.zeros((2 * n, 2 * n))
    M = np.zeros((2 * n, 2 * n))
    if m.cell_type == "quad":
        g = 1 / np.sqrt(3)
        gauss = [(-g, -g), (g, -g), (g, g), (-g, g)]
        xi_a = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)
    for cell in m.cells:
        X = m.points[cell]
        nv = len(cell)
        dofs = np.ravel([[2 * a, 2 * a + 1] for a in cell])
        ke = np.zeros((2 * nv, 2 * nv))
        me = np.zeros((nv, nv))
        if nv == 3:
            pts = [((1 / 3, 1 / 3), 1.0)]
        else:
            pts = [(q, 1.0) for q in gauss]
        for (xi, eta), w in pts:
            if nv == 3:
                N = np.array([1 - xi - eta, xi, eta])
                dN = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
                w = 0.5
            else:
                N = 0.25 * (1 + xi_a[:, 0] * xi) * (1 + xi_a[:, 1] * eta)
                dN = 0.25 * np.c_[xi_a[:, 0] * (1 + xi_a[:, 1] * eta), xi_a[:, 1] * (1 + xi_a[:, 0] * xi)]
            J = X.T @ dN
            detJ = np.linalg.det(J)
            G = dN @ np.linalg.inv(J)
            B = np.zeros((3, 2 * nv))
            B[0, 0::2], B[1, 1::2], B[2, 0::2], B[2, 1::2] = G[:, 0], G[:, 1], G[:, 1], G[:, 0]
            ke += t * w * detJ * B.T @ D @ B
            if nv == 4:
                me += rho * t * w * detJ * np.outer(N, N)
        if nv == 3:
            A = 0.5 * np.linalg.det(np.c_[np.ones(3), X])
            me = rho * t * A / 12 * (np.ones((3, 3)) + np.eye(3))
        K[np.ix_(dofs, dofs)] += ke
        for c in range(2):
            M[np.ix_(dofs[c::2], dofs[c::2])] += me
    if m.cell_type == "triangle":  # vertex rule: A/3 at each vertex
        A = m.cell_areas()
        ml = np.zeros(n)
        np.add.at(ml, m.cells.ravel(), np.repeat(rho * t * A / 3, 3))
        Ml = np.diag(np.repeat(ml, 2))
    else:
        Ml = np.diag(M.sum(axis=1))
    return K, M, Ml


def rel(A, B):
    A = A.toarray() if sp.issparse(A) else A
    B = B.toarray() if sp.issparse(B) else B
    return np.abs(A - B).max() / np.abs(B).max()


@pytest.fixture(scope="module", params=["quad", "triangle"])
def case(request):
    m = MESHES[request.param]()
    return m, assemble_operators(m, E, NU, RHO, T, "stress")


# ----------------------------------------------------------------------------- tests
@pytest.mark.parametrize("plane", ["stress", "strain"])
@pytest.mark.parametrize("kind", ["quad", "triangle"])
def test_matches_numpy_assembly_in_node_order(kind, plane):
    """Node-order mapping: dolfinx operators == numpy element assembly on a shuffled, distorted mesh (1e-10)."""
    m = MESHES[kind]()
    ops = assemble_operators(m, E, NU, RHO, T, plane)
    K, M, Ml = reference_operators(m, E, NU, RHO, T, plane)
    for A in (ops.K, ops.M_consistent, ops.M_lumped):
        assert sp.isspmatrix_csr(A) and A.shape == (2 * m.n_nodes, 2 * m.n_nodes)
    assert rel(ops.K, K) < 1e-10
    assert rel(ops.M_consistent, M) < 1e-10
    assert rel(ops.M_lumped, Ml) < 1e-10


def test_symmetry_and_rigid_modes(case):
    m, ops = case
    K = ops.K
    assert rel(K, K.T) < 1e-14
    x, y = m.points[:, 0], m.points[:, 1]
    modes = [np.c_[np.ones_like(x), 0 * x], np.c_[0 * x, np.ones_like(x)], np.c_[-y, x]]
    knorm = abs(K).max()
    for r in modes:
        r = r.ravel()
        assert np.abs(K @ r).max() < 1e-10 * knorm * np.abs(r).max()
    w = np.linalg.eigvalsh(K.toarray())
    assert np.all(w[:3] < 1e-10 * w[-1]) and w[3] > 1e-6 * w[-1]  # exactly 3 zero modes, the rest positive
    for M in (ops.M_consistent, ops.M_lumped):
        assert rel(M, M.T) < 1e-15


def test_mass_totals_and_lumping(case):
    m, ops = case
    total = RHO * m.area() * T
    for c in range(2):
        e = np.zeros(2 * m.n_nodes)
        e[c::2] = 1.0
        assert e @ ops.M_consistent @ e == pytest.approx(total, rel=1e-12)
        assert e @ ops.M_lumped @ e == pytest.approx(total, rel=1e-12)
    Ml = ops.M_lumped
    assert Ml.nnz == 2 * m.n_nodes and np.all(Ml.diagonal() > 0)
    assert np.array_equal(Ml.indices, np.arange(2 * m.n_nodes))  # exactly diagonal
    assert np.allclose(Ml.diagonal()[0::2], Ml.diagonal()[1::2], rtol=1e-15, atol=0)
    e = np.zeros(2 * m.n_nodes)
    e[0::2] = 1.0
    assert e @ ops.M_consistent @ e.T == pytest.approx(ops.M_consistent[0::2, 0::2].sum(), rel=1e-14)
    assert abs(ops.M_consistent[0::2, 1::2]).max() == 0.0  # no x-y coupling


@pytest.mark.parametrize("plane", ["stress", "strain"])
def test_patch_test(case, plane):
    """u = A x + b (uniform strain): S u = D eps in every cell exactly, and K u = nodal forces of the
    boundary traction sigma n (zero at interior nodes)."""
    m, _ = case
    ops = assemble_operators(m, E, NU, RHO, T, plane)
    A = np.array([[2e-4, -3e-4], [5e-4, -1e-4]])
    u = (m.points @ A.T + [1e-3, -2e-3]).ravel()
    eps = np.array([A[0, 0], A[1, 1], A[0, 1] + A[1, 0]])
    sig = elasticity_matrix(E, NU, plane) @ eps
    s = (stress_operator(m, E, NU, plane) @ u).reshape(-1, 3)
    assert s.shape == (len(m.cells), 3)
    assert np.abs(s - sig).max() < 1e-10 * np.abs(sig).max()
    S2 = np.array([[sig[0], sig[2]], [sig[2], sig[1]]])
    f = np.zeros(2 * m.n_nodes)
    a, b = m.points[m.boundary_edges[:, 0]], m.points[m.boundary_edges[:, 1]]
    d = b - a
    normal_len = np.c_[d[:, 1], -d[:, 0]]  # outward normal times edge length (body on the left)
    fe = 0.5 * T * normal_len @ S2.T
    for k in range(2):
        np.add.at(f, 2 * m.boundary_edges[:, k], fe[:, 0])
        np.add.at(f, 2 * m.boundary_edges[:, k] + 1, fe[:, 1])
    Ku = ops.K @ u
    assert np.abs(Ku - f).max() < 1e-10 * np.abs(f).max()


@pytest.mark.parametrize("cell", ["quad", "triangle"])
def test_uniaxial_apparent_modulus(cell):
    """Rectangle, ux = 0 on the left, ux = d on the right, uy = 0 at one corner, lateral sides free:
    the FE solution is homogeneous, so F = E_app (ly t / lx) d with E_app = E (plane stress) or
    E / (1 - nu^2) (plane strain); lateral strain -nu eps (stress) or -nu/(1-nu) eps (strain)."""
    lx, ly, d = 0.4, 0.15, 1e-4
    m = mesh_rectangle(lx, ly, 0.05, cell)
    x, y = m.points[:, 0], m.points[:, 1]
    left, right = np.flatnonzero(np.isclose(x, 0.0)), np.flatnonzero(np.isclose(x, lx))
    corner = np.flatnonzero(np.isclose(x, 0.0) & np.isclose(y, 0.0))
    fixed = np.r_[2 * left, 2 * right, 2 * corner + 1]
    ub = np.zeros(2 * m.n_nodes)
    ub[2 * right] = d
    free = np.setdiff1d(np.arange(2 * m.n_nodes), fixed)
    for plane, E_app, lat in (("stress", E, NU), ("strain", E / (1 - NU ** 2), NU / (1 - NU))):
        K = assemble_operators(m, E, NU, RHO, T, plane).K.tocsr()
        u = ub.copy()
        u[free] = sp.linalg.spsolve(K[free][:, free].tocsc(), -K[free][:, fixed] @ ub[fixed])
        F = (K @ u)[2 * right].sum()
        assert F == pytest.approx(E_app * ly * T / lx * d, rel=1e-10)
        assert np.allclose(u[1::2], -lat * (d / lx) * y, rtol=0, atol=1e-10 * d)


def test_translation_invariance(case):
    m, ops = case
    t = assemble_operators(m.translated(12.3, -4.5), E, NU, RHO, T, "stress")
    assert rel(t.K, ops.K) < 1e-11
    assert rel(t.M_consistent, ops.M_consistent) < 1e-11
    assert rel(t.M_lumped, ops.M_lumped) < 1e-11


def test_plane_strain_thickness_scaling():
    m = mesh_rectangle(0.3, 0.1, 0.05, "quad")
    a = assemble_operators(m, E, NU, RHO, 1.0, "strain")
    b = assemble_operators(m, E, NU, RHO, 0.25, "strain")
    assert rel(b.K, 0.25 * a.K) < 1e-14 and rel(b.M_consistent, 0.25 * a.M_consistent) < 1e-14


def test_von_mises_closed_forms():
    s = 3.0e6
    assert von_mises(np.array([s, 0, 0]), NU, plane_strain=False)[0] == pytest.approx(s, rel=1e-14)
    assert von_mises(np.array([0, 0, s]), NU, plane_strain=False)[0] == pytest.approx(np.sqrt(3) * s, rel=1e-14)
    assert von_mises(np.array([s, s, 0]), NU, plane_strain=False)[0] == pytest.approx(s, rel=1e-14)
    # plane strain, equibiaxial: szz = 2 nu s, vM = |s - 2 nu s|
    assert von_mises(np.array([s, s, 0]), NU, plane_strain=True)[0] == pytest.approx(s * (1 - 2 * NU), rel=1e-14)
    # plane strain, uniaxial: principal (s, 0, nu s)
    ref = np.sqrt(0.5 * (s ** 2 + (NU * s) ** 2 + (s - NU * s) ** 2))
    assert von_mises(np.array([[s, 0, 0], [s, 0, 0]]), NU, plane_strain=True) == pytest.approx([ref, ref], rel=1e-14)
    # one row per cell with its own nu and plane (as the 2D writer passes them): equibiaxial rows
    vm = von_mises(np.array([[s, s, 0], [s, s, 0], [s, s, 0]]), np.array([NU, NU, 0.1]), np.array([False, True, True]))
    assert vm == pytest.approx([s, s * (1 - 2 * NU), s * (1 - 0.2)], rel=1e-14)
    with pytest.raises(ValueError, match="3 .2D. or 6 .3D."):
        von_mises(np.zeros((2, 4)))


def test_stress_operator_shape_and_rigid_motion():
    m = distorted_quads()
    S = stress_operator(m, E, NU, "stress")
    assert sp.isspmatrix_csr(S) and S.shape == (3 * len(m.cells), 2 * m.n_nodes)
    x, y = m.points[:, 0], m.points[:, 1]
    rot = np.c_[-y, x].ravel()
    assert np.abs(S @ rot).max() < 1e-12 * E


@pytest.mark.parametrize("kw, field", [
    (dict(E=0.0), "E"), (dict(E=-1.0), "E"), (dict(E=float("nan")), "E"),
    (dict(nu=0.5), "nu"), (dict(nu=-1.0), "nu"), (dict(rho=0.0), "rho"),
    (dict(thickness=-0.1), "thickness"), (dict(plane="axisym"), "plane")])
def test_material_validation(kw, field):
    m = mesh_rectangle(1, 1, 1.0)
    args = dict(E=E, nu=NU, rho=RHO, thickness=T, plane="stress")
    args.update(kw)
    with pytest.raises(InputError, match=rf"^{field} = .*expected"):
        assemble_operators(m, **args)
    if field in ("E", "nu", "plane"):
        with pytest.raises(InputError, match=rf"^{field} = .*expected"):
            stress_operator(m, args["E"], args["nu"], args["plane"])
