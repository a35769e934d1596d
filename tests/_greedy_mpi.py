"""Run under mpirun by tests/test_dist_greedy.py: every rank builds the same random graphs (`graph`), keeps the
vertices it owns and only the edges given to it, colours with distributed/greedy.greedy_colours and writes what it
got to OUT_DIR/rank<r>.npz: for graph k, ids_k and colour_k (its vertices and their neighbours), and rounds_k.

Usage: mpirun -n N python tests/_greedy_mpi.py OUT_DIR
"""
import sys

import numpy as np
from mpi4py import MPI

from fem_blocks.distributed.greedy import greedy_colours


def graph(k, size):
    """(n, a, b, owner): random edges (a, b) over n vertices, duplicates and self-pairs included; the owner
    rank of each vertex (on 3 ranks or more the last owns none); each edge given to one rank only: the owner of a,
    in the direction (a, b) (never the reverse), so a rank may not know an edge of its vertex."""
    rng = np.random.default_rng(k)
    n = [60, 400, 1, 300][k]
    m = [150, 2000, 1, 0][k]
    a = rng.integers(0, n, m)
    b = rng.integers(0, n, m)
    if k == 1:  # a long path 0-1-2-... across the ranks: the dependencies cross ranks at every step
        a = np.concatenate([a, np.arange(n - 1)])
        b = np.concatenate([b, np.arange(1, n)])
    owner = rng.integers(0, size - 1 if size > 2 else size, n)
    return n, a, b, owner


def main(out):
    comm = MPI.COMM_WORLD
    p, size = comm.Get_rank(), comm.Get_size()
    res = {}
    for k in range(4):
        n, a, b, owner = graph(k, size)
        mine = owner[a] == p
        ids, col, rounds = greedy_colours(np.flatnonzero(owner == p), a[mine], b[mine], lambda x: owner[x], comm)
        res[f"ids_{k}"], res[f"colour_{k}"], res[f"rounds_{k}"] = ids, col, rounds
    np.savez(f"{out}/rank{p}.npz", **res)


if __name__ == "__main__":
    main(sys.argv[1])
