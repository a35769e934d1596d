"""Distributed linear solve of the global Newton: J Δr = b on a PETSc MPIBAIJ matrix, rows owned per rank.

Newton's Jacobian (solver/newton.py) J = D + E (W + ε I) has the block pattern of W: n contacts, d×d blocks
(d = 2 or 3), block row α couples contact α to the contacts β with W_αβ ≠ 0. Phase A keeps W, q, r and the Newton
iteration replicated on every rank; only the linear solve of each iteration,

    J x = b,   J ∈ R^{dn×dn} (blocks J_αβ, pattern of W),   b ∈ R^{dn},

is distributed. Rank p owns the contacts {α : owner[α] = p} (any assignment). PETSc wants each rank's rows to be a
contiguous range, so the contacts are renumbered: new number π(α) = position of α in the list sorted by (owner, α)
(a stable argsort of `owner`; the owned contacts of rank p keep their order and occupy [s_p, s_p + n_p),
s_p = Σ_{q<p} n_q). J is assembled as the MPIBAIJ matrix P J Pᵀ (P the block permutation π): rank p inserts only
its block rows, each with its columns in increasing new number, and sets b_p = (P b) on its range. The matrix
is preallocated once from the pattern (diagonal and off-diagonal block counts per row), so the nonzero structure
never changes and PETSc's PC redoes only the numerical factorisation on each call (the symbolic analysis of MUMPS
is kept: measured in bench/bench_dist_linear.py). Solver: LU by MUMPS (`-pc_factor_mat_solver_type mumps`,
distributed factor) when PETSc has it; otherwise GMRES preconditioned per rank (block Jacobi, ILU(0) on each
rank's diagonal block), to relative tolerance `rtol`. The solution y = P x (new numbering, distributed) is
gathered on every rank by a PETSc scatter to all (VecScatterCreateToAll) and permuted back: x = Pᵀ y, identical
bits on every rank. A failed factorisation (MUMPS: singular J), a diverged Krylov solve or a non-finite entry of
x gives None on every rank (the KSP's reason combined with an MPI max over the ranks), and the KSP is rebuilt, so
that the next call starts from a fresh analysis (a bjacobi/ILU PC that failed once kept failing on the next,
regular J; MUMPS without PC.reset() too).

Measured (bench/bench_dist_linear.py, 2 cores shared with another job at 100 %, load 2.1-2.4): FCLIB
fc2d_granularflowonwall_07002_00801 (14 004 unknowns, 31 452 blocks), N = 1: first call 100 ms (analysis +
factorisation), later calls 39 ms (36 of them factorisation + solve), serial linalg.lu_solve (MUMPS, analysis every
call) 98 ms; N = 2: 107 ms per call. 1000-brick wall (25 558 unknowns, 625 131 blocks): N = 1 773 ms per call
(serial lu_solve 838 ms), N = 2 1010 ms: on this machine the distributed factorisation does not pay.
"""
from __future__ import annotations

import numpy as np

from ..errors import InputError


def has_mumps() -> bool:
    from petsc4py import PETSc
    return bool(PETSc.Sys.hasExternalPackage("mumps"))


class DistBlockSolver:
    """J x = b for J in a fixed block pattern (BlockCSR indptr/indices, global contact numbering, the same on every
    rank), rows owned per rank (`owner` (n,) rank of each contact). Collective: construct, `solve` and `destroy`
    on every rank of `comm` (an mpi4py communicator).

    method: "auto" (MUMPS LU when PETSc has it, else "gmres"), "mumps" or "gmres" (GMRES + block Jacobi/ILU(0),
    relative tolerance `rtol`). `self.method` says which one is used. `options`: PETSc options of this solver
    only (set under its own prefix, without the leading "-"), e.g. {"mat_mumps_icntl_7": 3} (MUMPS ordering)."""

    def __init__(self, indptr, indices, dim: int, owner, comm, method: str = "auto", rtol: float = 1e-12,
                 max_it: int = 10000, options: dict | None = None):
        from petsc4py import PETSc
        self.comm = comm
        rank, size = comm.Get_rank(), comm.Get_size()
        indptr = np.asarray(indptr, dtype=np.int64)
        indices = np.asarray(indices, dtype=np.int64)
        owner = np.asarray(owner, dtype=np.int64).ravel()
        n = indptr.size - 1
        d = int(dim)
        if d not in (2, 3):
            raise InputError(f"DistBlockSolver: dim = {dim!r}: expected 2 or 3")
        if owner.size != n or (n and (owner.min() < 0 or owner.max() >= size)):
            raise InputError(f"DistBlockSolver: owner: expected {n} ranks in [0, {size})")
        if method == "auto":
            method = "mumps" if has_mumps() else "gmres"
        if method not in ("mumps", "gmres"):
            raise InputError(f"DistBlockSolver: method {method!r}: expected auto, mumps or gmres")
        if method == "mumps" and not has_mumps():
            raise InputError("DistBlockSolver: PETSc has no MUMPS")
        self.method, self.n, self.dim = method, n, d
        # renumbering: order[k] = old contact at new position k; new[α] = π(α)
        self.order = np.argsort(owner, kind="stable")
        new = np.empty(n, dtype=np.int64)
        new[self.order] = np.arange(n)
        counts = np.bincount(owner, minlength=size)
        start = int(counts[:rank].sum())
        n_own = int(counts[rank])
        self.n_own, self.start = n_own, start
        own = self.order[start:start + n_own]  # owned contacts, increasing old number
        self.own = own
        # the owned block rows in the new numbering, columns increasing; src = position in W's blocks
        cnt = indptr[own + 1] - indptr[own]
        pos = np.repeat(indptr[own] - np.cumsum(cnt) + cnt, cnt) + np.arange(int(cnt.sum()))
        row = np.repeat(np.arange(n_own), cnt)
        col = new[indices[pos]]
        srt = np.lexsort((col, row))
        self.src = pos[srt]
        self.cols = col[srt].astype(PETSc.IntType)
        self.rowptr = np.concatenate([[0], np.cumsum(cnt)]).astype(PETSc.IntType)
        diag = (self.cols >= start) & (self.cols < start + n_own)
        d_nnz = np.bincount(row, weights=diag, minlength=n_own).astype(PETSc.IntType)
        o_nnz = (cnt - d_nnz).astype(PETSc.IntType)
        pcomm = PETSc.Comm(comm)
        A = self.A = PETSc.Mat().createBAIJ(size=((d * n_own, d * n), (d * n_own, d * n)), bsize=d,
                                            nnz=(d_nnz, o_nnz), comm=pcomm)
        A.setOption(PETSc.Mat.Option.ROW_ORIENTED, False)  # values block by block, each block column-major
        A.setOption(PETSc.Mat.Option.NO_OFF_PROC_ENTRIES, True)
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        self.b, self.x = A.createVecs()
        self.gather, self.xall = PETSc.Scatter.toAll(self.x)
        self._ksp_args = (pcomm, method, rtol, max_it, options)
        self._make_ksp()
        self.n_calls = 0
        self.t_assemble = self.t_factor_solve = self.t_gather = 0.0

    def _make_ksp(self):
        """The KSP on A: preonly + LU (MUMPS), or GMRES + block Jacobi (ILU(0) per rank), and this solver's options
        (under its own prefix)."""
        from petsc4py import PETSc
        pcomm, method, rtol, max_it, options = self._ksp_args
        ksp = self.ksp = PETSc.KSP().create(pcomm)
        prefix = f"fb_dist_linear_{id(self)}_"
        ksp.setOptionsPrefix(prefix)
        ksp.setOperators(self.A)
        pc = ksp.getPC()
        if method == "mumps":
            ksp.setType("preonly")
            pc.setType("lu")
            pc.setFactorSolverType("mumps")
        else:
            ksp.setType("gmres")
            ksp.setTolerances(rtol=rtol, atol=0.0, max_it=max_it)
            ksp.setGMRESRestart(200)
            pc.setType("bjacobi")  # PETSc's default sub-solver: ILU(0) on each rank's diagonal block
        if options:
            db = PETSc.Options()
            for k, v in options.items():
                db[prefix + k] = v
            ksp.setFromOptions()

    def solve(self, Jb, rhs) -> np.ndarray | None:
        """x with J x = rhs, J of the blocks Jb (nnzb, d, d) in the pattern (replicated: each rank inserts only its
        owned block rows), rhs (d n,) replicated. Returns x (d n,), global numbering, the same on every rank, or
        None on every rank when the factorisation fails (J singular), the Krylov solve diverges or x is not
        finite."""
        import time
        from petsc4py import PETSc
        d = self.dim
        t0 = time.perf_counter()
        vals = np.ascontiguousarray(np.asarray(Jb, dtype=np.float64)[self.src].transpose(0, 2, 1))
        self.A.setValuesBlockedCSR(self.rowptr, self.cols, vals.ravel(), addv=PETSc.InsertMode.INSERT_VALUES)
        self.A.assemble()
        self.b.array[:] = np.asarray(rhs, dtype=np.float64).reshape(-1, d)[self.own].ravel()
        t1 = time.perf_counter()
        failed = 0
        try:
            self.ksp.solve(self.b, self.x)
            failed = int(self.ksp.getConvergedReason() < 0)
        except PETSc.Error:
            failed = 1
        failed = self.comm.allreduce(failed, op=_mpi_max())
        t2 = time.perf_counter()
        out = None
        if not failed:
            self.gather.scatter(self.x, self.xall, addv=PETSc.InsertMode.INSERT_VALUES,
                                mode=PETSc.ScatterMode.FORWARD)
            out = np.empty(d * self.n)
            out.reshape(-1, d)[self.order] = self.xall.array_r.reshape(-1, d)
            if not np.all(np.isfinite(out)):
                out = None
        else:  # start the next call from a fresh KSP (a failed PC keeps its failure: measured with bjacobi/ILU)
            self.ksp.getPC().reset()
            self.ksp.destroy()
            self._make_ksp()
        self.n_calls += 1
        self.t_assemble += t1 - t0
        self.t_factor_solve += t2 - t1
        self.t_gather += time.perf_counter() - t2
        return out

    def destroy(self):
        """Free the PETSc objects (the MUMPS factor with the PC)."""
        self.ksp.getPC().reset()
        for obj in (self.ksp, self.A, self.b, self.x, self.gather, self.xall):
            obj.destroy()


def _mpi_max():
    from mpi4py import MPI
    return MPI.MAX
