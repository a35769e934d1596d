"""Sparse direct factorizations with PETSc (petsc4py), shared by all instances of a block type.

`Factor(A)` factors a symmetric positive definite scipy CSR matrix once (PETSc's own LU for small
systems, CHOLMOD Cholesky from 1000 dofs up; superlu_dist is never used, see docs/stack-facts.md §2) and
solves `A x = b` for one or many right-hand sides (`MatMatSolve` on a dense block).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

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
