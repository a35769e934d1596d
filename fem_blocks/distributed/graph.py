"""The body graph and its partition across MPI ranks (PETSc MatPartitioning), for the time stepper and
distributed/partition.py.

body graph: vertices the bodies, an edge between two bodies with a contact between them or within reach (`pairs`),
weight = the number of contacts between them (at least 1); partition: PETSc MatPartitioning (PT-Scotch by default)
of that graph into comm.size parts, the owner rank of every body on every rank.
"""
from __future__ import annotations

import numpy as np


def body_graph(nb: int, pairs: np.ndarray, cand: np.ndarray, ant: np.ndarray):
    """Symmetric CSR (indptr, indices, weights) of the body graph: edges = near pairs ∪ contact pairs, weight =
    max(1, number of contacts between the two bodies); no diagonal."""
    cp = np.column_stack([cand, ant]).astype(np.int64)
    cp = cp[cp[:, 0] != cp[:, 1]]
    allp = np.concatenate([np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1), np.sort(cp, axis=1)])
    key = allp[:, 0] * nb + allp[:, 1]
    uk, inv = np.unique(key, return_inverse=True)
    w = np.zeros(len(uk), dtype=np.int64)
    np.add.at(w, inv[len(pairs):], 1)
    w = np.maximum(w, 1)
    i, j = uk // nb, uk % nb
    rows, cols, vals = np.concatenate([i, j]), np.concatenate([j, i]), np.concatenate([w, w])
    o = np.lexsort((cols, rows))
    rows, cols, vals = rows[o], cols[o], vals[o]
    indptr = np.zeros(nb + 1, dtype=np.int64)
    np.add.at(indptr, rows + 1, 1)
    return np.cumsum(indptr), cols, vals


def partition_graph(indptr, indices, weights, comm, method: str = "ptscotch") -> np.ndarray:
    """owner (nb,) int64 on every rank: PETSc MatPartitioning of type `method` into comm.size parts of the graph
    (CSR, symmetric, no diagonal, positive integer weights used as edge weights). Each rank inserts the rows of a
    contiguous block of vertices (PETSc's default layout) into an MPIAIJ adjacency; the part of each row is
    gathered with Allgatherv."""
    from petsc4py import PETSc
    nb = len(indptr) - 1
    size = comm.size
    if size == 1:
        return np.zeros(nb, dtype=np.int64)
    pcomm = PETSc.Comm(comm)
    n_loc = nb // size + (1 if comm.rank < nb % size else 0)
    start = comm.rank * (nb // size) + min(comm.rank, nb % size)
    s, e = int(indptr[start]), int(indptr[start + n_loc])
    ia = (indptr[start:start + n_loc + 1] - s).astype(PETSc.IntType)
    ja = indices[s:e].astype(PETSc.IntType)
    A = PETSc.Mat().createAIJ(size=((n_loc, nb), (n_loc, nb)), csr=(ia, ja, weights[s:e].astype(PETSc.ScalarType)),
                              comm=pcomm)
    A.assemble()
    part = PETSc.MatPartitioning().create(comm=pcomm)
    prefix = "fb_partition_"
    part.setOptionsPrefix(prefix)
    opts = PETSc.Options()
    opts[prefix + "mat_partitioning_use_edge_weights"] = "true"
    part.setAdjacency(A)
    part.setType(method)
    part.setFromOptions()
    iset = PETSc.IS()
    part.apply(iset)
    local = np.asarray(iset.getIndices(), dtype=np.int64)
    iset.destroy()
    part.destroy()
    A.destroy()
    del opts[prefix + "mat_partitioning_use_edge_weights"]
    counts = np.array(comm.allgather(len(local)), dtype=np.int64)
    owner = np.empty(nb, dtype=np.int64)
    from mpi4py import MPI
    comm.Allgatherv(local, [owner, counts, np.concatenate([[0], np.cumsum(counts)[:-1]]), MPI.INT64_T])
    return owner
