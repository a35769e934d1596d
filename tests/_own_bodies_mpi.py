"""Run by tests/test_dist_own_bodies.py, on one process or under mpirun: steps the case CASE.toml (frozen
geometry) three times and records, per rank, what the step, its record and the runner's per-step checks give, and
which bodies the rank stepped.

On N > 1 ranks a rank steps only its bodies B_p (the bodies it owns, the bodies of its own contacts, the rigid
bodies) and the bodies shared with every rank (Simulation.share_bodies: here the first and the last brick, as the
runner shares the bodies its outputs read at every step). Written to OUT.<rank>.json: per step the history's sums
over bodies (energies, works, largest velocity), the rigid bodies' reactions and their inertia parts, the record of
every contact, the state of each stepped body, the body NaN check and the small-rotation watch; and what the rank's
step did: the columns of each solve by a block type's step operator (free velocities, corrections), the deformable
bodies it should step (B_p and the shared bodies, found here from the contact set and the partition) and those
whose state is all NaN after the step.

Usage: [mpirun -n N] python tests/_own_bodies_mpi.py CASE.toml OUT
"""
import json
import sys

import numpy as np

from _case_steps import digest, stepping


def rank_bodies(sim, step) -> np.ndarray:
    """B_p: the bodies this rank owns, those of its own contacts, the rigid bodies (every body on one process)."""
    nb = len(sim.bodies)
    part = step.body_partition()
    if part is None:
        return np.ones(nb, dtype=bool)
    mine = part[1].copy()
    cs, own = step.cs, step._local.own
    mine[cs.cand_body[own]] = True
    mine[cs.ant_body[own]] = True
    mine[sim.rigid] = True
    return mine


def counting(g, op, log):
    """Wrap op.solve (group g's step operator) to append [g, the number of columns] of each call to `log`."""
    solve = op.solve

    def counted(B):
        log.append([g, int(np.shape(B)[1]) if np.ndim(B) == 2 else 1])
        return solve(B)
    op.solve = counted


def main(path, out):
    from mpi4py import MPI
    from fem_blocks.runner import _Guards, _RotationWatch
    comm = MPI.COMM_WORLD
    case, model, sim, step = stepping(path, comm)
    names = list(model.names)
    shared = [sim.deformable[0], sim.deformable[-1]]
    sim.share_bodies(shared)
    guards = _Guards(case, model, names, comm if comm.Get_size() > 1 else None)
    watch = _RotationWatch(sim, names, bound=1e-9)  # a bound every block passes: the blocks beyond are listed
    e0 = sim.energies()
    res = dict(rank=comm.Get_rank(), size=comm.Get_size(), steps=[])
    for k in range(3):
        solves = []
        for g, gr in enumerate(sim.groups):
            counting(g, gr.op, solves)
        info = sim.step()
        B = rank_bodies(sim, step)
        S = B.copy()
        S[shared] = True
        nan = [i for i in sim.deformable if np.isnan(sim.bodies[i].q).all() and np.isnan(sim.bodies[i].u).all()]
        rec = dict(sums=[info.kinetic, info.elastic, info.gravity_potential, sim.external_work, sim.driver_work,
                         sim.inertia_work, info.max_velocity],
                   reactions=digest(*[np.r_[sim.bodies[i].reaction, sim.bodies[i].reaction_inertia]
                                      for i in sim.rigid]),
                   record=digest(*(lambda c: (c.P, c.state, c.gt_end, c.status))(sim.last_contact.whole())),
                   bodies={str(i): digest(sim.bodies[i].q, sim.bodies[i].u) for i in np.flatnonzero(S)},
                   guard=guards.check(sim, info, e0),
                   solves=solves, expected=[int(np.count_nonzero(S[gr.members])) for gr in sim.groups],
                   stepped=[int(i) for i in sim.deformable if S[i]], nan=[int(i) for i in nan],
                   outside_shared=[int(i) for i in shared if not B[i]])
        watch.check(sim)
        rec["watch"] = dict(watch.state)
        res["steps"].append(rec)
        for gr in sim.groups:
            gr.op.__dict__.pop("solve", None)
    step.close()
    with open(f"{out}.{comm.Get_rank()}.json", "w") as f:
        json.dump(res, f)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
