"""Run under mpirun by tests/test_exact_sum.py: every rank sums its uneven share of one global array (rank 0's share
empty when several ranks) with distributed.exact; rank 0 writes what every rank got.

Usage: mpirun -n N python tests/_exact_mpi.py OUT.npz
"""
import sys

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_blocks.distributed import exact


def global_arrays():
    """The global terms, the same on every rank (fixed seed): mixed signs and exponents 1e-300..1e300, subnormals,
    cancellations; and a second array of squares of order one (a residual's terms)."""
    rng = np.random.default_rng(5)
    n = 20011
    x = rng.choice([-1.0, 1.0], n) * rng.uniform(1, 10, n) * 10.0 ** rng.integers(-300, 300, n)
    x[::97] = rng.integers(1, 1 << 40, x[::97].size) * 5e-324  # subnormal
    x[1::101] = 1e16
    x[2::101] = -1e16
    x[3::101] = 1.0
    y = rng.normal(size=n) ** 2
    return x, y


def main(out):
    comm = MPI.COMM_WORLD
    rank, size = comm.Get_rank(), comm.Get_size()
    x, y = global_arrays()
    n = x.size
    # uneven split: rank 0 nothing (when size > 1), the others growing shares
    w = np.array([0.0] + [float(k) for k in range(1, size)]) if size > 1 else np.ones(1)
    cuts = np.concatenate([[0], np.round(np.cumsum(w) / w.sum() * n).astype(int)])
    lo, hi = cuts[rank], cuts[rank + 1]
    s1 = exact.exact_sum(x[lo:hi], comm)
    s2 = exact.exact_sums([x[lo:hi], y[lo:hi], y[lo:hi][::-1]], PETSc.COMM_WORLD)  # a petsc4py communicator too
    got = comm.gather(np.array([s1] + s2 + [hi - lo]), root=0)
    # exact.largest: every rank's rank number, then a NaN on rank k (k = 0 .. size-1) and the others finite
    big = [exact.largest(float(rank), comm)] + [exact.largest(np.nan if rank == k else float(rank), comm)
                                               for k in range(size)]
    big = comm.gather(np.array(big), root=0)
    if rank == 0:
        np.savez(out, got=np.array(got), x=x, y=y, largest=np.array(big))


if __name__ == "__main__":
    main(sys.argv[1])
