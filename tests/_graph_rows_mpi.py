"""Run by tests/test_dist_partition.py under mpirun: the body graph's rows assembled from contacts given by the ranks
(distributed/graph.py contact_graph_rows), each contact by one rank, against body_graph and contact_weights of the
whole contact list written out on every rank; writes OUT.<rank>.json with both.

Usage: mpirun -n N python tests/_graph_rows_mpi.py OUT
"""
import json
import sys

import numpy as np

from fem_blocks.distributed.graph import body_graph, contact_graph_rows, contact_weights, row_block

NB = 23


def contacts():
    """(cand, ant) of 120 contacts among NB bodies (repeated pairs, both orientations of a pair, a body without
    contacts, body 0 only as antagonist and one self pair, which the graph drops)."""
    rng = np.random.default_rng(5)
    cand = rng.integers(1, NB - 1, 120)
    ant = rng.integers(0, NB - 1, 120)
    ant[0] = cand[0]
    return cand.astype(np.int64), ant.astype(np.int64)


def main(out):
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    rank, size = comm.Get_rank(), comm.Get_size()
    cand, ant = contacts()
    mine = np.flatnonzero((np.arange(len(cand)) * 7 + 3) % size == rank)  # (an interleaved share)
    start, ia, ja, w, vw = contact_graph_rows(NB, cand[mine], ant[mine], comm)
    s0, n_loc = row_block(NB, size, rank)
    indptr, indices, weights = body_graph(NB, np.zeros((0, 2), dtype=np.int64), cand, ant)
    s, e = int(indptr[s0]), int(indptr[s0 + n_loc])
    want = dict(start=s0, ia=(indptr[s0:s0 + n_loc + 1] - s).tolist(), ja=indices[s:e].tolist(),
                w=weights[s:e].tolist(), vw=contact_weights(NB, cand)[s0:s0 + n_loc].tolist())
    got = dict(start=int(start), ia=ia.tolist(), ja=ja.tolist(), w=w.tolist(), vw=vw.tolist())
    with open(f"{out}.{rank}.json", "w") as f:
        json.dump(dict(got=got, want=want), f)


if __name__ == "__main__":
    main(sys.argv[1])
