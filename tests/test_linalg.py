"""Sparse factorizations: every method solves SPD systems to round-off, single and multiple RHS."""
import numpy as np
import pytest
import scipy.sparse as sp

from fem_blocks.linalg import Factor


def spd(n, seed=0):
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=5.0 / n, random_state=seed)
    return (A @ A.T + sp.diags(1.0 + rng.random(n))).tocsr()


@pytest.mark.parametrize("method", ["auto", "petsc-lu", "cholmod", "mumps"])
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
