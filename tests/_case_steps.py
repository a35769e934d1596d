"""What the helpers that step a case file in-process share (tests/_own_rows_mpi.py, tests/_own_bodies_mpi.py, run on
one process or under mpirun; in-process tests of a case file too): the model of the case with its contact step shared by the ranks, and digests of arrays
to compare between runs."""
import hashlib

import numpy as np


def digest(*arrays) -> str:
    """sha1 of the arrays' bytes, in order."""
    h = hashlib.sha1()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def stepping(path, comm):
    """(case, model, sim, step) of the case file `path`: the expanded case, its model, a Simulation with the first
    stage's step and the model's contact step, sharing its solve among the ranks of `comm` (ContactStep.use_comm)."""
    from fem_blocks.case import load_case
    from fem_blocks.dynamics import Simulation
    from fem_blocks.expand import expand
    from fem_blocks.model import build_model
    case = expand(load_case(path))
    model = build_model(case)
    st = case.stages[0]
    sim = Simulation(model.bodies, h=st.h, theta=st.theta, gravity=model.gravity, velocity_reset=st.velocity_reset,
                     contact=model.contact)
    model.contact.use_comm(comm)
    return case, model, sim, model.contact
