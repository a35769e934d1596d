"""linalg.BlockLU (Newton's linear solve: symbolic analysis once, numeric LU per iteration) and newton's J assembly.

References independent of the code under test: numpy's dense solve, a dense boolean elimination for the fill
pattern, np.einsum for J = D + E W, scipy's SuperLU (linalg.lu_solve) for the Newton iterates."""
import numpy as np
import pytest
import scipy.sparse as sp

from fem_blocks.linalg import BlockLU, lu_solve, to_block_csr


def block_matrix(nb, d, seed=0, band=(1, 2, 7), shuffle=False, dominance=4.0):
    """Non-symmetric matrix of d x d blocks with a symmetric block pattern (like J = D + E W on W's pattern):
    block bands at the given offsets, diagonal blocks made dominant (no pivoting needed)."""
    rng = np.random.default_rng(seed)
    pat = sp.diags([np.ones(nb - k) for k in band] + [np.ones(nb - k) for k in band] + [np.ones(nb)],
                   list(band) + [-k for k in band] + [0]).tocoo()
    if shuffle:
        p = rng.permutation(nb)
        pat = sp.coo_matrix((pat.data, (p[pat.row], p[pat.col])), shape=(nb, nb))
    A = np.zeros((nb * d, nb * d))
    for a, b in zip(pat.row, pat.col):
        A[a * d:(a + 1) * d, b * d:(b + 1) * d] = rng.uniform(-1, 1, (d, d))
    A += dominance * len(band) * np.eye(nb * d)
    return A


def bcsr(A, d):
    W = to_block_csr(sp.csr_matrix(A), d)
    return W


def dense_fill(P):
    """Filled boolean pattern of L + U of a no-pivoting elimination of the (symmetric) boolean pattern P."""
    P = P.copy()
    n = len(P)
    for k in range(n):
        rows = np.flatnonzero(P[k + 1:, k]) + k + 1
        cols = np.flatnonzero(P[k, k + 1:]) + k + 1
        P[np.ix_(rows, cols)] = True
    return P


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("shuffle", [False, True])
def test_block_lu_solves_like_a_dense_solve(d, shuffle):
    A = block_matrix(60, d, seed=d, shuffle=shuffle)
    W = bcsr(A, d)
    lu = BlockLU(W.indptr, W.indices, d)
    b = np.random.default_rng(5).standard_normal(len(A))
    assert lu.factor(W.blocks)
    x = lu.solve(b)
    ref = np.linalg.solve(A, b)
    assert np.linalg.norm(x - ref) <= 1e-12 * np.linalg.norm(ref)
    # new values on the same pattern (what Newton does each iteration): the symbolic analysis is reused
    A2 = A * np.random.default_rng(6).uniform(0.5, 1.5, A.shape)
    W2 = bcsr(A2, d)
    assert np.array_equal(W2.indices, W.indices)
    x2 = lu.solve_checked(W2.blocks, b)
    assert np.linalg.norm(x2 - np.linalg.solve(A2, b)) <= 1e-12 * np.linalg.norm(x2)


@pytest.mark.parametrize("shuffle", [False, True])
def test_block_lu_fill_and_flops_match_a_dense_elimination(shuffle):
    """The filled pattern is exactly that of a dense boolean elimination in the chosen order (a missing fill block
    would give a wrong factor, an extra one wasted work), and flops = Σ_k |U_k,>k|²; the ordering chosen is
    the one with fewer flops (a shuffled band: reverse Cuthill–McKee)."""
    nb = 50
    A = block_matrix(nb, 2, seed=3, shuffle=shuffle)
    W = bcsr(A, 2)
    P = np.zeros((nb, nb), dtype=bool)
    rows = np.repeat(np.arange(nb), np.diff(W.indptr))
    P[rows, W.indices] = True
    flops = {}
    for o in ("natural", "rcm", "nd", "qmd"):
        lu = BlockLU(W.indptr, W.indices, 2, ordering=o)
        Pp = P[np.ix_(lu.perm, lu.perm)]
        fill = dense_fill(Pp)
        got = np.zeros((nb, nb), dtype=bool)
        got[np.repeat(np.arange(nb), np.diff(lu.fptr)), lu.fidx] = True
        assert np.array_equal(got, fill), o
        assert lu.flops == sum(int(np.sum(fill[k, k + 1:])) ** 2 for k in range(nb))
        flops[o] = lu.flops
    auto = BlockLU(W.indptr, W.indices, 2)
    assert auto.ordering == min(flops, key=flops.get)
    if shuffle:
        assert auto.ordering != "natural" and flops["rcm"] < 0.5 * flops["natural"]


def test_block_lu_factor_reproduces_the_matrix():
    """L U = P A Pᵀ to round-off from the stored factors (unit block-lower L, U with U_ii⁻¹ = dinv)."""
    d, nb = 2, 40
    A = block_matrix(nb, d, seed=7, shuffle=True)
    W = bcsr(A, d)
    lu = BlockLU(W.indptr, W.indices, d)
    assert lu.factor(W.blocks)
    L = np.eye(nb * d)
    U = np.zeros((nb * d, nb * d))
    for i in range(nb):
        for p in range(lu.fptr[i], lu.fptr[i + 1]):
            j = lu.fidx[p]
            (L if j < i else U)[i * d:(i + 1) * d, j * d:(j + 1) * d] = lu.vals[p]
        assert np.allclose(lu.dinv[i] @ U[i * d:(i + 1) * d, i * d:(i + 1) * d], np.eye(d), atol=1e-13)
    pe = (lu.perm[:, None] * d + np.arange(d)).ravel()
    assert np.abs(L @ U - A[np.ix_(pe, pe)]).max() <= 1e-13 * np.abs(A).max()


def test_block_lu_refuses_a_matrix_that_needs_pivoting_between_blocks():
    """A zero diagonal block: factor() is False, solve_checked None (the caller falls back to a pivoting LU), and a
    pivot block tiny against its row (growth): the backward-error check refuses it too."""
    d, nb = 2, 20
    A = block_matrix(nb, d, seed=1)
    A[0:2, 0:2] = 0.0  # the first pivot block; A stays regular through its off-diagonal blocks
    W = bcsr(A, d)
    assert np.linalg.cond(A) < 1e8
    lu = BlockLU(W.indptr, W.indices, d, ordering="natural")
    b = np.ones(nb * d)
    assert not lu.factor(W.blocks)
    assert lu.solve_checked(W.blocks, b) is None
    x = lu_solve(sp.csr_matrix(A), b)
    assert np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(b)
    A[0:2, 0:2] = 1e-13 * np.eye(2)  # a regular pivot block, but a no-pivoting LU loses ~13 digits (growth)
    W = bcsr(A, d)
    assert lu.factor(W.blocks)
    assert np.linalg.norm(A @ lu.solve(b) - b) > 1e-6 * np.linalg.norm(b)
    assert lu.solve_checked(W.blocks, b) is None
    A[0:2, 0:2] = 1e-7 * np.eye(2)  # growth 1e7: one step of iterative refinement restores the backward error
    W = bcsr(A, d)
    x = lu.solve_checked(W.blocks, b)
    assert np.abs(A @ x - b).max() <= 1e-10 * (np.abs(A).sum(axis=1).max() * np.abs(x).max() + 1.0)


def test_block_lu_rejects_an_unsymmetric_pattern_and_a_bad_ordering():
    W = bcsr(np.triu(block_matrix(10, 2)), 2)
    with pytest.raises(ValueError, match="symmetric"):
        BlockLU(W.indptr, W.indices, 2)
    W = bcsr(block_matrix(10, 2), 2)
    with pytest.raises(ValueError, match="expected auto, natural, rcm, nd, qmd"):
        BlockLU(W.indptr, W.indices, 2, ordering="amd")


@pytest.mark.parametrize("d", [2, 3])
def test_jacobian_assembly_equals_einsum_bitwise(d):
    """newton._assemble_jacobian: J = D + E (W + ε I) on W's block pattern, bitwise the einsum it replaces."""
    from fem_blocks.solver.newton import _assemble_jacobian
    rng = np.random.default_rng(d)
    nb = 30
    W = bcsr(block_matrix(nb, d, seed=d, shuffle=True), d)
    D, E = rng.standard_normal((nb, d, d)), rng.standard_normal((nb, d, d))
    E[::3] = 0.0  # open contacts
    eps = 1e-3
    rows = np.repeat(np.arange(nb), np.diff(W.indptr))
    ref = np.einsum("kij,kjl->kil", E[rows], W.blocks)
    ref[W.diag_pos] += D + eps * E
    Jb = np.full_like(W.blocks, np.nan)
    _assemble_jacobian(W.indptr, W.blocks, W.diag_pos, D, E, eps, Jb)
    assert np.array_equal(Jb, ref)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_newton_iterates_with_block_lu_match_superlu(seed, monkeypatch):
    """The semismooth Newton on a stiff 2D frictional problem takes the same iterations to the same solution
    whether its direction comes from BlockLU or from SuperLU (linalg.lu_solve)."""
    from fem_blocks.solver import newton
    rng = np.random.default_rng(seed)
    nb = 80
    M = rng.standard_normal((2 * nb, 2 * nb)) * (rng.random((2 * nb, 2 * nb)) < 0.05)
    Wd = M @ M.T + 0.5 * np.eye(2 * nb)  # SPD Delassus-like
    W = to_block_csr(Wd, 2)
    Wd = W.to_scipy().toarray()
    q = rng.standard_normal(2 * nb)
    mu = np.full(nb, 0.5)
    out = {}
    for flag in (True, False):
        monkeypatch.setattr(newton, "BLOCK_LU", flag)
        res = newton.solve_newton(W, q, mu, tol=1e-10, gs_sweeps=2)
        assert res.converged, res.message
        out[flag] = res
    assert out[True].message.split(", residual")[0] == out[False].message.split(", residual")[0]  # iterations
    assert np.allclose(out[True].r, out[False].r, rtol=0, atol=1e-9 * np.abs(out[False].r).max())


def test_block_lu_for_pattern_reuses_the_symbolic_analysis():
    A = block_matrix(30, 2, seed=4, shuffle=True)
    W = bcsr(A, 2)
    lu = BlockLU.for_pattern(W.indptr, W.indices, 2)
    assert BlockLU.for_pattern(W.indptr.copy(), W.indices.copy(), 2) is lu
    W2 = bcsr(block_matrix(31, 2, seed=4), 2)
    assert BlockLU.for_pattern(W2.indptr, W2.indices, 2) is not lu
    b = np.arange(60.0)
    assert np.allclose(lu.solve_checked(W.blocks, b), np.linalg.solve(A, b), rtol=1e-12, atol=0)
