"""Run by tests/test_dist_partition.py under mpirun: the body graph's partition (distributed/graph.py
partition_graph, PT-Scotch) of a grid graph of NX x NY vertices (4-neighbour edges, weight 1) whose vertices with
x < NX // 3 and y < NY // 2 (a corner) weigh HEAVY and the others 1, with those vertex weights and without; writes
OUT.<rank>.json with both owner arrays and the weights.

Usage: mpirun -n N python tests/_weights_mpi.py OUT
"""
import json
import sys

import numpy as np

from fem_blocks.distributed.graph import body_graph, partition_graph

NX, NY, HEAVY = 36, 20, 6


def grid():
    """(nb, edges (m, 2), vertex weights (nb,)) of the grid, vertex x + NX y."""
    v = np.arange(NX * NY).reshape(NY, NX)
    edges = np.concatenate([np.column_stack([v[:, :-1].ravel(), v[:, 1:].ravel()]),
                            np.column_stack([v[:-1, :].ravel(), v[1:, :].ravel()])])
    i = np.arange(NX * NY)
    w = np.where(((i % NX) < NX // 3) & (i // NX < NY // 2), HEAVY, 1)
    return NX * NY, edges, w


def main(out):
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    nb, edges, w = grid()
    g = body_graph(nb, edges, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
    weighted = partition_graph(*g, comm, vertex_weights=w)
    plain = partition_graph(*g, comm)
    with open(f"{out}.{comm.Get_rank()}.json", "w") as f:
        json.dump(dict(weighted=weighted.tolist(), plain=plain.tolist(), w=w.tolist()), f)


if __name__ == "__main__":
    main(sys.argv[1])
