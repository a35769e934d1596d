"""Distributed colour-order Gauss–Seidel (fem_blocks/distributed/sweep.py): rows of W owned per rank, only the
interface impulses exchanged per colour by PETSc scatters.

Expectation (independent of the code under test): the serial Gauss–Seidel sweep in colour order,
`solver.parallel.solve_parallel(comm=None)`, gives the iterates; N = 1, 2, 3 ranks with any ownership of the
contacts must give the same impulses, sweep count and residual, bitwise."""
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
import scipy.sparse as sp

from fem_blocks.distributed import sweep as ds
from fem_blocks.linalg import to_block_csr
from fem_blocks.solver import parallel

from _paths import FCLIB, ROOT  # noqa: E402

FCLIB_DIR = FCLIB if os.path.isdir(FCLIB) else os.environ.get("FEM_BLOCKS_FCLIB", FCLIB)
GRANULAR = os.path.join(FCLIB_DIR, "converted_from_siconos_dat", "fc2d_granularflowonwall_00667_00000.hdf5")


def grid_problem(nx=7, ny=5, seed=3):
    """A sparse 2D contact problem: rigid bodies (3 dofs) on an nx x ny grid, two contacts per neighbour pair and
    per ground body, W = Hᵀ M⁻¹ H + 0.1 I, q = Hᵀ v + gaps. Returns (W BlockCSR, q, mu)."""
    rng = np.random.default_rng(seed)
    nb = nx * ny
    pairs = [(i + nx * j, i + 1 + nx * j) for j in range(ny) for i in range(nx - 1)]
    pairs += [(i + nx * j, i + nx * (j + 1)) for j in range(ny - 1) for i in range(nx)]
    pairs += [(i, -1) for i in range(nx)]  # ground
    cols = []
    for a, b in pairs:
        for _ in range(2):
            t = rng.uniform(0, 2 * np.pi)
            n, tt = np.array([np.cos(t), np.sin(t)]), np.array([-np.sin(t), np.cos(t)])
            arm = rng.uniform(-0.5, 0.5, 2)
            for e in (n, tt):
                c = np.zeros(3 * nb)
                c[3 * a:3 * a + 3] = [e[0], e[1], arm[0] * e[1] - arm[1] * e[0]]
                if b >= 0:
                    c[3 * b:3 * b + 3] = [-e[0], -e[1], -(arm[0] * e[1] - arm[1] * e[0])]
                cols.append(c)
    H = sp.csr_matrix(np.array(cols).T)
    Minv = sp.diags(rng.uniform(0.5, 2.0, 3 * nb))
    W = (H.T @ Minv @ H + 0.1 * sp.eye(H.shape[1])).tocsr()  # a compliant contact: W positive definite
    W.eliminate_zeros()
    nc = len(cols) // 2
    q = H.T @ rng.normal(size=3 * nb)  # u = Hᵀ v_free + gap
    q[0::2] += rng.uniform(0.0, 0.2, nc)
    return to_block_csr(W, 2), q, rng.uniform(0.3, 0.7, nc)


def test_local_rows_are_the_owned_rows_and_ghosts_the_coupled_contacts():
    W, q, mu = grid_problem()
    A = W.to_scipy()
    owner = ds.ownership(W.n, 3, "cyclic")
    seen = np.zeros(W.n, dtype=int)
    for p in range(3):
        own = np.flatnonzero(owner == p)
        rows = ds.local_rows(W, q, mu, own)
        seen[rows.owned] += 1
        # ghosts: the contacts coupled to an owned row (structural pattern of W's block rows), minus the owned ones
        coupled = np.unique(W.indices[np.concatenate([np.arange(W.indptr[a], W.indptr[a + 1]) for a in own])])
        assert np.array_equal(rows.ghost, np.setdiff1d(coupled, own))
        # the local rows, mapped back to global columns, are W's rows (values and column order)
        ids = np.concatenate([rows.owned, rows.ghost])
        B = ds.BlockCSR(rows.indptr, rows.indices, rows.blocks, rows.diag_pos)
        for k, a in enumerate(own):
            sl = slice(W.indptr[a], W.indptr[a + 1])
            assert np.array_equal(ids[rows.indices[rows.indptr[k]:rows.indptr[k + 1]]], W.indices[sl])
            assert np.array_equal(rows.blocks[rows.indptr[k]:rows.indptr[k + 1]], W.blocks[sl])
            assert ids[rows.indices[B.diag_pos[k]]] == a
        dense = A[np.repeat(2 * own, 2) + np.tile([0, 1], own.size)][:, np.repeat(2 * ids, 2) + np.tile([0, 1], ids.size)]
        local = sp.bsr_matrix((rows.blocks, rows.indices, rows.indptr), shape=(2 * own.size, 2 * ids.size))
        assert np.array_equal(local.toarray(), dense.toarray())
        assert np.array_equal(rows.q, q.reshape(-1, 2)[own].ravel()) and np.array_equal(rows.mu, mu[own])
    assert np.all(seen == 1)


def test_one_rank_gives_the_serial_colour_order_iterates_bitwise():
    from mpi4py import MPI
    W, q, mu = grid_problem()
    colour = parallel.colour_contacts(W)
    rows = ds.local_rows(W, q, mu, np.arange(W.n))
    d = ds.DistSweep(rows, colour, int(colour.max()) + 1, MPI.COMM_SELF)
    serial = parallel.solve_parallel(W, q, mu, tol=1e-10, max_sweeps=100000)
    res = d.solve(tol=1e-10, max_sweeps=100000)
    assert serial.converged and res.converged
    assert res.sweeps == serial.sweeps and np.array_equal(res.r, serial.r) and res.residual == serial.residual
    # the cheap stopping test (MPI sum of partial sums) differs from the ordered sum by rounding only
    res2 = d.solve(tol=1e-10, max_sweeps=100000, residual="allreduce")
    assert res2.sweeps == serial.sweeps and np.array_equal(res2.r, serial.r)
    assert abs(res2.residual - serial.residual) <= 1e-13 * serial.residual
    d.destroy()


def _mpirun(n, problem, out, *args):
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1", OMPI_MCA_btl_vader_single_copy_mechanism="none", PYTHONPATH=ROOT)
    p = subprocess.run(["mpirun", "-n", str(n), sys.executable, "-m", "fem_blocks.distributed.sweep", str(problem),
                        str(out), *args], capture_output=True, text=True, cwd=ROOT, env=env, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    return np.load(out)


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")
@pytest.mark.parametrize("n, own", [(3, "cyclic")])
def test_mpirun_synthetic_equals_serial_colour_order_bitwise(tmp_path, n, own):
    W, q, mu = grid_problem()
    prob = tmp_path / "p.npz"
    np.savez(prob, indptr=W.indptr, indices=W.indices, blocks=W.blocks, diag_pos=W.diag_pos, q=q, mu=mu, tol=1e-10)
    out = _mpirun(n, prob, tmp_path / "out.npz", "--own", own)
    serial = parallel.solve_parallel(W, q, mu, tol=1e-10, max_sweeps=100000)
    assert int(out["ranks"]) == n and bool(out["converged"]) and serial.converged
    assert int(out["sweeps"]) == serial.sweeps
    assert np.array_equal(out["r"], serial.r)                 # iterates, bitwise
    assert float(out["residual"]) == serial.residual          # residual, bitwise (ordered sum on rank 0)
    nown = out["n_own"]
    assert nown.sum() == W.n
    if own == "skip0":
        assert nown[0] == 0 and out["bytes_sent"][0] == 0 and out["bytes_recv"][0] == 0  # a rank with no contact
    if n > 1:
        # bytes sent = bytes received over all ranks; each ghost received once per sweep (2 doubles per contact)
        assert out["bytes_sent"].sum() == out["bytes_recv"].sum() == 16 * out["n_ghost"].sum()


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")
@pytest.mark.parametrize("n", [3])
def test_mpirun_fclib_equals_serial_colour_order_bitwise(tmp_path, n):
    if not os.path.exists(GRANULAR):
        pytest.skip(f"FCLIB data not found at {FCLIB_DIR}")
    from fem_blocks.io import fclib
    p = fclib.read(GRANULAR)
    W = to_block_csr(p.W, p.dim)
    out = _mpirun(n, GRANULAR, tmp_path / "out.npz", "--own", "blocks", "--tol", "1e-12", "--max-sweeps", "300")
    serial = parallel.solve_parallel(W, p.q, p.mu, tol=1e-12, max_sweeps=300)
    assert int(out["sweeps"]) == serial.sweeps and bool(out["converged"]) == serial.converged
    assert np.array_equal(out["r"], serial.r) and float(out["residual"]) == serial.residual
    assert np.all(out["n_ghost"] > 0)  # the partition cuts the contact graph: impulses cross ranks


@pytest.mark.parametrize("dim", [2, 3])
def test_residual_terms_summed_in_order_are_the_serial_natural_map(dim):
    # the per-contact terms ‖F_α‖² of the ordered residual, summed in contact order, give nlgs.natural_map bitwise
    # (catches a term computed differently from the serial solver's, e.g. without the mu ‖u_T‖ shift)
    from fem_blocks.solver import nlgs
    rng = np.random.default_rng(dim)
    n = 5000
    r, u, mu = rng.normal(size=dim * n), rng.normal(size=dim * n), rng.uniform(0.1, 0.9, n)
    t = nlgs.natural_map_terms(r, u, mu, dim)
    assert np.sqrt(ds._ordered_sum(t)) == nlgs.natural_map(r, u, mu, dim)


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")
def test_mpirun_3d_equals_serial_colour_order_bitwise(tmp_path):
    # 3x3 blocks (local solver of solver/local.py, warm-started from r_α): the same bitwise agreement on 2 ranks
    from test_nlgs import random_problem_3d
    Wd, q = random_problem_3d(n=40, seed=2)
    W = to_block_csr(Wd, 3)
    mu = np.full(W.n, 0.4)
    prob = tmp_path / "p3.npz"
    np.savez(prob, indptr=W.indptr, indices=W.indices, blocks=W.blocks, diag_pos=W.diag_pos, q=q, mu=mu, tol=1e-10)
    out = _mpirun(2, prob, tmp_path / "out.npz", "--own", "cyclic")
    serial = parallel.solve_parallel(W, q, mu, tol=1e-10, max_sweeps=100000)
    assert serial.converged and bool(out["converged"]) and int(out["sweeps"]) == serial.sweeps
    assert np.array_equal(out["r"], serial.r) and float(out["residual"]) == serial.residual
    assert np.all(out["n_ghost"] > 0)
