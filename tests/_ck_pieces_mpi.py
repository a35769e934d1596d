"""Run under mpirun by tests/test_checkpoint_pieces.py: every rank writes its piece of the same small checkpoint
(distributed/checkpoint.write_pieces), then a second round in which rank 1 fails while it splits; each rank writes
what the second round raised on it to OUT_DIR/raised<r>.txt.

Usage: mpirun -n N python tests/_ck_pieces_mpi.py OUT_DIR
"""
import sys

import numpy as np
from mpi4py import MPI

from fem_blocks.contact.step import ContactStep
from fem_blocks.distributed.checkpoint import write_pieces
from fem_blocks.dynamics import body_of_key


def state(step):
    """4 bodies, 5 contacts, rows depending on the step."""
    return {"sim.step": np.int64(step), **{f"sim.body{i}.q": np.full(3, step + i, dtype=float) for i in range(4)},
            "contact.cs.cand_body": np.array([0, 1, 2, 3, 3]), "contact.cs.ant_body": np.array([1, 2, 3, 0, 1]),
            "contact.cs.key": np.array([3, 7, 11, 15, 16]),
            "contact.P": np.arange(10, dtype=float).reshape(5, 2) + step}


OWNER = np.array([0, 1, 1, 0])


def main(out):
    comm = MPI.COMM_WORLD
    flushed = []
    ck = state(3)
    write_pieces(comm, out, ck, OWNER, body_of_key, ContactStep.per_contact_keys(ck), before=lambda: flushed.append(1))
    assert flushed == ([1] if comm.Get_rank() == 0 else [])

    def failing(key):
        if comm.Get_rank() == 1:
            raise ValueError("no room left")
        return body_of_key(key)
    ck = state(5)
    try:
        write_pieces(comm, out, ck, OWNER, failing, ContactStep.per_contact_keys(ck))
        raised = "nothing"
    except Exception as e:  # noqa: BLE001 - what each rank raised is the result
        raised = f"{type(e).__name__}: {e}"
    with open(f"{out}/raised{comm.Get_rank()}.txt", "w") as f:
        f.write(raised)


if __name__ == "__main__":
    main(sys.argv[1])
