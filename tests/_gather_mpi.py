"""Run by tests/test_dist_own_rows.py under mpirun: distributed/sweep.py OwnRowsGather and gather_fields. Each rank
holds the rows of interleaved contact ids (negative ones too, as node points' keys give); the gather must give every
contact's rows in increasing id order on every rank; ids held by two ranks must raise on every rank. Writes
OUT.<rank>.json.

Usage: mpirun -n N python tests/_gather_mpi.py OUT
"""
import json
import sys

import numpy as np

from fem_blocks.distributed.sweep import OwnRowsGather, gather_fields


def main(out):
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    rank, size = comm.Get_rank(), comm.Get_size()
    every = np.arange(23, dtype=np.int64) * 5 - 40
    rng = np.random.default_rng(3)
    owner = rng.integers(0, size, every.size)
    ids = every[owner == rank]
    g = OwnRowsGather(comm, ids)
    fields = dict(i=ids, f=np.column_stack([ids * 0.5, -ids * 0.25]), b=(ids % 2 == 0),
                  t=np.repeat(ids, 6).reshape(-1, 2, 3).astype(np.float64))
    got = gather_fields(g, fields)
    res = dict(i=got["i"].tolist(), f=got["f"].tolist(), b=got["b"].tolist(), t=got["t"].tolist(),
               dtypes=[str(got[k].dtype) for k in ("i", "f", "b", "t")], want=every.tolist())
    twice = OwnRowsGather(comm, np.concatenate([ids, every[:1]]) if rank == size - 1 else ids)
    try:
        twice(np.zeros((twice.ids.size, 1)))
        res["twice"] = "no error"
    except RuntimeError as e:
        res["twice"] = str(e)
    with open(f"{out}.{rank}.json", "w") as f:
        json.dump(res, f)


if __name__ == "__main__":
    main(sys.argv[1])
