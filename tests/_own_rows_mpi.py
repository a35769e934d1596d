"""Run by tests/test_dist_own_rows.py, on one process or under mpirun: steps the case CASE.toml three times,
takes the runner's snapshot after step 2 (the state a refined or adaptive step goes back to), restores it and steps
again; writes OUT.<rank>.json with, per rank, the rows the contact step holds and the record's digests.

Usage: [mpirun -n N] python tests/_own_rows_mpi.py CASE.toml OUT [CASE2.toml OUT2 ...]
(several cases: each one in turn in the same launch, as if launched alone; a launch costs seconds of imports)
"""
import json
import math
import sys

import numpy as np

from _case_steps import digest, stepping


def record(sim, step) -> dict:
    """The step's record of every contact (ContactResult.whole(), in contact order), its totals and statistics, the
    rows the record itself holds, and the velocities of the bodies this rank steps (those not NaN: dynamics.py
    "Bodies stepped per rank"), as digests; and math.fsum of the record's S_DISS and frictional work per contact
    (the totals' expectation)."""
    from fem_blocks.laws import S_DISS
    own = sim.last_contact
    c = own.whole()
    return dict(P=digest(c.P), r=digest(c.r), v=digest(c.v), state=digest(c.state), gt_end=digest(c.gt_end),
                status=digest(c.status), friction=digest(c.friction), law=digest(c.law),
                friction_total=float(c.friction_total), dissipated=float(c.dissipated),
                stats=[own.stats.get(k) for k in ("contacts", "active", "slip", "sweeps")],
                u={str(i): digest(b.u) for i, b in enumerate(sim.bodies) if not np.isnan(b.u).all()},
                warm=digest(step.P), record_rows=int(len(own.P)),
                fsum=[math.fsum(c.state[:, S_DISS]), math.fsum(c.friction)])


def ids(step, rows=None) -> np.ndarray:
    """The contact ids (contact/matching.contact_ids) of the contact step's set, or of its `rows`."""
    from fem_blocks.contact.matching import contact_ids
    cs = step.cs
    rows = np.arange(len(cs.gap)) if rows is None else rows
    return contact_ids(cs.key[rows], cs.ant_body[rows], step.scene.nb)


def own_contacts(step, comm) -> np.ndarray:
    """The ids of the contacts whose candidate body this rank owns in the contact step's partition now (every contact
    on one process)."""
    cs = step.cs
    if step.body_owner is None:
        return ids(step)
    return ids(step, np.flatnonzero(np.asarray(step.body_owner)[cs.cand_body] == comm.Get_rank()))


def scripted_partition(step):
    """The cases "rebalanced", "rebalanced3d" (rebalance = 1.0): the first partition puts every body on rank 0 but
    every fourth (b = 1 mod 4 on rank 1; on 3 ranks b = 3 mod 4 on rank 2), so that the next re-detection partitions
    again, and a rank that owns a run of bodies next receives their rows from several ranks, interleaved in contact
    order (the order in which the new rows list them is not the ranks' order); the later ones split the bodies, in
    order, into runs of about equal weight (1 + contacts as candidate, graph.contact_weights) and turn the ranks'
    labels with the step count, so that the new partition is better than the first (kept: bodies and their
    contacts' rows move to another rank) and no better than the one before it (not kept). Any partition gives the
    same iterates; this one is the same for the same step (the step taken again after the restore) on every rank, as
    PT-Scotch's need not be."""
    from fem_blocks.distributed.graph import contact_weights
    size, nb = step.comm.Get_size(), step.scene.nb
    if step.steps == 0:  # (the first partition: made at the first step, from a provisional split of the bodies)
        b = np.arange(nb)
        owner = np.zeros(nb, dtype=np.int64)
        owner[b % 4 == 1] = 1
        if size > 2:
            owner[b % 4 == 3] = 2
        return owner
    cand = step.cs.cand_body[np.asarray(step.body_owner)[step.cs.cand_body] == step.comm.Get_rank()]
    w = step.comm.allreduce(contact_weights(nb, cand) - 1) + 1  # (every rank's own contacts: the whole set's)
    before = np.cumsum(w) - w
    return (before * size // w.sum() + step.steps) % size


def snapshot_pieces(model, comm, snap, directory) -> dict:
    """The runner's checkpoint of the snapshot `snap` (what a failed step writes: the last good state) as one piece
    per rank (runner._body_owner, distributed/checkpoint.write_pieces), read back whole as a resumed run reads it
    (output/checkpoint.latest_checkpoint: the pieces merged): digests of its impulses and law states (one process:
    the snapshot's own arrays)."""
    if comm.Get_size() > 1:
        from fem_blocks.contact.step import ContactStep
        from fem_blocks.distributed.checkpoint import write_pieces
        from fem_blocks.dynamics import body_of_key
        from fem_blocks.output.checkpoint import latest_checkpoint
        from fem_blocks.runner import _body_owner
        write_pieces(comm, directory, snap, _body_owner(model, comm, snap), body_of_key,
                     ContactStep.per_contact_keys(snap))
        comm.Barrier()
        snap = latest_checkpoint(directory)[1]
    return dict(P=digest(snap["contact.P"]), state=digest(snap["contact.state"]))


def main(path, out):
    import os
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    _, model, sim, step = stepping(path, comm)
    given = []
    if os.path.basename(path).startswith("rebalanced") and comm.Get_size() > 1:
        step._partition = lambda rows: scripted_partition(step)  # (this object only: the others keep PT-Scotch's)
    elif comm.Get_size() > 1:  # (PT-Scotch's, recording how many contacts the ranks give to its graph)
        partition = step._partition
        step._partition = lambda rows: (given.append(comm.allreduce(len(rows))), partition(rows))[1]
    res = dict(rank=comm.Get_rank(), size=comm.Get_size(), steps=[], owners=[], own_counts=[], given=given)
    pieces = f"{out}.pieces"
    if comm.Get_rank() == 0:
        os.makedirs(pieces, exist_ok=True)
    for k in range(3):
        if k >= 1:  # the runner's snapshot of the last good state (runner._snapshot)
            snap = sim.export_state()
            snap.update({key: (v.copy() if isinstance(v, np.ndarray) else v)
                         for key, v in step.export_state().items()})
            res["snapshot_rows"] = int(len(snap["contact.P"]))
        sim.step()
        res["steps"].append(record(sim, step))
        res["owners"].append(None if step.body_owner is None else np.asarray(step.body_owner).tolist())
        res["own_counts"].append(own_contacts(step, comm).size)
        if k == 1:  # the snapshot of step 1 written as the runner's checkpoint after step 2 (what a failed step
            # writes: the last good state; "rebalanced" partitions the bodies again at step 2)
            comm.Barrier()
            res["snapshot_pieces"] = snapshot_pieces(model, comm, snap, pieces)
    sim.restore_state(snap)
    back = sim.last_contact.whole()
    res["restored"] = dict(P=digest(back.P), state=digest(back.state))
    sim.step()
    res["again"] = record(sim, step)
    n = len(step.cs.gap) if step._local is None else step._local.n
    own = own_contacts(step, comm)
    cs = step.cs
    res.update(n_contacts=n, own=own.tolist(), rebalanced=step.rebalanced, held=ids(step).tolist(),
               owner_end=None if step.body_owner is None else np.asarray(step.body_owner).tolist(),
               pairs=np.column_stack([ids(step), cs.cand_body, cs.ant_body]).tolist(),
               rows={name: (None if getattr(step, name, None) is None else int(len(getattr(step, name))))
                     for name in step.ROWS})
    step.close()
    with open(f"{out}.{comm.Get_rank()}.json", "w") as f:
        json.dump(res, f)


if __name__ == "__main__":
    args = sys.argv[1:]
    assert args and len(args) % 2 == 0, "expected pairs CASE.toml OUT"
    try:
        for k in range(0, len(args), 2):
            main(args[k], args[k + 1])
    except BaseException:  # (an error on one rank stops every rank now, as the command line does, instead of
        import traceback   # leaving the others waiting until the test's timeout)
        from mpi4py import MPI
        traceback.print_exc()
        sys.stderr.flush()
        MPI.COMM_WORLD.Abort(1)
