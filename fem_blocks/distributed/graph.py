"""The body graph and its partition across MPI ranks (PETSc MatPartitioning), for the time stepper and
distributed/partition.py.

body graph: vertices the bodies, an edge between two bodies with a contact between them or within reach (`pairs`),
weight = the number of contacts between them (at least 1); partition: PETSc MatPartitioning (PT-Scotch by default)
of that graph into comm.size parts, the owner rank of every body on every rank. With vertex weights w_b (the time
stepper: w_b = 1 + the number of contacts whose candidate body is b, `contact_weights`) the parts balance
Σ_{b ∈ part} w_b — the contacts each rank owns and sweeps — rather than the number of bodies, within PT-Scotch's
imbalance tolerance (1 % by default).

petsc4py 3.18 has no MatPartitioningSetVertexWeights: `_set_vertex_weights` calls it in the PETSc library the
process has loaded (ctypes), with an array from PetscMalloc, which the MatPartitioning then owns and frees.
"""
from __future__ import annotations

import ctypes
import functools
import warnings

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


def contact_weights(nb: int, cand: np.ndarray) -> np.ndarray:
    """Vertex weights of the bodies for the time stepper's partition: w_b = 1 + #{contacts c : cand_c = b} (a rank
    owns the contacts of its candidate bodies and sweeps their rows; the 1 keeps a body without contacts, whose
    free velocity a rank still solves, from weighing nothing)."""
    return 1 + np.bincount(np.asarray(cand, dtype=np.int64), minlength=nb)


@functools.lru_cache(maxsize=None)
def _petsc_library():
    """The loaded shared object that exports MatPartitioningSetVertexWeights (libpetsc, or petsc4py's own module
    when PETSc is linked statically), found in /proc/self/maps, with the return types of the two functions called
    set; None if there is none. Looked up once per process (a run partitions again at re-detections)."""
    from petsc4py import PETSc
    paths = []
    try:
        with open("/proc/self/maps") as f:
            paths = [line.split()[-1] for line in f if "petsc" in line.lower() and ".so" in line]
    except OSError:
        pass
    paths = sorted(set(paths), key=lambda q: ("libpetsc" not in q, q)) + [PETSc.__file__]
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
            lib.MatPartitioningSetVertexWeights.restype = ctypes.c_int  # (the symbols must be there)
            lib.PetscMallocA.restype = ctypes.c_int
            lib.PetscFreeA.restype = ctypes.c_int
            return lib
        except (OSError, AttributeError):
            continue
    return None


def _set_vertex_weights(part, w_local: np.ndarray, comm) -> bool:
    """COLLECTIVE: MatPartitioningSetVertexWeights(part, w) with w a PetscMalloc copy of this rank's rows' weights
    (PETSc's PetscInt); the MatPartitioning frees it (this function does if the call fails). False (nothing set, on
    every rank: PT-Scotch needs the weights of every rank or of none) if a rank's loaded libraries do not export the
    function."""
    from mpi4py import MPI
    from petsc4py import PETSc
    lib = _petsc_library()
    if not comm.allreduce(int(lib is not None), op=MPI.MIN):
        return False
    w = np.ascontiguousarray(w_local, dtype=PETSc.IntType)
    ptr = ctypes.c_void_p()
    err = lib.PetscMallocA(ctypes.c_int(1), ctypes.c_int(0), ctypes.c_int(0), b"_set_vertex_weights", b"graph.py",
                           ctypes.c_size_t(max(w.nbytes, w.itemsize)), ctypes.byref(ptr))
    if err or not ptr.value:
        raise MemoryError(f"PetscMallocA of {w.nbytes} bytes failed (PETSc error {err})")
    ctypes.memmove(ptr, w.ctypes.data, w.nbytes)
    err = lib.MatPartitioningSetVertexWeights(ctypes.c_void_p(part.handle), ptr)
    if err:  # (not taken: the buffer is still ours)
        lib.PetscFreeA(ctypes.c_int(1), ctypes.c_int(0), b"_set_vertex_weights", b"graph.py", ctypes.byref(ptr))
        raise RuntimeError(f"MatPartitioningSetVertexWeights failed (PETSc error {err})")
    return True


def row_block(nb: int, size: int, rank: int) -> tuple[int, int]:
    """(start, count): the contiguous block of vertices a rank holds the rows of (PETSc's default layout)."""
    return rank * (nb // size) + min(rank, nb % size), nb // size + (1 if rank < nb % size else 0)


def contact_graph_rows(nb: int, cand, ant, comm):
    """COLLECTIVE: this rank's rows (start, indptr, indices, weights, vertex weights) of the time stepper's body graph
    — `body_graph(nb, [], cand, ant)` and `contact_weights(nb, cand)` of every contact — from the contacts (cand,
    ant) this rank gives, each contact given by one rank (its owner): no rank needs the whole contact set. Each
    contact's two directed edges go to the ranks holding their rows (sweep.exchange, `row_block`), where the edges
    are counted (the weight of an edge = the contacts between its two bodies, as body_graph's); the vertex weights
    1 + #{contacts with candidate b} are the ranks' counts summed (one Reduce_scatter)."""
    from mpi4py import MPI
    from .sweep import exchange
    size, rank = comm.Get_size(), comm.Get_rank()
    cand, ant = np.asarray(cand, dtype=np.int64), np.asarray(ant, dtype=np.int64)
    two = cand != ant
    rows = np.concatenate([cand[two], ant[two]])
    cols = np.concatenate([ant[two], cand[two]])
    starts = np.array([row_block(nb, size, p)[0] for p in range(size)], dtype=np.int64)
    dest = np.searchsorted(starts, rows, side="right") - 1
    o = np.argsort(dest, kind="stable")
    recv, _ = exchange(comm, np.column_stack([rows[o], cols[o]]), np.bincount(dest, minlength=size))
    start, n_loc = row_block(nb, size, rank)
    uk, w = np.unique(recv[:, 0] * nb + recv[:, 1], return_counts=True)  # (sorted by row, then column)
    r, c = uk // nb - start, uk % nb
    indptr = np.zeros(n_loc + 1, dtype=np.int64)
    np.add.at(indptr, r + 1, 1)
    vw = np.empty(n_loc, dtype=np.int64)
    comm.Reduce_scatter(np.bincount(cand, minlength=nb).astype(np.int64), vw,
                        recvcounts=[row_block(nb, size, p)[1] for p in range(size)], op=MPI.SUM)
    return start, np.cumsum(indptr), c, w.astype(np.int64), 1 + vw


def partition_contact_graph(nb: int, cand, ant, comm, method: str = "ptscotch") -> np.ndarray:
    """COLLECTIVE: owner (nb,) int64 on every rank, the partition of the time stepper's body graph (edges weighted by
    their contacts, bodies by 1 + their contacts as candidate) from the contacts (cand, ant) this rank gives, each
    contact given by one rank (`contact_graph_rows`); the same graph as `body_graph` and `contact_weights` of the
    whole set, so the same partition as `partition_graph` of it."""
    if comm.Get_size() == 1:
        return np.zeros(nb, dtype=np.int64)
    start, ia, ja, w, vw = contact_graph_rows(nb, cand, ant, comm)
    return _partition_rows(nb, start, ia, ja, w, vw, comm, method)


def partition_graph(indptr, indices, weights, comm, method: str = "ptscotch", vertex_weights=None) -> np.ndarray:
    """owner (nb,) int64 on every rank: PETSc MatPartitioning of type `method` into comm.size parts of the graph
    (CSR, symmetric, no diagonal, positive integer weights used as edge weights; `vertex_weights` (nb,) positive
    integers, the same on every rank, or None: every vertex weighs 1). Each rank inserts the rows of a contiguous
    block of vertices (`row_block`, PETSc's default layout) into an MPIAIJ adjacency; the part of each row is
    gathered with Allgatherv."""
    nb = len(indptr) - 1
    if comm.size == 1:
        return np.zeros(nb, dtype=np.int64)
    start, n_loc = row_block(nb, comm.size, comm.rank)
    s, e = int(indptr[start]), int(indptr[start + n_loc])
    vw = None if vertex_weights is None else np.asarray(vertex_weights)[start:start + n_loc]
    return _partition_rows(nb, start, indptr[start:start + n_loc + 1] - s, indices[s:e], weights[s:e], vw, comm,
                           method)


def _partition_rows(nb, start, ia, ja, weights, vertex_weights, comm, method) -> np.ndarray:
    """COLLECTIVE: the partition (owner (nb,) on every rank) of the graph whose rows start .. start + len(ia) - 2
    this rank holds (CSR ia, ja, weights; vertex weights of those rows, or None)."""
    from petsc4py import PETSc
    pcomm = PETSc.Comm(comm)
    n_loc = len(ia) - 1
    A = PETSc.Mat().createAIJ(size=((n_loc, nb), (n_loc, nb)),
                              csr=(np.asarray(ia).astype(PETSc.IntType), np.asarray(ja).astype(PETSc.IntType),
                                   np.asarray(weights).astype(PETSc.ScalarType)), comm=pcomm)
    A.assemble()
    part = PETSc.MatPartitioning().create(comm=pcomm)
    prefix = "fb_partition_"
    part.setOptionsPrefix(prefix)
    opts = PETSc.Options()
    opts[prefix + "mat_partitioning_use_edge_weights"] = "true"
    part.setAdjacency(A)
    part.setType(method)
    if vertex_weights is not None and not _set_vertex_weights(part, vertex_weights, comm):
        if comm.rank == 0:
            warnings.warn("the bodies are partitioned without vertex weights (no loaded PETSc library exports "
                          "MatPartitioningSetVertexWeights): the ranks get equal numbers of bodies, not of contacts",
                          RuntimeWarning, stacklevel=2)
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
