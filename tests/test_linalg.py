"""Sparse factorizations: every method solves SPD systems to round-off, single and multiple RHS."""
import numpy as np
import pytest
import scipy.sparse as sp

from fem_blocks.linalg import Factor


def spd(n, seed=0):
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=5.0 / n, random_state=seed)
    return (A @ A.T + sp.diags(1.0 + rng.random(n))).tocsr()


@pytest.mark.parametrize("method", ["auto", "petsc-lu", "cholmod", "mumps", "mumps-lu"])
@pytest.mark.parametrize("n", [50, 1500])
def test_factor_solves(method, n):
    A = spd(n)
    F = Factor(A, method)
    rng = np.random.default_rng(1)
    b = rng.random(n)
    x = F.solve(b)
    assert np.linalg.norm(A @ x - b) <= 1e-10 * np.linalg.norm(b)
    B = rng.random((n, 7))
    X = F.solve(B)
    assert X.shape == (n, 7)
    assert np.linalg.norm(A @ X - B) <= 1e-10 * np.linalg.norm(B)
    assert np.allclose(X[:, 0], F.solve(B[:, 0]), rtol=1e-12, atol=0)


@pytest.mark.parametrize("n", [30, 900])
def test_petsc_lu_solves_each_column_alone(n):
    """PETSc's LU (the block types below SMALL_SYSTEM dofs): each column of a multi-column solve is the same double
    for any set of columns beside it, one column included (a body's free velocity does not depend on the bodies
    solved with it: docs/scaling.md "Sums over bodies"). Catches one column solved by the vector solve, which rounds
    otherwise. (CHOLMOD's and MUMPS's multi-column solves do not have this property.)"""
    F = Factor(spd(n), "petsc-lu")
    B = np.random.default_rng(2).standard_normal((n, 7))
    X = F.solve(B)
    for cols in ([0], [6], [3, 1], [5, 0, 2], list(range(6, -1, -1))):
        assert np.array_equal(F.solve(B[:, cols]), X[:, cols])
    assert np.array_equal(F.solve(np.asfortranarray(B[:, [4]])), X[:, [4]])


def nonsymmetric(n, seed=0):
    """A block-sparse non-symmetric matrix like Newton's J = D + E W (2x2 blocks, diagonally dominant)."""
    rng = np.random.default_rng(seed)
    offsets = [-40, -9, -2, -1, 1, 2, 9, 40]  # banded like a wall's contact numbering (no random-graph fill-in)
    A = sp.diags([rng.uniform(-0.5, 0.5, n - abs(k)) for k in offsets], offsets)
    return (A + sp.diags(4.0 + rng.random(n))).tocsr()


@pytest.mark.parametrize("method", ["auto", "superlu", "mumps"])
@pytest.mark.parametrize("n", [60, 4000])
def test_lu_solve_general(method, n):
    from fem_blocks.linalg import lu_solve
    A = nonsymmetric(n)
    assert abs(A - A.T).max() > 0.1  # really non-symmetric
    b = np.random.default_rng(2).random(n)
    x = lu_solve(A, b, method)
    assert np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(b) * n
    # the same answer whichever factorisation
    assert np.allclose(x, lu_solve(A, b, "superlu"), rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("method", ["superlu", "mumps"])
def test_lu_solve_singular_returns_none(method):
    from fem_blocks.linalg import lu_solve
    A = nonsymmetric(50).tolil()
    A[7, :] = 0.0  # a zero row: exactly singular
    assert lu_solve(A.tocsr(), np.ones(50), method) is None


def test_lu_solve_bad_method():
    from fem_blocks.linalg import lu_solve
    with pytest.raises(ValueError, match="expected auto, superlu or mumps"):
        lu_solve(sp.eye(3).tocsr(), np.ones(3), "lapack")


def _matvec_by_definition(indptr, indices, blocks, x):
    """y = W x in plain Python, each entry summed in the order matvec_bcsr states: y_ai = (((0 + s_1) + s_2) + ...)
    over the row's blocks in order, s_k = ((0 + W_k,i0 x_0) + W_k,i1 x_1) + ..."""
    d = blocks.shape[1]
    y = []
    for a in range(len(indptr) - 1):
        for i in range(d):
            acc = 0.0
            for k in range(indptr[a], indptr[a + 1]):
                s = 0.0
                for j in range(d):
                    s += float(blocks[k, i, j]) * float(x[d * indices[k] + j])
                acc += s
            y.append(acc)
    return np.array(y)


@pytest.mark.parametrize("d", [1, 2, 3, 4])
def test_block_matvec_sums_in_the_stated_order(d):
    """matvec_bcsr (the u = W r + q of every solver) against its stated summation order, bitwise, for the 2D and 3D
    blocks it specialises and the general loop (d = 1, 4); an empty row gives 0; and against the dense product
    (1e-13). Catches a specialised branch that sums a block's entries or the row's blocks in another order (other
    bits), reads the wrong component or forgets to clear y (the output array is filled with garbage first)."""
    from fem_blocks.linalg import matvec_bcsr
    rng = np.random.default_rng(d)
    n = 40
    counts = rng.integers(0, 7, n)
    counts[3] = 0
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    indices = np.concatenate([np.sort(rng.choice(n, c, replace=False)) for c in counts]).astype(np.int64)
    blocks = rng.standard_normal((indptr[-1], d, d)) * 10.0 ** rng.integers(-8, 8, (indptr[-1], d, d))
    x = rng.standard_normal(d * n) * 10.0 ** rng.integers(-8, 8, d * n)
    y = np.full(d * n, np.nan)
    matvec_bcsr(indptr, indices, blocks, x, y)
    want = _matvec_by_definition(indptr, indices, blocks, x)
    assert y.tobytes() == want.tobytes()
    assert np.all(y[d * 3:d * 4] == 0.0)
    dense = np.zeros((d * n, d * n))
    for a in range(n):
        for k in range(indptr[a], indptr[a + 1]):
            b = indices[k]
            dense[d * a:d * a + d, d * b:d * b + d] = blocks[k]
    ref = dense @ x
    assert np.allclose(y, ref, rtol=1e-13, atol=1e-13 * np.abs(dense).max() * np.abs(x).max())
