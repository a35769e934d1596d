"""Run under mpirun by tests/test_body_sums.py: the bodies of test_body_sums partitioned over the ranks (rank 0
owns none on 3 ranks; the two rigid bodies on different ranks), each rank adding its own bodies' terms to the sums
over bodies (dynamics.py) through the contact step's face `body_partition`; every rank's energies and works must be
the bits of one process's sums over every body. Prints "same bits on every rank" from rank 0, exits 1 otherwise.

Usage: mpirun -n N python tests/_body_sums_mpi.py
"""
import sys

import numpy as np
from mpi4py import MPI

from fem_blocks.bodies import BlockType
from fem_blocks.dynamics import Simulation
from fem_blocks.meshing import mesh_rectangle
from test_body_sums import MAT, ORDERS, bodies, sums


class Owners:
    """What the simulation asks of its contact step here: no contact, and the partition of the bodies (the
    geometry "updated", which co-rotational bodies need)."""

    def __init__(self, comm, owner):
        self.comm, self.owner = comm, owner
        self.opts = type("Options", (), {"geometry": "updated"})()

    def on_step_change(self, sim):
        pass

    def solve(self, sim, t0, t1):
        return None

    def body_partition(self):
        return self.comm, self.owner == self.comm.Get_rank()


def main():
    comm = MPI.COMM_WORLD
    types = (BlockType(mesh_rectangle(0.2, 0.1, 0.05, cell="quad"), MAT, mass="lumped", name="q4"),
             BlockType(mesh_rectangle(0.3, 0.1, 0.1, cell="quad"), MAT, mass="consistent", name="q4c"))
    owner = np.array([1, 2, 1, 1, 2, 1, 2, 1]) % comm.Get_size()  # by body number; rigid: 6 and 7
    ok = True
    for corotational in (False, True):
        for order in ORDERS[:2]:
            ref = sums(Simulation(bodies(types, order, corotational), h=1e-3, corotational=corotational))
            part = Owners(comm, owner[order])
            got = sums(Simulation(bodies(types, order, corotational), h=1e-3, corotational=corotational,
                                  contact=part))
            if got != ref:
                ok = False
                print(f"rank {comm.Get_rank()}, corotational {corotational}, order {order}: {got} against {ref}",
                      flush=True)
    ok = comm.allreduce(ok, op=MPI.LAND)
    if comm.Get_rank() == 0 and ok:
        print("same bits on every rank", flush=True)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
