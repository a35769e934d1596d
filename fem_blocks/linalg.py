"""Linear algebra: the block-CSR matrix of the contact solvers, and sparse direct factorizations with PETSc.

`BlockCSR` stores a matrix of d x d blocks (d = 2 or 3, one block row per contact: the Delassus operator W of
u = W r + q) as plain arrays (indptr, indices, blocks (nnzb, d, d), diag_pos) that the numba kernels take without
scipy objects; `to_block_csr` builds it from a dense or scipy matrix, `matvec_bcsr` computes y = W x.

Sparse direct factorizations with PETSc (petsc4py), shared by all instances of a block type:

`Factor(A)` factors a symmetric positive definite scipy CSR matrix once (PETSc's own LU for small
systems, CHOLMOD Cholesky from 1000 dofs up; superlu_dist is never used, see docs/stack-facts.md §2) and
solves `A x = b` for one or many right-hand sides (`MatMatSolve` on a dense block).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit
from petsc4py import PETSc

from .errors import InputError


@dataclass
class BlockCSR:
    indptr: np.ndarray   # (nc+1,) int64
    indices: np.ndarray  # (nnzb,) int64, sorted per row
    blocks: np.ndarray   # (nnzb, d, d) float64, C-contiguous
    diag_pos: np.ndarray  # (nc,) int64: position of the diagonal block of each row

    @property
    def n(self) -> int:
        return len(self.indptr) - 1

    @property
    def dim(self) -> int:
        return self.blocks.shape[1]

    def to_scipy(self) -> sp.csr_matrix:
        d = self.dim
        return sp.bsr_matrix((self.blocks, self.indices, self.indptr), shape=(d * self.n, d * self.n)).tocsr()


def to_block_csr(W, dim: int = 2) -> BlockCSR:
    """Block-CSR of a dense or sparse W (m x m, m = dim * nc); a missing diagonal block is added as zeros."""
    if isinstance(W, BlockCSR):
        return W
    if sp.issparse(W):
        Ws = W.tocsr()
    else:
        Wd = np.asarray(W, dtype=float)
        if Wd.ndim != 2:
            raise InputError(f"W: expected a square matrix, got shape {Wd.shape}")
        Ws = sp.csr_matrix(Wd)
    m = Ws.shape[0]
    if Ws.shape[1] != m or m % dim:
        raise InputError(f"W: expected a square matrix of size dim * n_contacts, got shape {Ws.shape} (dim {dim})")
    nc = m // dim
    c = Ws.tocoo()  # explicit zero diagonal entries (a csr sum would drop them): every row gets its diagonal block
    Ws = sp.coo_matrix((np.r_[c.data, np.zeros(m)], (np.r_[c.row, np.arange(m)], np.r_[c.col, np.arange(m)])),
                       shape=(m, m)).tocsr()
    B = Ws.tobsr(blocksize=(dim, dim))
    B.sort_indices()
    indptr = B.indptr.astype(np.int64)
    indices = B.indices.astype(np.int64)
    blocks = np.ascontiguousarray(B.data, dtype=np.float64)
    diag_pos = np.full(nc, -1, dtype=np.int64)
    rows = np.repeat(np.arange(nc), np.diff(indptr))
    on = rows == indices
    diag_pos[rows[on]] = np.flatnonzero(on)
    return BlockCSR(indptr, indices, blocks, diag_pos)


@njit(cache=True)
def matvec_bcsr(indptr, indices, blocks, x, y):
    """y = W x (block-CSR, d x d blocks, d = blocks.shape[1])."""
    n = indptr.shape[0] - 1
    dd = blocks.shape[1]
    for a in range(n):
        for i in range(dd):
            y[dd * a + i] = 0.0
        for k in range(indptr[a], indptr[a + 1]):
            b = indices[k]
            for i in range(dd):
                s = 0.0
                for j in range(dd):
                    s += blocks[k, i, j] * x[dd * b + j]
                y[dd * a + i] += s


SMALL_SYSTEM = 1000  # dofs: below, PETSc LU is fastest; above, CHOLMOD Cholesky


def _to_petsc(A: sp.csr_matrix) -> PETSc.Mat:
    A = sp.csr_matrix(A)
    A.sort_indices()
    return PETSc.Mat().createAIJ(size=A.shape, csr=(A.indptr.astype(PETSc.IntType),
                                                    A.indices.astype(PETSc.IntType),
                                                    A.data.astype(PETSc.ScalarType)),
                                 comm=PETSc.COMM_SELF)


# method -> (PETSc PC type, factor package)
_METHODS = {"petsc-lu": ("lu", "petsc"), "cholmod": ("cholesky", "cholmod"), "mumps": ("cholesky", "mumps"),
            "mumps-lu": ("lu", "mumps")}


class Factor:
    """Factorization of a sparse matrix — SPD for petsc-lu / cholmod / mumps (Cholesky), general for mumps-lu;
    `solve(b)` with b of shape (n,) or (n, k); `destroy()` frees it at once (PETSc objects, MUMPS factors).
    Raises PETSc.Error when the factorisation fails (singular matrix)."""

    def __init__(self, A: sp.spmatrix, method: str = "auto"):
        n = A.shape[0]
        if method == "auto":
            method = "petsc-lu" if n < SMALL_SYSTEM else "cholmod"
        if method not in _METHODS:
            raise ValueError(f"factor method {method!r}: expected auto, petsc-lu, cholmod, mumps or mumps-lu")
        self.n, self.method = n, method
        self._A = _to_petsc(A)
        ksp = self._ksp = PETSc.KSP().create(PETSc.COMM_SELF)
        self._b, self._x = self._A.createVecs()
        ksp.setOperators(self._A)
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType(_METHODS[method][0])
        pc.setFactorSolverType(_METHODS[method][1])
        try:
            ksp.setUp()
        except PETSc.Error:
            self.destroy()
            raise
        self._F = pc.getFactorMatrix()

    def failed(self) -> bool:
        """The last solve did not succeed (PETSc's converged reason < 0)."""
        return self._ksp.getConvergedReason() < 0

    def destroy(self):
        """Free the factor now: without PC.reset() + destroy() the memory of a MUMPS factorisation stays until the
        interpreter exits (130 MB per factorisation of the dome's Newton Jacobian, measured)."""
        self._ksp.getPC().reset()
        for obj in (getattr(self, "_F", None), self._ksp, self._A, self._b, self._x):
            if obj is not None:
                obj.destroy()

    def solve(self, b: np.ndarray) -> np.ndarray:
        b = np.asarray(b, dtype=float)
        if b.ndim == 1:
            self._b.array[:] = b
            self._ksp.solve(self._b, self._x)
            return self._x.array.copy()
        n, k = b.shape
        if k == 0:
            return np.zeros((n, 0))
        if k == 1:
            return self.solve(b[:, 0])[:, None]
        B = PETSc.Mat().createDense((n, k), array=np.asfortranarray(b), comm=PETSc.COMM_SELF)
        X = PETSc.Mat().createDense((n, k), comm=PETSc.COMM_SELF)
        X.setUp()
        self._F.matSolve(B, X)
        out = np.array(X.getDenseArray(), copy=True)
        B.destroy(); X.destroy()
        return out


LU_SMALL = 3000  # unknowns: below, scipy's SuperLU; above, MUMPS (10-12x faster on the 3D dome's J, measured)


def lu_solve(A: sp.spmatrix, b: np.ndarray, method: str = "auto") -> np.ndarray | None:
    """x = A⁻¹ b for a general (non-symmetric) sparse A by a direct LU; None when A is singular.

    method: "superlu" (scipy, COLAMD ordering), "mumps" (PETSc/MUMPS, its own fill-reducing ordering) or "auto"
    (SuperLU below LU_SMALL unknowns, MUMPS above). Newton's Jacobians J = D + E W of a wall or a dome have
    hundreds of nonzeros per row (every contact point of a block is coupled through its W_bb): on the full 3D
    dome (24 336 unknowns, 8.1e6 nonzeros) SuperLU takes 26 s per factorisation, MUMPS 2.2 s
    (bench/bench_lu.py, docs/benchmarks.md)."""
    n = A.shape[0]
    if method == "auto":
        method = "superlu" if n < LU_SMALL else "mumps"
    if method == "superlu":
        import scipy.sparse.linalg as spla
        try:
            x = spla.splu(sp.csc_matrix(A)).solve(np.asarray(b, dtype=float))
        except RuntimeError:  # exactly singular
            return None
        return x if np.all(np.isfinite(x)) else None
    if method != "mumps":
        raise ValueError(f"lu method {method!r}: expected auto, superlu or mumps")
    try:
        F = Factor(A, "mumps-lu")
    except PETSc.Error:  # MUMPS reports a singular (or numerically singular) matrix
        return None
    try:
        x = F.solve(b)
        failed = F.failed()
    finally:
        F.destroy()
    return None if failed or not np.all(np.isfinite(x)) else x
