"""The greedy colouring of a graph whose vertices are spread over MPI ranks, without gathering the graph.

Sequential greedy colouring (solver/parallel.pair_colouring): vertices in increasing number, each takes the
smallest colour that none of its already coloured neighbours has,

    c(v) = min { k ≥ 0 : k ≠ c(w) for every neighbour w < v } .

Here each rank p owns the vertices V_p (the body-pair groups of its contacts) and knows the edges it was given
(the time stepper: the pairs of its own groups with the groups sharing one of their moving bodies,
colour.sweep_plan). Rank p colours v ∈ V_p as soon as every neighbour
w < v has its colour (Jones–Plassmann with the vertex numbers as priorities): then c(v) is the formula above, so
the colours are those of the sequential greedy, on any number of ranks and for any ownership. One round:

1. each rank passes over its uncoloured vertices in increasing number and colours those whose lower neighbours are
   all coloured (solver/parallel.greedy_pass, the pass of the sequential colouring itself; its own chains of
   dependencies are resolved within the pass: a lower own vertex comes first);
2. the colours of the vertices of p that another rank q has as neighbours go to q (an MPI neighbourhood
   all-to-all on the graph of the ranks that share edges);
3. an all-reduce of the vertices left uncoloured ends the rounds at 0.

The globally smallest uncoloured vertex is always ready, so every round colours at least one vertex; the rounds
are about the number of times the longest increasing path of dependencies crosses between ranks (twice the courses
of a wall cut into vertical strips). Before the rounds the edges are made symmetric: an edge (a, b) known only to
the owner of a is sent to the owner of b (an all-to-all of the counts, then one of the pairs), so the graph is the
union of every rank's edges in either direction, as for pair_colouring. Memory per rank: its vertices, their edges
and their neighbours' colours.
"""
from __future__ import annotations

import numpy as np

from ..solver.parallel import greedy_pass
from .sweep import exchange


def greedy_colours(own, a, b, owner_of, comm):
    """The sequential greedy colours of a graph whose vertices are spread over the ranks of `comm` (collective).
    own: the global numbers of this rank's vertices (distinct; any int64 keys, their order the priority); (a, b):
    edges this rank knows, a ∈ own (either direction is an edge; self-pairs ignored); owner_of(x): the rank owning
    each vertex of the array x (called on the b's). Returns (ids, colour, rounds): this rank's vertices and their
    neighbours (global numbers, increasing), their colours (those of pair_colouring on the union of every rank's
    edges) and the number of rounds."""
    from mpi4py import MPI
    own = np.unique(np.asarray(own, dtype=np.int64))
    a = np.asarray(a, dtype=np.int64)
    b = np.asarray(b, dtype=np.int64)
    keep = a != b
    a, b = a[keep], b[keep]
    if a.size:  # distinct pairs, in (a, b) order (a rank's rows give each pair once per coupled block); the vertex
        # numbers may be any keys (the time stepper's: body pairs): numbered densely first, in their order
        ids, ab = np.unique(np.concatenate([a, b]), return_inverse=True)
        e = np.unique(ab[:a.size] * ids.size + ab[a.size:])
        a, b = ids[e // ids.size], ids[e % ids.size]
    if np.any(~np.isin(a, own)):
        raise ValueError("greedy_colours: an edge (a, b) with a not among this rank's vertices")
    p, size = comm.Get_rank(), comm.Get_size()
    # 1. symmetric edges: (b, a) to the owner of b when b is another rank's ...
    far = ~np.isin(b, own)
    ob = np.asarray(owner_of(b[far]), dtype=np.int64)
    by = np.argsort(ob, kind="stable")  # (b, a) pairs grouped by the owner of b, in rank order
    pairs = np.column_stack([b[far][by], a[far][by]]).astype(np.int64)
    extra, _ = exchange(comm, pairs, np.bincount(ob, minlength=size))
    a, b = (np.concatenate([a, b[~far], extra[:, 0]]),  # ... and (b, a) here when b is this rank's
            np.concatenate([b, a[~far], extra[:, 1]]))
    # 2. local numbering: own vertices, then the ghosts (increasing global numbers in each part)
    ghost = np.setdiff1d(b, own)
    gid = np.concatenate([own, ghost])
    gowner = np.asarray(owner_of(ghost), dtype=np.int64)
    la = np.searchsorted(own, a)
    lb = np.where(np.isin(b, own), np.searchsorted(own, b), own.size + np.searchsorted(ghost, b))
    e = np.unique(la * gid.size + lb)
    la, lb = e // max(gid.size, 1), e % max(gid.size, 1)
    indptr = np.concatenate([[0], np.cumsum(np.bincount(la, minlength=own.size))]).astype(np.int64)
    indices = lb.astype(np.int64)
    # 3. neighbour ranks: who owns my ghosts (by symmetry they have my vertices as ghosts); what I send each: my
    # vertices adjacent to a vertex it owns (increasing), what I receive: my ghosts it owns (increasing)
    nbrs = np.unique(gowner).astype(int).tolist()
    own_of_edge_b = np.full(lb.size, -1, dtype=np.int64)
    is_ghost = lb >= own.size
    own_of_edge_b[is_ghost] = gowner[lb[is_ghost] - own.size]
    send_idx = [np.unique(la[own_of_edge_b == q]) for q in nbrs]
    recv_idx = [own.size + np.flatnonzero(gowner == q) for q in nbrs]
    graph = comm.Create_dist_graph_adjacent(nbrs, nbrs, reorder=False)
    try:
        scounts = np.array([s.size for s in send_idx], dtype=np.int64)
        rcounts = np.array([r.size for r in recv_idx], dtype=np.int64)
        send_all = np.concatenate(send_idx).astype(np.int64) if nbrs else np.empty(0, dtype=np.int64)
        recv_all = np.concatenate(recv_idx).astype(np.int64) if nbrs else np.empty(0, dtype=np.int64)
        sdis = np.cumsum(scounts) - scounts
        rdis = np.cumsum(rcounts) - rcounts
        colour = -np.ones(gid.size, dtype=np.int64)
        rounds = 0
        sbuf = np.empty(send_all.size, dtype=np.int64)
        rbuf = np.empty(recv_all.size, dtype=np.int64)
        while True:
            left = greedy_pass(own.size, gid, indptr, indices, colour)
            sbuf[:] = colour[send_all]
            graph.Neighbor_alltoallv([sbuf, (scounts, sdis), MPI.INT64_T], [rbuf, (rcounts, rdis), MPI.INT64_T])
            colour[recv_all] = rbuf
            rounds += 1
            if comm.allreduce(left, op=MPI.SUM) == 0:
                break
    finally:
        graph.Free()
    order = np.argsort(gid, kind="stable")
    return gid[order], colour[order], rounds
