"""Run by tests/test_dist_own_bodies.py, on one process or under mpirun: steps the case CASE.toml (frozen
geometry) three times and records, per rank, what the step, its record and the runner's per-step checks give.

On N > 1 ranks, after every step, the state (q, u) of every deformable body outside the rank's bodies B_p is set to
NaN: B_p = the bodies it owns, the bodies of its own contacts, and the rigid bodies. What reads only B_p is then
unchanged; what reads another body turns NaN, or differs from the serial run. Written to OUT.<rank>.json: per step
the history's sums over bodies (energies, works, largest velocity), the rigid bodies' reactions and their inertia
parts, the record of every contact, the state of each body of B_p, the body NaN check and the small-rotation
watch.

Usage: [mpirun -n N] python tests/_own_bodies_mpi.py CASE.toml OUT
"""
import json
import sys

import numpy as np

from _case_steps import digest, stepping


def rank_bodies(sim, step, rank) -> np.ndarray:
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


def main(path, out):
    from mpi4py import MPI
    from fem_blocks.runner import _Guards, _RotationWatch
    comm = MPI.COMM_WORLD
    case, model, sim, step = stepping(path, comm)
    names = list(model.names)
    guards = _Guards(case, model, names, comm if comm.Get_size() > 1 else None)
    watch = _RotationWatch(sim, names, bound=1e-9)  # a bound every block passes: the blocks beyond are listed
    e0 = sim.energies()
    res = dict(rank=comm.Get_rank(), size=comm.Get_size(), steps=[], poisoned=[])
    for k in range(3):
        info = sim.step()
        B = rank_bodies(sim, step, comm.Get_rank())
        rec = dict(sums=[info.kinetic, info.elastic, info.gravity_potential, sim.external_work, sim.driver_work,
                         sim.inertia_work, info.max_velocity],
                   reactions=digest(*[np.r_[sim.bodies[i].reaction, sim.bodies[i].reaction_inertia]
                                      for i in sim.rigid]),
                   record=digest(*(lambda c: (c.P, c.state, c.gt_end, c.status))(sim.last_contact.whole())),
                   bodies={str(i): digest(sim.bodies[i].q, sim.bodies[i].u) for i in np.flatnonzero(B)},
                   guard=guards.check(sim, info, e0))
        watch.check(sim)
        rec["watch"] = dict(watch.state)
        res["steps"].append(rec)
        if comm.Get_size() > 1:  # the bodies this rank does not step need not hold anything
            out_of = [i for i in np.flatnonzero(~B) if sim.bodies[i].kind == 0]
            for i in out_of:
                sim.bodies[i].q[:] = np.nan
                sim.bodies[i].u[:] = np.nan
            res["poisoned"].append(len(out_of))
    step.close()
    with open(f"{out}.{comm.Get_rank()}.json", "w") as f:
        json.dump(res, f)


if __name__ == "__main__":
    import warnings
    warnings.simplefilter("ignore", RuntimeWarning)  # the poisoned bodies' NaN arithmetic
    main(sys.argv[1], sys.argv[2])
