"""Run under mpirun by tests/test_body_sums.py: the bodies of test_body_sums partitioned over the ranks (rank 0
owns none on 3 ranks; the two rigid bodies on different ranks), each rank adding its own bodies' terms to the sums
over bodies (dynamics.py) through the contact step's face `body_partition` and stepping its own bodies and body 1
(`stepped_bodies`; dynamics.py "Bodies stepped per rank": the bodies with a traction, 1 and 4, stepped by every rank
or by one); every rank's energies and works must be the bits of one process's sums over every body, and the state
of each body it steps the serial one. Prints "same bits on every rank" from rank 0, exits 1 otherwise.

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
    """What the simulation asks of its contact step here: no contact, the partition of the bodies (the geometry
    "updated", which co-rotational bodies need) and the bodies this rank steps (`stepped_bodies`: its own and body
    `also`, as a contact step's mask with the bodies of the rank's contacts; co-rotational groups are stepped whole)."""

    def __init__(self, comm, owner, also):
        self.comm, self.owner = comm, owner
        self.opts = type("Options", (), {"geometry": "updated"})()
        self.stepped = self.owner == self.comm.Get_rank()
        self.stepped[also] = True

    def on_step_change(self, sim):
        pass

    def solve(self, sim, t0, t1):
        return None

    def body_partition(self):
        return self.comm, self.owner == self.comm.Get_rank()

    def stepped_bodies(self):
        return self.stepped


def main():
    comm = MPI.COMM_WORLD
    types = (BlockType(mesh_rectangle(0.2, 0.1, 0.05, cell="quad"), MAT, mass="lumped", name="q4"),
             BlockType(mesh_rectangle(0.3, 0.1, 0.1, cell="quad"), MAT, mass="consistent", name="q4c"))
    owner = np.array([1, 2, 1, 1, 2, 1, 2, 1]) % comm.Get_size()  # by body number; rigid: 6 and 7
    ok = True
    for corotational in (False, True):
        for order in ORDERS[:2]:
            one = Simulation(bodies(types, order, corotational), h=1e-3, corotational=corotational)
            ref = sums(one)
            part = Owners(comm, owner[order], also=list(order).index(1))  # body 1 (a traction) on every rank
            sim = Simulation(bodies(types, order, corotational), h=1e-3, corotational=corotational, contact=part)
            got = sums(sim)
            stepped = np.flatnonzero(part.stepped)
            state = [np.array_equal(np.r_[sim.bodies[i].q, sim.bodies[i].u], np.r_[one.bodies[i].q, one.bodies[i].u])
                     for i in stepped]
            if got != ref or not all(state):
                ok = False
                print(f"rank {comm.Get_rank()}, corotational {corotational}, order {order}: {got} against {ref}; "
                      f"the state of the stepped bodies {stepped} the serial one: {state}", flush=True)
    ok = comm.allreduce(ok, op=MPI.LAND)
    if comm.Get_rank() == 0 and ok:
        print("same bits on every rank", flush=True)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
