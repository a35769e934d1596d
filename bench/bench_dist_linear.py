"""Distributed linear solve of the global Newton (fem_blocks/distributed/linear.py): time per solve J Δr = -F at
N = 1, 2 ranks against the serial solves of solver/newton.py (linalg.lu_solve: SuperLU below LU_SMALL unknowns,
MUMPS above; linalg.BlockLU in 2D below LU_SMALL).

Two stages, so that every run times the same systems:

    record PROBLEM OUT.npz [--iters K] [--gs S]   (serial) the Jacobians J_k (blocks in W's pattern) and right-hand
        sides -F_k of the first K Newton iterations of solver.newton.solve_newton on PROBLEM (an FCLIB .hdf5, or
        `wall:N` for the Delassus operator of bench/bench_wall.py's N-brick running-bond wall of deformable bricks,
        dry joints, captured at its 5th step), and the serial reference solutions;
    time IN.npz [--own blocks|cyclic] [--repeat R] [--options k=v,...]  (under mpirun -n N) DistBlockSolver on each J_k, R passes: the
        first call (symbolic analysis + numerical factorisation + solve), the later calls (numerical factorisation +
        solve, the analysis reused), a fresh solver per call (analysis every time), split into assembly /
        factorisation + solve / gather; on rank 0 also the serial lu_solve (and BlockLU in 2D below LU_SMALL),
        and the error against the recorded solutions.

Run: .venv/bin/python bench/bench_dist_linear.py record ... ; mpirun -n 2 .venv/bin/python bench/bench_dist_linear.py
time ...
"""
import os
import sys
import time

import numpy as np
import scipy.sparse as sp

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))


def opt(name, default):
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


def wall_problem(n_bricks, steps=5):
    """(W, q, mu) of the contact problem of the `steps`-th step of bench_wall.build(n_bricks) (dry joints)."""
    sys.path.insert(0, os.path.dirname(__file__))
    import bench_wall
    import fem_blocks.solver as fs
    got = {}
    orig = fs.solve

    def spy(problem, *a, **k):
        got["p"] = problem
        return orig(problem, *a, **k)

    fs.solve = spy
    try:
        sim = bench_wall.build(n_bricks, "dry")[0]
        for _ in range(steps):
            sim.step()
    finally:
        fs.solve = orig
    p = got["p"]
    return p.W, np.asarray(p.q, dtype=float), np.broadcast_to(np.asarray(p.mu, dtype=float), (p.W.n,)).copy()


def record():
    from fem_blocks.linalg import lu_solve, to_block_csr
    from fem_blocks.solver import newton
    src, out = sys.argv[2], sys.argv[3]
    if src.startswith("wall:"):
        W, q, mu = wall_problem(int(src[5:]))
    else:
        from fem_blocks.io import fclib
        p = fclib.read(src)
        W, q, mu = to_block_csr(p.W, p.dim), p.q, p.mu
    K = int(opt("--iters", 5))
    rec = []

    class Recorder:
        def solve(self, Jb, rhs):
            x = lu_solve(sp.bsr_matrix((Jb, W.indices, W.indptr), shape=(W.dim * W.n,) * 2), rhs)
            if len(rec) < K:
                rec.append((Jb.copy(), rhs.copy(), x))
            return x

    t = time.perf_counter()
    res = newton.solve_newton(W, q, mu, gs_sweeps=int(opt("--gs", 20)), max_iter=K, linear=Recorder())
    print(f"{src}: {W.n} contacts, {W.dim * W.n} unknowns, {W.indices.size} blocks; {res.message} "
          f"({time.perf_counter() - t:.1f} s)")
    data = dict(indptr=W.indptr, indices=W.indices, dim=W.dim, name=src)
    for k, (Jb, b, x) in enumerate(rec):
        data[f"blocks_{k}"], data[f"rhs_{k}"], data[f"x_{k}"] = Jb, b, np.full(b.size, np.nan) if x is None else x
    np.savez(out, **data)


def timed():
    from mpi4py import MPI
    from fem_blocks.distributed.linear import DistBlockSolver
    from fem_blocks.distributed.sweep import ownership
    from fem_blocks.linalg import LU_SMALL, BlockLU, lu_solve
    comm = MPI.COMM_WORLD
    rank, size = comm.Get_rank(), comm.Get_size()
    z = dict(np.load(sys.argv[2]))
    indptr, indices, d = z["indptr"], z["indices"], int(z["dim"])
    n = indptr.size - 1
    K = sum(1 for k in z if k.startswith("blocks_"))
    R = int(opt("--repeat", 3))
    owner = ownership(n, size, opt("--own", "blocks"))
    comm.Barrier()
    t = time.perf_counter()
    options = dict(o.split("=") for o in opt("--options", "").split(",") if o)
    s = DistBlockSolver(indptr, indices, d, owner, comm, options=options)
    t_build = time.perf_counter() - t
    first, later, err = None, [], 0.0
    for rep in range(R):
        for k in range(K):
            comm.Barrier()
            t = time.perf_counter()
            x = s.solve(z[f"blocks_{k}"], z[f"rhs_{k}"])
            dt = time.perf_counter() - t
            if first is None:
                first = dt
                split0 = (s.t_assemble, s.t_factor_solve, s.t_gather)
            else:
                later.append(dt)
            ref = z[f"x_{k}"]
            err = np.inf if x is None else max(err, float(np.linalg.norm(x - ref) / np.linalg.norm(ref)))
    split = [(a - b) / max(s.n_calls - 1, 1) for a, b in zip((s.t_assemble, s.t_factor_solve, s.t_gather), split0)]
    s.destroy()
    fresh = []
    for k in range(K):
        comm.Barrier()
        t = time.perf_counter()
        f = DistBlockSolver(indptr, indices, d, owner, comm, options=options)
        f.solve(z[f"blocks_{k}"], z[f"rhs_{k}"])
        f.destroy()
        fresh.append(time.perf_counter() - t)
    mine = np.array([t_build, first, np.mean(later), np.mean(fresh)] + split)
    tmax = np.empty_like(mine)
    comm.Reduce(mine, tmax, op=MPI.MAX, root=0)  # the slowest rank
    if rank == 0:
        print(f"{z['name']}: {n} contacts, {d * n} unknowns, {indices.size} blocks, {K} systems x {R}; "
              f"N = {size} ({s.method}), own {opt('--own', 'blocks')}, options {options}")
        print(f"  DistBlockSolver: set-up {tmax[0] * 1e3:.1f} ms; first solve {tmax[1] * 1e3:.1f} ms; later solves "
              f"{tmax[2] * 1e3:.1f} ms (assembly {tmax[4] * 1e3:.1f}, factorisation + solve {tmax[5] * 1e3:.1f}, "
              f"gather {tmax[6] * 1e3:.1f}); fresh solver per solve {tmax[3] * 1e3:.1f} ms; "
              f"max error vs recorded {err:.1e}")
        if size == 1:
            ser = []
            for k in range(K):
                A = sp.bsr_matrix((z[f"blocks_{k}"], indices, indptr), shape=(d * n, d * n))
                t = time.perf_counter()
                lu_solve(A, z[f"rhs_{k}"])
                ser.append(time.perf_counter() - t)
            meth = "SuperLU" if d * n < LU_SMALL else "MUMPS"
            line = f"  serial lu_solve ({meth}, scipy BSR -> solver each call): {np.mean(ser) * 1e3:.1f} ms"
            if d == 2 and d * n < LU_SMALL:
                blu = BlockLU.for_pattern(indptr, indices, d)
                bt = []
                for k in range(K):
                    t = time.perf_counter()
                    blu.solve_checked(z[f"blocks_{k}"], z[f"rhs_{k}"])
                    bt.append(time.perf_counter() - t)
                line += f"; BlockLU (analysis reused) {np.mean(bt) * 1e3:.1f} ms"
            print(line)


if __name__ == "__main__":
    {"record": record, "time": timed}[sys.argv[1]]()
