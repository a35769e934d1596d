"""The distributed colour-order Gauss–Seidel (fem_blocks/distributed/sweep.py: rows of W owned per rank, the
interface impulses exchanged per colour by PETSc scatters) solved by its one driver, colour.ColourSolver, and the
file driver `python -m fem_blocks.distributed.colour` built on it.

Expectations (independent of the code under test): the iterates and sweep count of the serial Gauss–Seidel sweep
in colour order, `solver.parallel.solve_parallel(comm=None)` (a replicated sweep of its own); the stopping test's
residual sqrt(Σ_α ‖F_α‖²)/‖q‖ with both sums correctly rounded by `math.fsum` (the FCLIB natural-map terms
`nlgs.natural_map_terms`, which tests/test_natural_map_terms.py checks against the serial natural map); the
ghosts, exchanged entries and messages per rank counted here from W's nonzero blocks, the ownership and the
colours. N = 1, 2, 3 ranks with contiguous, cyclic, PT-Scotch ownership and a rank without contacts must give the
same impulses, sweep count and residual, bitwise. Ranks run under mpirun: ONE launch per rank count
(tests/_dist_sweep_mpi.py calls the file driver's main once per run), the tests read what each run wrote."""
import json
import math
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
import scipy.sparse as sp

from fem_blocks.distributed import sweep as ds
from fem_blocks.distributed.colour import ColourSolver
from fem_blocks.linalg import matvec_bcsr, to_block_csr
from fem_blocks.solver import nlgs, parallel

from _mpi import ENV  # noqa: E402
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


def problem_3d():
    """A 3D problem (3x3 blocks, the local solver of solver/local.py): W = A Aᵀ + diag, sparse A (W, q, mu)."""
    from test_nlgs import random_problem_3d
    Wd, q = random_problem_3d(n=40, seed=2)
    W = to_block_csr(Wd, 3)
    return W, q, np.full(W.n, 0.4)


def exact_residual(W, q, mu, r):
    """sqrt(Σ_α ‖F_α‖²) / sqrt(Σ q_i²), both sums correctly rounded (math.fsum), u = W r + q row by row."""
    u = np.empty_like(q)
    matvec_bcsr(W.indptr, W.indices, W.blocks, r, u)
    u += q
    t = nlgs.natural_map_terms(r, u, mu, W.dim)
    return math.sqrt(math.fsum(t)) / (math.sqrt(math.fsum(q * q)) or 1.0)


def expected_exchange(W, owner, size):
    """Per rank (n_own, n_ghost, bytes sent, bytes received, messages received) per sweep, counted from W's nonzero
    blocks: rank p's ghosts are the contacts β owned elsewhere with W_αβ ≠ 0 for an owned α; it receives d doubles
    per ghost, sends d doubles per (owned contact, rank that ghosts it), and receives one message per colour and
    owner rank among its ghosts of that colour (colours: parallel.colour_contacts)."""
    d = W.dim
    colour = parallel.colour_contacts(W)
    nz = np.any(W.blocks != 0.0, axis=(1, 2))
    row = np.repeat(np.arange(W.n), np.diff(W.indptr))
    ghosts = []
    for p in range(size):
        mine = owner[row] == p
        g = np.unique(W.indices[mine & nz])
        ghosts.append(g[owner[g] != p])
    out = []
    for p in range(size):
        sent = sum(int(np.sum(owner[ghosts[k]] == p)) for k in range(size) if k != p)
        msgs = len({(int(colour[b]), int(owner[b])) for b in ghosts[p]})
        out.append((int(np.sum(owner == p)), ghosts[p].size, 8 * d * sent, 8 * d * ghosts[p].size, msgs))
    return out


def test_localise_numbers_owned_then_ghosts_in_increasing_order():
    """sweep.localise (a rank's own rows, global column numbers -> local ones) against its definition: local number
    of an owned contact = its position in `owned`; the ghosts = the columns met that are not owned, increasing, numbered
    after them. Global numbers with gaps, owned contacts that no row reads, the largest number an owned one, no rows.
    Catches a ghost list with repeats or owned contacts, ghosts numbered before the owned, a table cut at the largest
    column."""
    rng = np.random.default_rng(11)
    for trial in range(30):
        universe = np.sort(rng.choice(10 ** 6, 60, replace=False))
        owned = np.sort(rng.choice(universe, int(rng.integers(0, 15)), replace=False))
        nrow = owned.size
        lens = rng.integers(0, 6, nrow)
        indptr = np.concatenate([[0], np.cumsum(lens)]).astype(np.int64)
        cols = np.concatenate([np.sort(rng.choice(universe, n, replace=False)) for n in lens]).astype(np.int64) \
            if nrow else np.zeros(0, dtype=np.int64)
        lr = ds.localise(owned, indptr, cols, np.zeros((cols.size, 2, 2)), np.zeros(nrow, dtype=np.int64))
        ghost = np.array(sorted(set(cols.tolist()) - set(owned.tolist())), dtype=np.int64)
        assert np.array_equal(lr.ghost, ghost), trial
        number = {int(c): k for k, c in enumerate(owned)}
        number.update({int(c): owned.size + k for k, c in enumerate(ghost)})
        assert lr.indices.tolist() == [number[int(c)] for c in cols], trial


@pytest.mark.parametrize("dim", [2, 3])
def test_colour_solver_is_the_serial_colour_order_with_the_exact_residual(dim):
    """One process: ColourSolver (contacts coloured one by one, residual criterion every 10 sweeps) gives
    solve_parallel's impulses, u and sweep count bitwise; its residual is the fsum expectation bitwise, and differs
    from solve_parallel's running sum by rounding only (<= 1e-13 relative). Catches ‖q‖² for ‖q‖ in the stopping
    test (checked: `qnorm = float(exact_sums(...)[0])`, without the sqrt, fails)."""
    W, q, mu = grid_problem() if dim == 2 else problem_3d()
    serial = parallel.solve_parallel(W, q, mu, tol=1e-10, max_sweeps=100000)
    res = ColourSolver(W).solve(q, mu, tol=1e-10, criterion="residual", max_sweeps=100000, check_every=10)
    assert serial.converged and res.converged
    assert res.sweeps == serial.sweeps and np.array_equal(res.r, serial.r) and np.array_equal(res.u, serial.u)
    assert res.residual == exact_residual(W, q, mu, serial.r)
    assert abs(res.residual - serial.residual) <= 1e-13 * serial.residual


def test_file_driver_on_one_process(tmp_path):
    """The file driver without mpirun (one rank, serial ColourSolver, nothing exchanged): solve_parallel's r and
    sweeps, the fsum residual, the tolerance read from the .npz. Catches the .npz's tol ignored (checked: the
    default 1e-8 instead of its 1e-10 stops after 230 sweeps instead of 310 and fails)."""
    W, q, mu = grid_problem()
    prob = tmp_path / "p.npz"
    np.savez(prob, indptr=W.indptr, indices=W.indices, blocks=W.blocks, diag_pos=W.diag_pos, q=q, mu=mu, tol=1e-10)
    from fem_blocks.distributed import colour
    assert colour.main([str(prob), str(tmp_path / "out.npz"), "--own", "cyclic"]) == 0
    out = np.load(tmp_path / "out.npz")
    serial = parallel.solve_parallel(W, q, mu, tol=1e-10, max_sweeps=100000)
    assert int(out["ranks"]) == 1 and bool(out["converged"]) and int(out["sweeps"]) == serial.sweeps
    assert np.array_equal(out["r"], serial.r) and float(out["residual"]) == exact_residual(W, q, mu, serial.r)
    assert [list(out[k]) for k in ("n_own", "n_ghost", "bytes_sent", "bytes_recv", "messages")] == \
        [[W.n], [0], [0], [0], [0]]


# (ranks, problem, ownership): every run of one rank count in one mpirun launch
RUNS = [(2, "grid", "blocks"), (2, "grid", "skip0"), (2, "p3d", "cyclic"), (2, "p3d", "ptscotch"),
        (3, "grid", "cyclic"), (3, "grid", "ptscotch"), (3, "grid", "skip0"), (3, "fclib", "blocks")]
FCLIB_ARGS = ["--tol", "1e-12", "--max-sweeps", "300"]


def _problem(name):
    """(W, q, mu, tol, max_sweeps) of a run's problem."""
    if name == "fclib":
        from fem_blocks.io import fclib
        p = fclib.read(GRANULAR)
        return to_block_csr(p.W, p.dim), p.q, p.mu, 1e-12, 300
    W, q, mu = grid_problem() if name == "grid" else problem_3d()
    return W, q, mu, 1e-10, 100000


@pytest.fixture(scope="module")
def launches(tmp_path_factory):
    """{(ranks, problem, own): OUT.npz of that run}: one mpirun launch per rank count (2, 3)."""
    if shutil.which("mpirun") is None:
        pytest.skip("no mpirun")
    d = tmp_path_factory.mktemp("dist_sweep")
    paths = {"fclib": GRANULAR}
    for name in ("grid", "p3d"):
        W, q, mu, tol, _ = _problem(name)
        paths[name] = str(d / f"{name}.npz")
        np.savez(paths[name], indptr=W.indptr, indices=W.indices, blocks=W.blocks, diag_pos=W.diag_pos, q=q, mu=mu,
                 tol=tol)
    outs = {}
    for n in sorted({r[0] for r in RUNS}):
        runs = []
        for key in (r for r in RUNS if r[0] == n and (r[1] != "fclib" or os.path.exists(GRANULAR))):
            outs[key] = str(d / f"out_{n}_{key[1]}_{key[2]}.npz")
            runs.append([paths[key[1]], outs[key], "--own", key[2]] + (FCLIB_ARGS if key[1] == "fclib" else []))
        (d / f"runs{n}.json").write_text(json.dumps(runs))
        try:
            p = subprocess.run(["mpirun", "-n", str(n), sys.executable,
                                os.path.join(ROOT, "tests", "_dist_sweep_mpi.py"), str(d / f"runs{n}.json")],
                               capture_output=True, text=True, cwd=ROOT, env=ENV, timeout=120)
        except subprocess.TimeoutExpired as e:
            pytest.fail(f"{n} ranks: the launch did not end in 120 s (a rank left waiting in a collective, e.g. ranks "
                        f"whose stopping decisions differ)\n{e.stdout}\n{e.stderr}")
        assert p.returncode == 0, (p.stdout + p.stderr)[-3000:]
    return outs


def _out(launches, key):
    if key not in launches:
        pytest.skip(f"FCLIB data not found at {FCLIB_DIR}")
    return np.load(launches[key])


@pytest.mark.parametrize("key", RUNS, ids=["-".join(map(str, r)) for r in RUNS])
def test_mpirun_file_driver_equals_serial_colour_order_bitwise(launches, key):
    """N = 2, 3 ranks through the file driver (ColourSolver on MPI.COMM_WORLD): solve_parallel's impulses, sweep count
    and convergence, bitwise; the fsum residual bitwise, the same as on one process. Catches: after each colour the
    impulses of colour 0 exchanged (checked: `scatters[0]` in ColourSolver._exchange fails every run where impulses
    cross ranks, all but 2-grid-skip0); ‖q‖ summed over a rank's own contacts only (checked: `exact_sums([qo * qo],
    None)`: the ranks' stopping decisions differ, a rank is left waiting and the launch fails at its timeout)."""
    out = _out(launches, key)
    W, q, mu, tol, max_sweeps = _problem(key[1])
    serial = parallel.solve_parallel(W, q, mu, tol=tol, max_sweeps=max_sweeps)
    assert int(out["ranks"]) == key[0] and bool(out["converged"]) == serial.converged
    assert int(out["sweeps"]) == serial.sweeps
    assert np.array_equal(out["r"], serial.r)                                  # iterates, bitwise
    assert float(out["residual"]) == exact_residual(W, q, mu, serial.r)       # exact sums: any N, the same bits


@pytest.mark.parametrize("key", RUNS, ids=["-".join(map(str, r)) for r in RUNS])
def test_mpirun_exchange_counts_per_rank(launches, key):
    """Per rank, the contacts owned and ghosted, bytes sent and received and messages per sweep (the counters of
    distributed.sweep.DistSweep): those counted here from W and the ownership (contiguous: contact a on rank
    ⌊a N / n⌋; cyclic: a mod N; skip0: rank 0 none, ranks 1..N-1 contiguous); PT-Scotch (owner unknown here):
    sent = received = d doubles per ghost over all ranks. Catches the messages counted per ghost contact instead of
    per (colour, owner rank) (checked: `remote_owner[cgh == c].size` without np.unique fails)."""
    out = _out(launches, key)
    n_ranks, name, own = key
    W = _problem(name)[0]
    got = list(zip(*(out[k].tolist() for k in ("n_own", "n_ghost", "bytes_sent", "bytes_recv", "messages"))))
    if own == "ptscotch":
        assert sum(g[0] for g in got) == W.n and all(g[0] > 0 for g in got)
        assert sum(g[2] for g in got) == sum(g[3] for g in got) == 8 * W.dim * sum(g[1] for g in got) > 0
        return
    a = np.arange(W.n)
    owner = {"blocks": a * n_ranks // W.n, "cyclic": a % n_ranks,
             "skip0": 1 + a * (n_ranks - 1) // W.n}[own]
    assert got == expected_exchange(W, owner, n_ranks)
    if own == "skip0":
        assert got[0] == (0, 0, 0, 0, 0)
    else:
        assert all(g[1] > 0 for g in got)  # the ownership cuts the contact graph: impulses cross ranks
