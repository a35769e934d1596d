"""Colour-parallel Gauss–Seidel (solver/parallel.py): valid colouring, identical iterates to the serial sweep in
colour order, and the same result and residual with `mpirun -n 2` as serially."""
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from fem_blocks.solver import nlgs, parallel
from fem_blocks.linalg import to_block_csr

from test_nlgs import random_problem, random_problem_3d  # noqa: E402

from _paths import ROOT  # noqa: E402


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


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")
def test_mpirun_two_ranks_reaches_the_serial_result(tmp_path):
    W, q = random_problem(n=300, seed=7)
    B = to_block_csr(W, 2)
    mu = np.full(B.n, 0.5)
    prob = tmp_path / "p.npz"
    np.savez(prob, indptr=B.indptr, indices=B.indices, blocks=B.blocks, diag_pos=B.diag_pos, q=q, mu=mu, tol=1e-10)
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMPI_MCA_rmaps_base_oversubscribe="1",
               OMPI_MCA_btl_vader_single_copy_mechanism="none", PYTHONPATH=ROOT)
    p = subprocess.run(["mpirun", "-n", "2", sys.executable, "-m", "fem_blocks.solver.parallel", str(prob),
                        str(tmp_path / "out.npz")], capture_output=True, text=True, cwd=ROOT, env=env, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    out = np.load(tmp_path / "out.npz")
    assert int(out["ranks"]) == 2 and bool(out["converged"]) and float(out["residual"]) <= 1e-10
    serial = parallel.solve_parallel(B, q, mu, tol=1e-10, max_sweeps=100000)
    assert int(out["sweeps"]) == serial.sweeps
    assert np.array_equal(out["r"], serial.r)  # same iterates as the serial colour-ordered sweep, bitwise
