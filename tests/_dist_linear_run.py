"""mpirun driver of tests/test_dist_linear.py (and bench/bench_dist_linear.py): every rank reads the same input,
builds a DistBlockSolver with the asked ownership and runs one of

    solve    IN.npz OUT.npz --own K: indptr, indices, dim and the systems J_k (blocks_k, rhs_k) in IN; solves them in
             turn with one solver (the pattern's analysis reused); OUT: x_k (NaN when None), none_k, and
             same_k = every rank returned the same bits;
    newton   PROBLEM OUT.npz --own K: newton.solve_newton on an FCLIB .hdf5 or an .npz (indptr, indices, blocks,
             diag_pos, q, mu, tol), options --tol T (default 1e-8 or the file's) --gs K (Gauss–Seidel start
             sweeps, default 20); OUT: r, message, residual, converged, sweeps, same, linear_calls;
    cohesive IN.npz OUT.npz --own K: newton.solve_cohesive_newton on the problem in IN (W, q, mu, law, par, st, ueff,
             area, h, theta, tol); OUT as newton plus the internal variables x.

--own blocks | cyclic | skip0 (as distributed.sweep.ownership: skip0 leaves rank 0 without a contact)."""
import sys

import numpy as np


def main():
    from mpi4py import MPI
    from fem_blocks.distributed.linear import DistBlockSolver
    from fem_blocks.distributed.sweep import ownership
    from fem_blocks.linalg import BlockCSR, to_block_csr
    from fem_blocks.solver import newton

    mode, src, out = sys.argv[1:4]
    def opt(name, default):
        return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default

    own = opt("--own", "blocks")
    gs = int(opt("--gs", 20))
    comm = MPI.COMM_WORLD
    rank, size = comm.Get_rank(), comm.Get_size()

    def same(a):
        """Every rank holds the same bits of a (None on all ranks counts as the same)."""
        b = comm.bcast(a, root=0)
        ok = (a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b, equal_nan=True))
        return bool(comm.allreduce(int(ok), op=MPI.MIN))

    res = dict(ranks=size)
    if mode == "solve":
        z = dict(np.load(src))
        n = z["indptr"].size - 1
        owner = ownership(n, size, own)
        s = DistBlockSolver(z["indptr"], z["indices"], int(z["dim"]), owner, comm)
        res["method"] = s.method
        res["n_own"] = comm.gather(s.n_own, root=0)
        k = 0
        while f"blocks_{k}" in z:
            x = s.solve(z[f"blocks_{k}"], z[f"rhs_{k}"])
            res[f"none_{k}"] = x is None
            res[f"x_{k}"] = np.full(z[f"rhs_{k}"].size, np.nan) if x is None else x
            res[f"same_{k}"] = same(x)
            k += 1
        s.destroy()
    else:
        if src.endswith(".hdf5"):
            from fem_blocks.io import fclib
            p = fclib.read(src)
            W, q, mu, tol = to_block_csr(p.W, p.dim), p.q, p.mu, 1e-8
            z = {}
        else:
            z = dict(np.load(src))
            W = BlockCSR(z["indptr"].astype(np.int64), z["indices"].astype(np.int64),
                         np.ascontiguousarray(z["blocks"]), z["diag_pos"].astype(np.int64))
            q, mu, tol = z["q"], z["mu"], float(z["tol"])
        owner = ownership(W.n, size, own)
        s = DistBlockSolver(W.indptr, W.indices, W.dim, owner, comm)
        res["method"] = s.method
        if mode == "newton":
            r = newton.solve_newton(W, q, mu, tol=float(opt("--tol", tol)), gs_sweeps=gs, linear=s)
            x = None
        else:
            r, x = newton.solve_cohesive_newton(W, q, mu, z["law"], z["par"], z["st"], z["ueff"], z["area"],
                                                float(z["h"]), float(z["theta"]), tol=tol, gs_sweeps=gs, linear=s)
            res["x"] = x
        res.update(r=r.r, message=r.message, residual=r.residual, converged=r.converged, sweeps=r.sweeps,
                   same=same(r.r) and same(x) and same(np.array([r.sweeps, r.residual])),
                   linear_calls=s.n_calls)
        s.destroy()
    if rank == 0:
        np.savez(out, **res)


if __name__ == "__main__":
    main()
