"""Distributed linear solve of the global Newton (fem_blocks/distributed/linear.py): J x = b on a PETSc MPIBAIJ
matrix with rows owned per rank (MUMPS LU), x all-gathered on every rank; and the `linear=` hook of
solver/newton.py.

Expectations (independent of the code under test): x = scipy.sparse.linalg.spsolve(J, b) (SuperLU) to 1e-12
relative (measured: at most 1.2e-15 on the systems below, condition numbers 4 to 2e2); identical bits on every
rank; None on every rank for a singular J; Newton with the distributed solve takes the iterations of the serial
Newton (BlockLU / SuperLU) and ends within the tolerance, r within a stated bound of the serial r.

Ranks run in subprocesses under mpirun (tests/_dist_linear_run.py, as tests/test_dist_sweep.py does)."""
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fem_blocks.distributed.linear import DistBlockSolver, has_mumps
from fem_blocks.linalg import to_block_csr
from fem_blocks.solver import newton

from _mpi import ENV  # noqa: E402
from _paths import FCLIB, ROOT  # noqa: E402

FCLIB_DIR = FCLIB if os.path.isdir(FCLIB) else os.environ.get("FEM_BLOCKS_FCLIB", FCLIB)
GRANULAR = os.path.join(FCLIB_DIR, "converted_from_siconos_dat", "fc2d_granularflowonwall_00667_00000.hdf5")
CAPSULES = os.path.join(FCLIB_DIR, "Capsules-i97-269.hdf5")
DRIVER = os.path.join(ROOT, "tests", "_dist_linear_run.py")
needs_mpirun = pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")


def pattern(n, seed, density=0.05):
    """A random symmetric block pattern with every diagonal block (the pattern of a W): BlockCSR indptr, indices."""
    A = sp.random(n, n, density=density, random_state=seed, format="csr")
    P = ((abs(A) + abs(A.T) + sp.eye(n)) != 0).astype(float).tocsr()
    P.sort_indices()
    return P.indptr.astype(np.int64), P.indices.astype(np.int64)


def blocks(indptr, indices, d, kind, seed):
    """Blocks of J in the pattern. "dominant": random blocks, each diagonal block + (Σ of the row's |entries| + 1) I
    (strictly diagonally dominant by rows); "unsymmetric": random blocks + 2√(row length) I on the diagonal, not
    dominant, values unsymmetric in every block and between J_αβ and J_βα (condition number ~1e2-1e3);
    "singular": "dominant" with block row 3 zero."""
    rng = np.random.default_rng(seed)
    n = indptr.size - 1
    B = rng.normal(size=(indices.size, d, d))
    rows = np.repeat(np.arange(n), np.diff(indptr))
    diag = np.flatnonzero(indices == rows)
    if kind == "unsymmetric":
        B[diag] += 2.0 * np.sqrt(np.diff(indptr))[:, None, None] * np.eye(d)
        return B
    s = np.bincount(rows, weights=np.abs(B).sum(axis=(1, 2)), minlength=n)
    B[diag] += (s + 1.0)[:, None, None] * np.eye(d)
    if kind == "singular":
        B[indptr[3]:indptr[4]] = 0.0
    return B


def reference(indptr, indices, B, b):
    d = B.shape[1]
    n = indptr.size - 1
    J = sp.bsr_matrix((B, indices, indptr), shape=(d * n, d * n)).tocsc()
    return spla.spsolve(J, b)


def rel(x, y):
    return float(np.linalg.norm(x - y) / np.linalg.norm(y))


@pytest.mark.parametrize("method", ["auto", "gmres"])
def test_one_process_equals_spsolve_and_reuses_the_pattern(method):
    """COMM_SELF, 2D and 3D blocks, one solver for several systems in turn: x = spsolve to 1e-12 relative for each
    (MUMPS, measured <= 1.2e-15; the GMRES fallback, relative residual 1e-12: 1e-10, measured <= 7.6e-13), None for
    the singular one, the next system solved again after it. Catches blocks inserted transposed (the unsymmetric
    systems), a stale factor reused for new values (the second system) and a solver left broken after a failed
    factorisation (the system after the singular one: without the rebuilt KSP, both methods return None there)."""
    from mpi4py import MPI
    tol = 1e-10 if method == "gmres" else 1e-12
    for d in (2, 3):
        indptr, indices = pattern(60, seed=d)
        n = indptr.size - 1
        s = DistBlockSolver(indptr, indices, d, np.zeros(n, dtype=np.int64), MPI.COMM_SELF, method=method)
        assert s.method == ("mumps" if has_mumps() and method == "auto" else "gmres")
        rng = np.random.default_rng(10 + d)
        for k, kind in enumerate(["dominant", "unsymmetric", "singular", "dominant"]):
            B = blocks(indptr, indices, d, kind, seed=k)
            b = rng.normal(size=d * n)
            x = s.solve(B, b)
            if kind == "singular":
                assert x is None
                continue
            assert x is not None and rel(x, reference(indptr, indices, B, b)) <= tol, (d, kind)
        s.destroy()


def _mpirun(n, *args, timeout=300):
    p = subprocess.run(["mpirun", "-n", str(n), sys.executable, DRIVER, *map(str, args)], capture_output=True,
                       text=True, cwd=ROOT, env=ENV, timeout=timeout)
    assert p.returncode == 0, p.stdout + p.stderr
    return p


@needs_mpirun
@pytest.mark.parametrize("ranks, own, d", [(3, "cyclic", 3)])
def test_mpirun_equals_spsolve_on_every_rank(tmp_path, ranks, own, d):
    """N = 2, 3 ranks (one process: the test above), cyclic ownership / rank 0 owning no contact: for a diagonally dominant,
    an unsymmetric, a singular and again a dominant J (one solver): x = spsolve to 1e-12 relative (measured
    <= 8.1e-16), the same bits on every rank; None on every rank for the singular J, no hang. Catches a wrong
    renumbering (checked: `new = order` instead of its inverse fails the cyclic cases, where the owned contacts are
    not a contiguous range of the global numbering) and blocks inserted transposed; a rank with no contact takes
    part in every collective. Not caught: dropping the MPI max of the failure flag (MUMPS reports a singular J on
    every rank by itself; the max guards the other failures)."""
    indptr, indices = pattern(90, seed=5 + d)
    n = indptr.size - 1
    rng = np.random.default_rng(d)
    kinds = ["dominant", "unsymmetric", "singular", "dominant"]
    systems = {}
    for k, kind in enumerate(kinds):
        systems[f"blocks_{k}"] = blocks(indptr, indices, d, kind, seed=20 + k)
        systems[f"rhs_{k}"] = rng.normal(size=d * n)
    np.savez(tmp_path / "in.npz", indptr=indptr, indices=indices, dim=d, **systems)
    _mpirun(ranks, "solve", tmp_path / "in.npz", tmp_path / "out.npz", "--own", own)
    out = np.load(tmp_path / "out.npz", allow_pickle=True)
    assert int(out["ranks"]) == ranks and sum(out["n_own"]) == n
    if own == "skip0":
        assert out["n_own"][0] == 0
    for k, kind in enumerate(kinds):
        assert bool(out[f"same_{k}"]), k
        if kind == "singular":
            assert bool(out[f"none_{k}"])
            continue
        x_ref = reference(indptr, indices, systems[f"blocks_{k}"], systems[f"rhs_{k}"])
        assert not bool(out[f"none_{k}"]) and rel(out[f"x_{k}"], x_ref) <= 1e-12, (kind, rel(out[f"x_{k}"], x_ref))



def _random_3d(tmp_path, n=60, seed=1):
    """A 3D problem with an SPD W (tests/test_nlgs.random_problem_3d: unique solution), μ = 0.3, as an .npz."""
    from test_nlgs import random_problem_3d
    Wd, q = random_problem_3d(n, seed)
    W = to_block_csr(Wd, 3)
    path = tmp_path / "random3d.npz"
    np.savez(path, indptr=W.indptr, indices=W.indices, blocks=W.blocks, diag_pos=W.diag_pos, q=q,
             mu=np.full(W.n, 0.3), tol=1e-8)
    return W, q, np.full(W.n, 0.3), path


@needs_mpirun
@pytest.mark.parametrize("case, ranks, own", [("random3d", 3, "skip0")])
def test_mpirun_newton_equals_serial_newton(tmp_path, case, ranks, own):
    """solve_newton(..., linear=DistBlockSolver) from r = 0 (gs_sweeps = 0: every step is Newton's), tolerance 1e-8,
    against the serial solve_newton (BlockLU in 2D, SuperLU in 3D):
    - FCLIB fc2d_granularflowonwall_00667_00000 (2D, 667 contacts, W of full rank): 5 iterations both, r within
      1e-12 relative (measured 1.2e-16);
    - (measured once; not in the suite, for time) FCLIB Capsules-i97-269 (3D, 216 contacts): 13 iterations both, u = W r + q within 1e-12 (measured 1.0e-16)
      but r only within 1e-5 (measured 1.6e-6): W has rank 451 of 648, r is not unique, J = D + E (W + ε I) is
      nearly singular along W's null space and r moves there with the rounding of the LU (the serial Newton with
      MUMPS instead of SuperLU, same process, differs from it by 1.3e-6 too);
    - a random 3D problem with SPD W (60 contacts) on 3 ranks, rank 0 owning no contact: 4 iterations both, r within
      1e-12 (measured 1.8e-16).
    Always: converged, the same r and iteration count on every rank, one linear solve per iteration, the natural-map
    residual recomputed independently (fclib.residual) <= 1e-8. Catches a hook that ignores `linear`
    (linear_calls = 0), a sign error of the right-hand side (no convergence) and a rank-dependent direction
    (same = False)."""
    from fem_blocks.io import fclib
    if case == "random3d":
        W, q, mu, problem = _random_3d(tmp_path)
        Wsp = W.to_scipy()
    else:
        problem = GRANULAR if case == "granular" else CAPSULES
        if not os.path.exists(problem):
            pytest.skip(f"FCLIB data not found at {FCLIB_DIR}")
        p = fclib.read(problem)
        W, q, mu, Wsp = to_block_csr(p.W, p.dim), p.q, p.mu, p.W
    serial = newton.solve_newton(W, q, mu, tol=1e-8, gs_sweeps=0)
    _mpirun(ranks, "newton", problem, tmp_path / "out.npz", "--own", own, "--gs", 0, "--tol", 1e-8)
    out = np.load(tmp_path / "out.npz", allow_pickle=True)
    assert serial.converged and bool(out["converged"]), str(out["message"])
    assert bool(out["same"])
    assert int(out["sweeps"]) == serial.sweeps == {"granular": 5, "capsules": 13, "random3d": 4}[case], \
        (str(out["message"]), serial.message)
    assert int(out["linear_calls"]) == serial.sweeps  # no Gauss–Seidel sweep, no fallback: one solve per iteration
    r = out["r"]
    if case == "capsules":
        assert rel(Wsp @ r + q, serial.u) <= 1e-12
        assert rel(r, serial.r) <= 1e-5
    else:
        assert rel(r, serial.r) <= 1e-12
    assert fclib.residual(Wsp, q, mu, r, W.dim).rel_q <= 1e-8


@needs_mpirun
@pytest.mark.parametrize("case, own", [("random", "cyclic")])
def test_mpirun_cohesive_newton_equals_serial(tmp_path, case, own):
    """solve_cohesive_newton(..., linear=DistBlockSolver) on 2 ranks against the serial solve (tolerance 1e-10), on the
    softening problems of tests/test_newton_softening.py: "random" (30 compliant mixed-mode joints, damage inside:
    serial 13 Newton iterations) and "crack" (40 joints; the compliant coupled pass gives up and the Alart–Curnier
    pass converges: serial 62 iterations, 40 fallbacks). Expect: converged, the serial Newton iteration and sweep
    count, r within 1e-12 relative (measured in one process: 2.4e-17 and 5.7e-19) and the damage x within 1e-12
    (measured 6.7e-16 and 1.7e-15), the same bits on every rank, one linear solve per Newton iteration. Catches
    `linear` not passed down from solve_cohesive_newton to _newton (linear_calls = 0) and rank-dependent results."""
    import test_newton_softening as ts
    prob = ts._random_problem() if case == "random" else ts._crack_and_joint_problem()
    W, q, mu, law, par, st, ueff, area, h, th = prob
    serial, x = newton.solve_cohesive_newton(*prob, tol=1e-10)
    np.savez(tmp_path / "in.npz", indptr=W.indptr, indices=W.indices, blocks=W.blocks, diag_pos=W.diag_pos, q=q,
             mu=mu, law=law, par=par, st=st, ueff=ueff, area=area, h=h, theta=th, tol=1e-10)
    _mpirun(2, "cohesive", tmp_path / "in.npz", tmp_path / "out.npz", "--own", own)
    out = np.load(tmp_path / "out.npz", allow_pickle=True)
    assert serial.converged and bool(out["converged"]) and bool(out["same"]), str(out["message"])
    assert str(out["message"]) == serial.message  # iterations, sweeps, fallbacks and residual (3 digits)
    n_it = int(serial.message.split(":")[1].split("Newton")[0])
    assert n_it == {"random": 13, "crack": 62}[case] and int(out["linear_calls"]) == n_it
    assert rel(out["r"], serial.r) <= 1e-12
    assert np.abs(out["x"] - x).max() <= 1e-12
