"""Run by tests/test_dist_own_rows.py under mpirun: a dry wall in updated geometry re-detected every step, stepped twice
in colour order (on N > 1 ranks each rank holds its own contacts' rows and its part of the contact set), then switched
through the Python API to the "given" order with the interface coarse correction (every rank then runs the same serial
solve on the whole contact set), and stepped twice more: at the switch's re-detection the old rows, held by their
owners, are gathered whole by contact id (contact/step.py `_carry_rows`). Writes OUT.<rank>.json with the digests of
every step's record (every contact's) and whether the rank held its part of the set.

Usage: mpirun -n N python tests/_leave_colours_mpi.py CASE.toml OUT
"""
import dataclasses
import json
import sys

from _case_steps import digest, stepping


def main(path, out):
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    _, model, sim, step = stepping(path, comm if comm.Get_size() > 1 else None)
    res = []
    for k in range(4):
        if k == 2:
            step.set_options(dataclasses.replace(step.opts, coarse="interfaces", order="given"))
        sim.step()
        c = sim.last_contact.whole()
        res.append(dict(P=digest(c.P), state=digest(c.state), n=int(len(c.P)), part=step._local is not None,
                        order=step.opts.order))
    with open(f"{out}.{comm.Get_rank()}.json", "w") as f:
        json.dump(res, f)


if __name__ == "__main__":
    try:
        main(sys.argv[1], sys.argv[2])
    except BaseException:  # (an error on one rank stops every rank, as the command line does)
        import traceback
        from mpi4py import MPI
        traceback.print_exc()
        sys.stderr.flush()
        MPI.COMM_WORLD.Abort(1)
