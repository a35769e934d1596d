"""Sparse direct factorizations with PETSc (petsc4py), shared by all instances of a block type.

`Factor(A)` factors a symmetric positive definite scipy CSR matrix once (PETSc's own LU for small
systems, CHOLMOD Cholesky from 1000 dofs up; superlu_dist is never used, see STACK-FACTS §2) and
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


class Factor:
    """Factorization of a sparse SPD matrix; `solve(b)` with b of shape (n,) or (n, k)."""

    def __init__(self, A: sp.spmatrix, method: str = "auto"):
        n = A.shape[0]
        if method == "auto":
            method = "petsc-lu" if n < SMALL_SYSTEM else "cholmod"
        self.n, self.method = n, method
        self._A = _to_petsc(A)
        ksp = PETSc.KSP().create(PETSc.COMM_SELF)
        ksp.setOperators(self._A)
        ksp.setType("preonly")
        pc = ksp.getPC()
        if method == "petsc-lu":
            pc.setType("lu")
            pc.setFactorSolverType("petsc")
        elif method == "cholmod":
            pc.setType("cholesky")
            pc.setFactorSolverType("cholmod")
        elif method == "mumps":
            pc.setType("cholesky")
            pc.setFactorSolverType("mumps")
        else:
            raise ValueError(f"factor method {method!r}: expected auto, petsc-lu, cholmod or mumps")
        ksp.setUp()
        self._ksp = ksp
        self._F = pc.getFactorMatrix()
        self._b, self._x = self._A.createVecs()

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
