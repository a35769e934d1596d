"""Parallel nonlinear Gauss–Seidel by graph colouring (MPI through mpi4py), the building block of a distributed
contact solver (docs/scaling.md).

Two contacts α, β are coupled when W_αβ ≠ 0 (they share a body). A greedy colouring of that graph gives colours
whose contacts are pairwise uncoupled, so the local solves of one colour are independent: a sweep that visits the
colours in turn, each colour's contacts split among the ranks and solved at once, then the new impulses of that
colour exchanged (Allgatherv), is exactly the serial Gauss–Seidel sweep in colour order — same iterates, bitwise,
for any number of ranks (`colour_order` gives that serial order). Here W, q and r are replicated on every rank
(the distributed version keeps only the rows of the rank's bodies; see docs/scaling.md).

Run: `mpirun -n 2 python -m fem_blocks.solver.parallel PROBLEM.npz OUT.npz` (PROBLEM: indptr, indices, blocks,
diag_pos, q, mu; OUT: r, sweeps, residual, converged).
"""
from __future__ import annotations

import sys

import numpy as np
from numba import njit

from ..errors import InputError
from ..linalg import BlockCSR, matvec_bcsr
from . import nlgs
from .problem import SolverResult


@njit(cache=True)
def greedy_pass(n_own, gid, indptr, indices, colour):
    """One pass of the greedy colouring over the vertices 0..n_own-1 (their global numbers gid increasing; a vertex's
    neighbours indices[indptr[i]:indptr[i + 1]] in local numbers, gid of every local vertex, colour -1 where
    unknown): each uncoloured vertex whose lower neighbours (gid smaller) are all coloured takes the smallest colour
    none of them has, c(v) = min {k ≥ 0 : k ≠ c(w), w < v neighbour}. With every vertex local and gid = 0..n-1 one
    pass is the sequential greedy colouring (`pair_colouring`); distributed/greedy.py repeats it across ranks.
    Returns the number of vertices 0..n_own-1 left uncoloured."""
    left = 0
    maxdeg = 0
    for i in range(n_own):
        maxdeg = max(maxdeg, indptr[i + 1] - indptr[i])
    used = np.full(maxdeg + 1, -1, dtype=np.int64)  # used[c] == i: colour c taken by a lower neighbour of i
    for i in range(n_own):
        if colour[i] >= 0:
            continue
        ready = True
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            if gid[j] < gid[i] and colour[j] < 0:
                ready = False
                break
        if not ready:
            left += 1
            continue
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            if gid[j] < gid[i] and colour[j] <= maxdeg:
                used[colour[j]] = i
        c = 0
        while used[c] == i:
            c += 1
        colour[i] = c
    return left


def pair_colouring(n: int, a, b) -> np.ndarray:
    """Colour per vertex 0..n-1 of the graph whose edges are the pairs (a[k], b[k]) (either direction; self-pairs
    ignored): greedy, vertices in increasing number, each taking the smallest colour none of its coloured
    neighbours has."""
    a = np.asarray(a, dtype=np.int64)
    b = np.asarray(b, dtype=np.int64)
    e = np.unique(np.concatenate([a * n + b, b * n + a]))
    indptr = np.concatenate([[0], np.cumsum(np.bincount(e // n, minlength=n))]).astype(np.int64)
    colour = -np.ones(n, dtype=np.int64)
    greedy_pass(n, np.arange(n, dtype=np.int64), indptr, (e % n).astype(np.int64), colour)
    return colour


def colour_contacts(W: BlockCSR) -> np.ndarray:
    """Colour per contact such that coupled contacts (a stored block W_αβ or W_βα) differ (greedy, in contact
    order: `pair_colouring` of W's pattern)."""
    return pair_colouring(W.n, np.repeat(np.arange(W.n, dtype=np.int64), np.diff(W.indptr)), W.indices)


def colour_order(colour: np.ndarray):
    """(order, ptr): contacts sorted by colour (stable), colour c = order[ptr[c]:ptr[c + 1]]."""
    order = np.argsort(colour, kind="stable").astype(np.int64)
    ptr = np.zeros(int(colour.max()) + 2 if colour.size else 1, dtype=np.int64)
    np.add.at(ptr, colour + 1, 1)
    return order, np.cumsum(ptr)


def solve_parallel(W: BlockCSR, q, mu, comm=None, r0=None, tol: float = 1e-8, max_sweeps: int = 10000,
                   check_every: int = 10) -> SolverResult:
    """Colour-parallel NLGS (2D or 3D blocks) with the residual criterion; every rank returns the same result.
    comm: an mpi4py communicator (None: serial, the same iterates)."""
    q, mu = nlgs._check(W, q, mu, tol, max_sweeps, 1.0, "given", check_every)
    n, d = W.n, W.dim
    r = np.zeros(d * n) if r0 is None else np.array(r0, dtype=np.float64).ravel()
    if r.size != d * n:
        raise InputError(f"r0: expected {d * n} entries, got {r.size}")
    size, rank = (1, 0) if comm is None else (comm.Get_size(), comm.Get_rank())
    order, ptr = colour_order(colour_contacts(W))
    qnorm = float(np.linalg.norm(q)) or 1.0
    u = np.empty_like(q)
    # per colour: the rank's share (contiguous blocks of the colour's contacts) and the gather layout
    parts = []
    for c in range(len(ptr) - 1):
        idx = order[ptr[c]:ptr[c + 1]]
        bounds = np.linspace(0, idx.size, size + 1).astype(np.int64)
        parts.append((idx, bounds, idx[bounds[rank]:bounds[rank + 1]]))
    sweeps, res, converged = 0, np.inf, False
    while sweeps < max_sweeps:
        for idx, bounds, mine in parts:
            nlgs.sweep(W.indptr, W.indices, W.blocks, W.diag_pos, q, mu, r, mine)
            if size > 1:
                send = np.ascontiguousarray(r.reshape(-1, d)[mine]).ravel()
                recv = np.empty(idx.size * d)
                counts = np.diff(bounds) * d
                comm.Allgatherv(send, [recv, counts, np.concatenate([[0], np.cumsum(counts)[:-1]]), _mpi_double()])
                r.reshape(-1, d)[idx] = recv.reshape(-1, d)
        sweeps += 1
        if sweeps % check_every == 0 or sweeps == max_sweeps:
            matvec_bcsr(W.indptr, W.indices, W.blocks, r, u)
            u += q
            res = float(nlgs.natural_map(r, u, mu, d)) / qnorm
            if res <= tol:
                converged = True
                break
    matvec_bcsr(W.indptr, W.indices, W.blocks, r, u)
    u += q
    res = float(nlgs.natural_map(r, u, mu, d)) / qnorm
    msg = (f"{'converged' if converged else 'not converged'} in {sweeps} colour-parallel sweeps on {size} ranks "
           f"({len(parts)} colours), residual {res:.3g}")
    return SolverResult(r, u, sweeps, converged, 0.0, res, res * qnorm, msg)


def _mpi_double():
    from mpi4py import MPI
    return MPI.DOUBLE


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print("usage: mpirun -n N python -m fem_blocks.solver.parallel PROBLEM.npz OUT.npz", file=sys.stderr)
        return 2
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    with np.load(argv[0]) as z:
        W = BlockCSR(z["indptr"], z["indices"], np.ascontiguousarray(z["blocks"]), z["diag_pos"])
        q, mu = z["q"], z["mu"]
        tol = float(z["tol"]) if "tol" in z.files else 1e-8
    res = solve_parallel(W, q, mu, comm=comm, tol=tol, max_sweeps=100000)
    if comm.Get_rank() == 0:
        np.savez(argv[1], r=res.r, sweeps=res.sweeps, residual=res.residual, converged=res.converged,
                 ranks=comm.Get_size())
        print(res.message)
    return 0


if __name__ == "__main__":
    sys.exit(main())
