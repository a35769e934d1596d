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
