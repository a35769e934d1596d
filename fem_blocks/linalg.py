"""Linear algebra: the block-CSR matrix of the contact solvers, and sparse direct factorizations with PETSc.

`BlockCSR` stores a matrix of d x d blocks (d = 2 or 3, one block row per contact: the Delassus operator W of
u = W r + q) as plain arrays (indptr, indices, blocks (nnzb, d, d), diag_pos) that the numba kernels take without
scipy objects; `to_block_csr` builds it from a dense or scipy matrix, `matvec_bcsr` computes y = W x.

Sparse direct factorizations with PETSc (petsc4py), shared by all instances of a block type:

`Factor(A)` factors a symmetric positive definite scipy CSR matrix once (PETSc's own LU for small
systems, CHOLMOD Cholesky from 1000 dofs up; superlu_dist is never used, see docs/stack-facts.md §2) and
solves `A x = b` for one or many right-hand sides (`MatMatSolve` on a dense block).

`BlockLU` (Newton's J = D + E W, whose block pattern is W's and whose values change every iteration): the symbolic
analysis once per pattern — ordering (natural, reverse Cuthill–McKee, nested dissection or minimum degree: the fewest
block multiply-adds Σ_k |U_k,>k|²), elimination tree, filled pattern of L + U — then per matrix the numeric block LU
P A Pᵀ = L U without pivoting between blocks (L unit block-lower, U_ii inverted exactly) and x = Pᵀ U⁻¹ L⁻¹ P b,
accepted when the backward error ‖A x - b‖∞ <= 1e-10 (‖A‖∞‖x‖∞ + ‖b‖∞) after at most one step of iterative refinement;
otherwise the caller uses the pivoting `lu_solve` (SuperLU / MUMPS).
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
    """y = W x (block-CSR, d x d blocks, d = blocks.shape[1]; x and y distinct arrays). Each entry is summed as
    y_ai = (((0 + s_1) + s_2) + ...) over the row's blocks k in order, s_k = (0 + W_k,i0 x_0) + W_k,i1 x_1 (+ W_k,i2
    x_2): d = 2 and 3 keep the row's sums in registers (one store per entry, not one per block: about 3 times faster
    on the 10⁴-brick wall's W), the same operations in the same order as the general loop, so the same bits."""
    n = indptr.shape[0] - 1
    dd = blocks.shape[1]
    if dd == 2:
        for a in range(n):
            y0 = 0.0
            y1 = 0.0
            for k in range(indptr[a], indptr[a + 1]):
                b = 2 * indices[k]
                x0 = x[b]
                x1 = x[b + 1]
                s0 = 0.0
                s0 += blocks[k, 0, 0] * x0
                s0 += blocks[k, 0, 1] * x1
                s1 = 0.0
                s1 += blocks[k, 1, 0] * x0
                s1 += blocks[k, 1, 1] * x1
                y0 += s0
                y1 += s1
            y[2 * a] = y0
            y[2 * a + 1] = y1
        return
    if dd == 3:
        for a in range(n):
            y0 = 0.0
            y1 = 0.0
            y2 = 0.0
            for k in range(indptr[a], indptr[a + 1]):
                b = 3 * indices[k]
                x0 = x[b]
                x1 = x[b + 1]
                x2 = x[b + 2]
                s0 = 0.0
                s0 += blocks[k, 0, 0] * x0
                s0 += blocks[k, 0, 1] * x1
                s0 += blocks[k, 0, 2] * x2
                s1 = 0.0
                s1 += blocks[k, 1, 0] * x0
                s1 += blocks[k, 1, 1] * x1
                s1 += blocks[k, 1, 2] * x2
                s2 = 0.0
                s2 += blocks[k, 2, 0] * x0
                s2 += blocks[k, 2, 1] * x1
                s2 += blocks[k, 2, 2] * x2
                y0 += s0
                y1 += s1
                y2 += s2
            y[3 * a] = y0
            y[3 * a + 1] = y1
            y[3 * a + 2] = y2
        return
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


@njit(cache=True)
def permute_rows(indptr, indices, blocks, perm, relabel):
    """In place: the rows of a block-CSR put in the order `perm` (new row i = old row perm[i], each row's blocks in
    their order) and every column index c replaced by relabel[c]; returns the new indptr. The blocks move along the
    cycles of the permutation (one block held aside at a time), so no second copy of `blocks` is made: extra memory
    is one int64 per block (its destination, set to -1 once it is in place). Each block is moved entry by entry
    on a flat (m, d·d) view (1.7 times faster than moving sub-arrays, the same result)."""
    n = perm.shape[0]
    m = indices.shape[0]
    new_ptr = np.empty(n + 1, dtype=np.int64)
    new_ptr[0] = 0
    for i in range(n):
        a = perm[i]
        new_ptr[i + 1] = new_ptr[i] + indptr[a + 1] - indptr[a]
    dest = np.empty(m, dtype=np.int64)
    for i in range(n):
        a = perm[i]
        off = new_ptr[i] - indptr[a]
        for k in range(indptr[a], indptr[a + 1]):
            dest[k] = k + off
    for k in range(m):
        indices[k] = relabel[indices[k]]
    B = blocks.reshape(m, blocks.shape[1] * blocks.shape[2])
    w = B.shape[1]
    held = np.empty(w)
    swap = np.empty(w)
    for s in range(m):
        if dest[s] < 0:
            continue
        if dest[s] == s:
            dest[s] = -1
            continue
        for j in range(w):
            held[j] = B[s, j]
        held_c = indices[s]
        cur = s
        while True:
            t = dest[cur]
            for j in range(w):
                swap[j] = B[t, j]
                B[t, j] = held[j]
            swap_c = indices[t]
            indices[t] = held_c
            dest[cur] = -1
            if t == s:
                break
            for j in range(w):
                held[j] = swap[j]
            held_c = swap_c
            cur = t
    return new_ptr


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

    @property
    def columnwise(self) -> bool:
        """`solve` of an (n, k) right side gives each column the same double whatever the other columns: PETSc's LU
        (checked, tests/test_linalg.py); CHOLMOD's and MUMPS' multi-column solves round a column otherwise with
        other columns beside it."""
        return self.method == "petsc-lu"

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
        # every k through MatMatSolve, one column at a time inside: each column's x the same double whatever the
        # other columns (a body's free velocity does not depend on the bodies solved beside it, dynamics.py); the
        # vector solve above rounds otherwise
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


# ---------------------------------------------------------------------------------------------------------------
# Block LU with the symbolic analysis done once (Newton's J = D + E W: the block pattern of W, values change)
# ---------------------------------------------------------------------------------------------------------------

@njit(cache=True)
def _etree(indptr, indices, iperm):
    """Elimination tree of the symmetric block pattern (indptr, indices) in the order iperm (old -> new): parent[j]
    = min{i > j : L_ij ≠ 0} (Liu's algorithm with path compression; -1 at a root)."""
    n = indptr.shape[0] - 1
    perm = np.empty(n, dtype=np.int64)
    for a in range(n):
        perm[iperm[a]] = a
    parent = np.full(n, -1, dtype=np.int64)
    ancestor = np.full(n, -1, dtype=np.int64)
    for i in range(n):
        a = perm[i]
        for p in range(indptr[a], indptr[a + 1]):
            k = iperm[indices[p]]
            while k != -1 and k < i:
                nxt = ancestor[k]
                ancestor[k] = i
                if nxt == -1:
                    parent[k] = i
                k = nxt
    return parent, perm


@njit(cache=True)
def _symbolic(indptr, indices, iperm):
    """Filled block pattern of L + U (no pivoting, symmetric pattern) in the order iperm: row i of L holds the nodes
    on the elimination-tree paths from each k < i with A_ik ≠ 0 up to i (row subtrees), U = pattern of Lᵀ.
    Returns (fptr, fidx, fdiag, flops): block CSR of L + U (sorted rows, fdiag = position of the diagonal) and
    Σ_k |U_k,>k|² (2×2 or 3×3 block multiply-adds of the numeric factorisation)."""
    n = indptr.shape[0] - 1
    parent, perm = _etree(indptr, indices, iperm)
    mark = np.full(n, -1, dtype=np.int64)
    lcount = np.zeros(n, dtype=np.int64)
    ucount = np.zeros(n, dtype=np.int64)
    for i in range(n):  # pass 1: counts
        mark[i] = i
        a = perm[i]
        for p in range(indptr[a], indptr[a + 1]):
            k = iperm[indices[p]]
            while k < i and mark[k] != i:
                mark[k] = i
                lcount[i] += 1
                ucount[k] += 1
                k = parent[k]
    fptr = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        fptr[i + 1] = fptr[i] + lcount[i] + 1 + ucount[i]
    fidx = np.empty(fptr[n], dtype=np.int64)
    fdiag = np.empty(n, dtype=np.int64)
    lpos = fptr[:-1].copy()
    upos = np.empty(n, dtype=np.int64)
    for i in range(n):
        fdiag[i] = fptr[i] + lcount[i]
        fidx[fdiag[i]] = i
        upos[i] = fdiag[i] + 1
    mark[:] = -1
    for i in range(n):  # pass 2: L row i (unsorted) and, transposed, U rows (ascending i: sorted)
        mark[i] = i
        a = perm[i]
        for p in range(indptr[a], indptr[a + 1]):
            k = iperm[indices[p]]
            while k < i and mark[k] != i:
                mark[k] = i
                fidx[lpos[i]] = k
                lpos[i] += 1
                fidx[upos[k]] = i
                upos[k] += 1
                k = parent[k]
        fidx[fptr[i]:fdiag[i]] = np.sort(fidx[fptr[i]:fdiag[i]])
    flops = 0
    for k in range(n):
        flops += ucount[k] * ucount[k]
    return fptr, fidx, fdiag, flops


@njit(cache=True)
def _scatter_map(indptr, indices, iperm, fptr, fidx):
    """Position in the filled pattern of every block of the original pattern (row a, column indices[p])."""
    n = indptr.shape[0] - 1
    src = np.empty(indices.shape[0], dtype=np.int64)
    for a in range(n):
        i = iperm[a]
        row = fidx[fptr[i]:fptr[i + 1]]
        for p in range(indptr[a], indptr[a + 1]):
            src[p] = fptr[i] + np.searchsorted(row, iperm[indices[p]])
    return src


@njit(cache=True)
def _inv_block(A, out):
    """out = A⁻¹ (2×2 or 3×3, cofactors); returns |det A| / (max|A_ij|^d), 0 for a singular or non-finite block."""
    d = A.shape[0]
    s = 0.0
    for i in range(d):
        for j in range(d):
            s = max(s, abs(A[i, j]))
    if d == 2:
        det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
        if det == 0.0 or not np.isfinite(det):
            return 0.0
        out[0, 0], out[0, 1] = A[1, 1] / det, -A[0, 1] / det
        out[1, 0], out[1, 1] = -A[1, 0] / det, A[0, 0] / det
        return abs(det) / (s * s)
    c00 = A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]
    c01 = A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2]
    c02 = A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]
    det = A[0, 0] * c00 + A[0, 1] * c01 + A[0, 2] * c02
    if det == 0.0 or not np.isfinite(det):
        return 0.0
    out[0, 0] = c00 / det
    out[1, 0] = c01 / det
    out[2, 0] = c02 / det
    out[0, 1] = (A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2]) / det
    out[1, 1] = (A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]) / det
    out[2, 1] = (A[0, 1] * A[2, 0] - A[0, 0] * A[2, 1]) / det
    out[0, 2] = (A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]) / det
    out[1, 2] = (A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]) / det
    out[2, 2] = (A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]) / det
    return abs(det) / (s * s * s)


@njit(cache=True)
def _block_lu_numeric(fptr, fidx, fdiag, src, blocks, vals, dinv, work):
    """Numeric block LU without pivoting between blocks (up-looking, row by row): A = L U with L unit block-lower
    and U block-upper on the filled pattern (fptr, fidx), A's blocks scattered by src. For row i (ascending):
    w = A_i,:;  for k < i in the pattern (ascending): L_ik = w_k U_kk⁻¹,  w_j -= L_ik U_kj (j > k);  then
    L_i,<i = w_<i, U_i,>=i = w_>=i. Zero multipliers are skipped (open contacts: E = 0 rows of J). dinv[i] = U_ii⁻¹.
    Returns the smallest scaled |det U_ii| (0: a singular or non-finite pivot block)."""
    n = fptr.shape[0] - 1
    d = blocks.shape[1]
    vals[:] = 0.0
    for p in range(src.shape[0]):
        vals[src[p]] = blocks[p]
    m = np.empty((d, d))
    piv = np.inf
    for i in range(n):
        for p in range(fptr[i], fptr[i + 1]):
            j = fidx[p]
            for r in range(d):
                for c in range(d):
                    work[j, r, c] = vals[p, r, c]
        if d == 2:  # the 2D case unrolled (2×2 blocks in registers)
            for p in range(fptr[i], fdiag[i]):
                k = fidx[p]
                w00, w01, w10, w11 = work[k, 0, 0], work[k, 0, 1], work[k, 1, 0], work[k, 1, 1]
                m00 = w00 * dinv[k, 0, 0] + w01 * dinv[k, 1, 0]
                m01 = w00 * dinv[k, 0, 1] + w01 * dinv[k, 1, 1]
                m10 = w10 * dinv[k, 0, 0] + w11 * dinv[k, 1, 0]
                m11 = w10 * dinv[k, 0, 1] + w11 * dinv[k, 1, 1]
                work[k, 0, 0], work[k, 0, 1], work[k, 1, 0], work[k, 1, 1] = m00, m01, m10, m11
                if m00 == 0.0 and m01 == 0.0 and m10 == 0.0 and m11 == 0.0:
                    continue
                for q in range(fdiag[k] + 1, fptr[k + 1]):
                    j = fidx[q]
                    u00, u01, u10, u11 = vals[q, 0, 0], vals[q, 0, 1], vals[q, 1, 0], vals[q, 1, 1]
                    work[j, 0, 0] -= m00 * u00 + m01 * u10
                    work[j, 0, 1] -= m00 * u01 + m01 * u11
                    work[j, 1, 0] -= m10 * u00 + m11 * u10
                    work[j, 1, 1] -= m10 * u01 + m11 * u11
            for p in range(fptr[i], fptr[i + 1]):
                j = fidx[p]
                vals[p, 0, 0], vals[p, 0, 1], vals[p, 1, 0], vals[p, 1, 1] = \
                    work[j, 0, 0], work[j, 0, 1], work[j, 1, 0], work[j, 1, 1]
            g = _inv_block(vals[fdiag[i]], dinv[i])
            if g < piv:
                piv = g
            if g == 0.0:
                return 0.0
            continue
        for p in range(fptr[i], fdiag[i]):
            k = fidx[p]
            nz = False
            for r in range(d):
                for c in range(d):
                    s = 0.0
                    for t in range(d):
                        s += work[k, r, t] * dinv[k, t, c]
                    m[r, c] = s
                    if s != 0.0:
                        nz = True
            work[k] = m
            if not nz:
                continue
            for q in range(fdiag[k] + 1, fptr[k + 1]):
                j = fidx[q]
                for r in range(d):
                    for c in range(d):
                        s = 0.0
                        for t in range(d):
                            s += m[r, t] * vals[q, t, c]
                        work[j, r, c] -= s
        for p in range(fptr[i], fptr[i + 1]):
            vals[p] = work[fidx[p]]
        g = _inv_block(vals[fdiag[i]], dinv[i])
        if g < piv:
            piv = g
        if g == 0.0:
            return 0.0
    return piv


@njit(cache=True)
def _block_lu_solve(fptr, fidx, fdiag, vals, dinv, perm, b, x):
    """x = A⁻¹ b from the block LU (permuted: row/column i of L U is block perm[i] of A): L y = P b, U z = y."""
    n = fptr.shape[0] - 1
    d = vals.shape[1]
    y = np.empty((n, d))
    if d == 2:  # unrolled
        for i in range(n):
            a = perm[i]
            y0, y1 = b[2 * a], b[2 * a + 1]
            for p in range(fptr[i], fdiag[i]):
                k = fidx[p]
                y0 -= vals[p, 0, 0] * y[k, 0] + vals[p, 0, 1] * y[k, 1]
                y1 -= vals[p, 1, 0] * y[k, 0] + vals[p, 1, 1] * y[k, 1]
            y[i, 0], y[i, 1] = y0, y1
        for i in range(n - 1, -1, -1):
            y0, y1 = y[i, 0], y[i, 1]
            for p in range(fdiag[i] + 1, fptr[i + 1]):
                j = fidx[p]
                y0 -= vals[p, 0, 0] * y[j, 0] + vals[p, 0, 1] * y[j, 1]
                y1 -= vals[p, 1, 0] * y[j, 0] + vals[p, 1, 1] * y[j, 1]
            z0 = dinv[i, 0, 0] * y0 + dinv[i, 0, 1] * y1
            z1 = dinv[i, 1, 0] * y0 + dinv[i, 1, 1] * y1
            y[i, 0], y[i, 1] = z0, z1
            a = perm[i]
            x[2 * a], x[2 * a + 1] = z0, z1
        return
    for i in range(n):
        a = perm[i]
        for r in range(d):
            y[i, r] = b[d * a + r]
        for p in range(fptr[i], fdiag[i]):
            k = fidx[p]
            for r in range(d):
                s = 0.0
                for t in range(d):
                    s += vals[p, r, t] * y[k, t]
                y[i, r] -= s
    z = np.empty(d)
    for i in range(n - 1, -1, -1):
        for p in range(fdiag[i] + 1, fptr[i + 1]):
            j = fidx[p]
            for r in range(d):
                s = 0.0
                for t in range(d):
                    s += vals[p, r, t] * y[j, t]
                y[i, r] -= s
        for r in range(d):
            s = 0.0
            for t in range(d):
                s += dinv[i, r, t] * y[i, t]
            z[r] = s
        y[i] = z
        a = perm[i]
        for r in range(d):
            x[d * a + r] = y[i, r]


BLOCK_LU_ORDERINGS = ("natural", "rcm", "nd", "qmd")


def _block_ordering(G: sp.csr_matrix, name: str) -> np.ndarray:
    """iperm (old -> new) of the block graph G: natural, reverse Cuthill–McKee (scipy), nested dissection or
    quotient minimum degree (PETSc's MatGetOrdering: its row IS maps new -> old)."""
    n = G.shape[0]
    if name == "natural":
        return np.arange(n, dtype=np.int64)
    if name == "rcm":
        from scipy.sparse.csgraph import reverse_cuthill_mckee
        perm = reverse_cuthill_mckee(G, symmetric_mode=True)
    elif name in ("nd", "qmd"):
        A = PETSc.Mat().createAIJ(size=(n, n), csr=(G.indptr.astype(PETSc.IntType), G.indices.astype(PETSc.IntType),
                                                    G.data.astype(PETSc.ScalarType)), comm=PETSc.COMM_SELF)
        rows, cols = A.getOrdering(name)
        perm = rows.getIndices().copy()
        for obj in (rows, cols, A):
            obj.destroy()
    else:
        raise ValueError(f"BlockLU ordering {name!r}: expected auto, {', '.join(BLOCK_LU_ORDERINGS)}")
    iperm = np.empty(n, dtype=np.int64)
    iperm[np.asarray(perm, dtype=np.int64)] = np.arange(n)
    return iperm


class BlockLU:
    """Sparse LU of matrices with one fixed block pattern (d x d blocks, symmetric pattern: Newton's J = D + E W has
    the pattern of the Delassus W), the symbolic analysis done once: the block ordering (natural or reverse
    Cuthill–McKee, nested dissection or quotient minimum degree, whichever needs the fewest block multiply-adds),
    the elimination tree and the filled pattern of L + U.
    `factor(blocks)` refreshes the values (blocks in the order of the pattern) and factors without pivoting between
    blocks (each diagonal block inverted exactly); `solve(b)` = A⁻¹ b. No pivoting: the caller checks the backward
    error (`solve_checked`) and falls back to a pivoting LU (lu_solve) when it is not small."""

    def __init__(self, indptr, indices, dim: int, ordering: str = "auto"):
        indptr = np.ascontiguousarray(indptr, dtype=np.int64)
        indices = np.ascontiguousarray(indices, dtype=np.int64)
        n = len(indptr) - 1
        self.n, self.dim, self.indptr, self.indices = n, dim, indptr, indices
        G = sp.csr_matrix((np.ones(len(indices)), indices, indptr), shape=(n, n))
        if (G != G.T).nnz:
            raise ValueError("BlockLU: the block pattern must be symmetric")
        names = BLOCK_LU_ORDERINGS if ordering == "auto" else (ordering,)
        best = None
        for name in names:
            iperm = _block_ordering(G, name)
            fptr, fidx, fdiag, flops = _symbolic(indptr, indices, iperm)
            if best is None or flops < best[-1]:
                best = (name, iperm, fptr, fidx, fdiag, flops)
        self.ordering, iperm, self.fptr, self.fidx, self.fdiag, self.flops = best
        self.perm = np.empty(n, dtype=np.int64)
        self.perm[iperm] = np.arange(n)
        self.src = _scatter_map(indptr, indices, iperm, self.fptr, self.fidx)
        self.vals = np.zeros((len(self.fidx), dim, dim))
        self.dinv = np.zeros((n, dim, dim))
        self._work = np.zeros((n, dim, dim))
        self.pivot = 0.0
        self._blocks = None

    _cache: dict = {}

    @classmethod
    def for_pattern(cls, indptr, indices, dim: int) -> "BlockLU":
        """The BlockLU (ordering "auto") of this block pattern, its symbolic analysis reused while the pattern recurs
        (the contact set of consecutive steps often does not change; the last 4 patterns are kept)."""
        key = (dim, np.asarray(indptr, dtype=np.int64).tobytes(), np.asarray(indices, dtype=np.int64).tobytes())
        lu = cls._cache.pop(key, None)
        if lu is None:
            lu = cls(indptr, indices, dim)
        cls._cache[key] = lu
        while len(cls._cache) > 4:
            del cls._cache[next(iter(cls._cache))]
        return lu

    @property
    def nnz_blocks(self) -> int:
        """Blocks of L + U (fill included)."""
        return len(self.fidx)

    def factor(self, blocks: np.ndarray) -> bool:
        """Numeric factorisation of the matrix with these blocks; False when a pivot block is singular (or not
        finite) or nearly so (scaled |det| < 1e-13)."""
        blocks = np.ascontiguousarray(blocks, dtype=np.float64)
        self._blocks = blocks
        self.pivot = _block_lu_numeric(self.fptr, self.fidx, self.fdiag, self.src, blocks, self.vals, self.dinv,
                                       self._work)
        return self.pivot > 1e-13

    def solve(self, b: np.ndarray) -> np.ndarray:
        x = np.empty(self.n * self.dim)
        _block_lu_solve(self.fptr, self.fidx, self.fdiag, self.vals, self.dinv, self.perm,
                        np.ascontiguousarray(b, dtype=np.float64), x)
        return x

    def solve_checked(self, blocks: np.ndarray, b: np.ndarray, tol: float = 1e-10) -> np.ndarray | None:
        """x = A⁻¹ b with A of these blocks, or None when the factorisation fails or the backward error
        ‖A x - b‖ / (‖A‖_∞ ‖x‖_∞ + ‖b‖_∞) stays above tol after one step of iterative refinement
        (the caller then uses a pivoting LU)."""
        if not self.factor(blocks):
            return None
        b = np.asarray(b, dtype=np.float64)
        x = self.solve(b)
        r = np.empty_like(x)
        anorm = _bcsr_inf_norm(self.indptr, blocks)
        for it in range(2):
            if not np.all(np.isfinite(x)):
                return None
            matvec_bcsr(self.indptr, self.indices, blocks, x, r)
            r -= b
            scale = anorm * float(np.max(np.abs(x), initial=0.0)) + float(np.max(np.abs(b), initial=0.0))
            if float(np.max(np.abs(r), initial=0.0)) <= tol * scale or scale == 0.0:
                return x
            if it == 0:
                x = x - self.solve(r)
        return None


@njit(cache=True)
def _bcsr_inf_norm(indptr, blocks):
    """‖A‖_∞ (largest absolute row sum) of a block-CSR matrix."""
    n = indptr.shape[0] - 1
    d = blocks.shape[1]
    best = 0.0
    for a in range(n):
        for r in range(d):
            s = 0.0
            for p in range(indptr[a], indptr[a + 1]):
                for c in range(d):
                    s += abs(blocks[p, r, c])
            best = max(best, s)
    return best
