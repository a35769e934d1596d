"""Colour-parallel Gauss–Seidel (solver/parallel.py): valid colouring, identical iterates to the serial sweep in
colour order. (Runs on several ranks: tests/test_dist_sweep.py, which takes solve_parallel(comm=None) as its serial
reference, and tests/test_dist_run.py.)"""
import numpy as np
import pytest

from fem_blocks.solver import nlgs, parallel
from fem_blocks.linalg import to_block_csr

from test_nlgs import random_problem, random_problem_3d  # noqa: E402


def test_colouring_separates_coupled_contacts():
    W, q = random_problem(n=200, seed=5)
    B = to_block_csr(W, 2)
    colour = parallel.colour_contacts(B)
    rows = np.repeat(np.arange(B.n), np.diff(B.indptr))
    off = rows != B.indices
    assert np.all(colour[rows[off]] != colour[B.indices[off]])
    assert colour.max() + 1 < B.n  # a sparse W needs far fewer colours than contacts
    order, ptr = parallel.colour_order(colour)
    assert sorted(order) == list(range(B.n)) and ptr[-1] == B.n


@pytest.mark.parametrize("dim", [2, 3])
def test_serial_run_equals_gauss_seidel_in_colour_order(dim):
    W, q = random_problem(n=80, seed=2) if dim == 2 else random_problem_3d(n=40, seed=2)
    B = to_block_csr(W, dim)
    res = parallel.solve_parallel(B, q, 0.4, tol=1e-10, max_sweeps=5000, check_every=1)
    assert res.converged
    order, _ = parallel.colour_order(parallel.colour_contacts(B))
    r = np.zeros(dim * B.n)
    mu = np.full(B.n, 0.4)
    for _ in range(res.sweeps):
        nlgs.sweep(B.indptr, B.indices, B.blocks, B.diag_pos, np.ascontiguousarray(q), mu, r, order)
    assert np.array_equal(r, res.r)  # bitwise: the colours' updates are independent
