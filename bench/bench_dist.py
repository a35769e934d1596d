"""Time steps of a running-bond wall on N MPI ranks (issue #24): the contact solve shared by the ranks.

The wall of bench_wall.py / bench_partition.py (bricks 0.25 x 0.06 m, Q1 0.03 m, about twice as wide as high, dry
joints μ = 0.7 on a rigid floor) as a case file, quasi-static steps (θ = 1, velocity reset, h = 1e-3 s), NLGS in
colour order (`[contact] order = "colours"`) to a change of 1e-4, at most 1000 sweeps per step. Every rank builds
the model (build_model) and steps it (dynamics.Simulation); the contact step shares its sweeps with the other ranks
(ContactStep.use_comm, distributed/colour.py). The first `--warm` steps (the colouring, the partition and the PETSc
scatters are set up in the first) are not timed; then `--steps` steps are.

Rank 0 prints one markdown row per wall: ranks, bricks, contacts, colours, contacts per rank (min–max), setup [s]
(model build + first steps, max over ranks), ms per step, sweeps per step, ms per sweep in the contact solve (NLGS
timer / sweeps), of which in the per-colour exchanges (max over ranks), bytes sent / received per sweep per rank
(max), messages per sweep per rank (max), peak RSS per rank [MB] (max), the blocks of W held per rank (max: each
rank assembles the rows of its own contacts), and the sha1 of the floor's reaction and
the sweep counts of the timed steps (equal sha1 on any N: the same iterates); then a line with the resident memory
per rank after the steps (min–max: what the run holds, where the peak may be the set-up's) and the contacts each rank
holds (its part of the contact set, min–max).

With --checkpoint DIR, the state after the steps is also written as a checkpoint, one piece per rank (best of 3; the
sizes of the pieces). (Until the contact step held its own contacts' rows only, it was also written as one file by
rank 0, the layout before the pieces: rank 0 no longer holds the whole state.)

With --geometry updated (and --redetect-every K) the steps re-detect the contacts every K steps and assemble W, G
and the colour solver at every step; a line after the row gives the contact step's own timers per step (detection:
geometry, detection and W; delassus: W alone; local: the local quantities and the colour solver's set-up; nlgs;
correction), the slowest rank's, with the times the bodies were partitioned again (`[contact] rebalance`, its
default unless --rebalance B is given) and the contacts per rank at the end.

Usage: mpirun -n N .venv/bin/python bench/bench_dist.py [n_bricks ...] [--steps S] [--warm W] [--max-sweeps K]
                                                        [--checkpoint DIR] [--geometry G] [--redetect-every K]
                                                        [--rebalance B]
"""
import argparse
import hashlib
import os
import resource
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
from fem_blocks.case import load_case  # noqa: E402
from fem_blocks.dynamics import Simulation  # noqa: E402
from fem_blocks.expand import expand  # noqa: E402
from fem_blocks.model import build_model  # noqa: E402

from bench_partition import wall_case  # noqa: E402 (bench/ is on sys.path when this file runs)

SETTINGS = """[contact]
order = "colours"
geometry = "{geometry}"
redetect_every = {redetect}
tol = 1e-4
max_sweeps = {max_sweeps}
[[stages]]
name = "g"
duration = 1.0
h = 1e-3
theta = 1.0
velocity_reset = true
"""


def rss_now() -> float:
    """This process's resident memory now [MB] (VmRSS of /proc/self/status; the peak is ru_maxrss)."""
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:")) / 1024


def checkpoint_times(sim, model, comm, directory, repeat=3):
    """After the steps: the run's checkpoint (Simulation and contact step state) written `repeat` times as one piece
    per rank (distributed/checkpoint.write_pieces). Returns (best seconds (the slowest rank), MB of the largest and
    the smallest piece)."""
    from fem_blocks.contact.step import ContactStep
    from fem_blocks.distributed.checkpoint import write_pieces
    from fem_blocks.dynamics import body_of_key
    from fem_blocks.output.checkpoint import piece_names
    arrays = {**sim.export_state(), **model.contact.export_state()}
    owner = model.contact.body_owner if model.contact.body_owner is not None else np.zeros(len(model.bodies), int)
    many = os.path.join(directory, "pieces")
    if comm.rank == 0:
        os.makedirs(many, exist_ok=True)
    t_many = []
    for _ in range(repeat):
        comm.Barrier()
        c = time.perf_counter()
        write_pieces(comm, many, arrays, owner, body_of_key, ContactStep.per_contact_keys(arrays))
        comm.Barrier()
        t_many.append(time.perf_counter() - c)
    sizes = [os.path.getsize(os.path.join(many, piece_names(p)[0])) / 1e6 for p in range(comm.size)]
    return min(t_many), max(sizes), min(sizes)


def run(n_bricks, comm, steps, warm, show=True, max_sweeps=1000, ck_dir=None, geometry="frozen", redetect=1,
        rebalance=None):
    settings = SETTINGS.format(max_sweeps=max_sweeps, geometry=geometry, redetect=redetect)
    if rebalance is not None:
        settings = settings.replace("[contact]\n", f"[contact]\nrebalance = {rebalance!r}\n", 1)
    with tempfile.TemporaryDirectory() as d:
        # the wall of bench_partition.py, with this benchmark's solver and steps
        path = wall_case(n_bricks, d, settings)
        comm.Barrier()
        c = time.perf_counter()
        model = build_model(expand(load_case(path)))
    sim = Simulation(model.bodies, h=1e-3, theta=1.0, gravity=model.gravity, velocity_reset=True,
                     contact=model.contact)
    cs = model.contact
    cs.use_comm(comm)
    for _ in range(warm):
        sim.step()
    comm.Barrier()
    t_setup = time.perf_counter() - c
    t_nlgs0 = cs.timers["nlgs"]
    timers0 = dict(cs.timers)
    sweeps, reac = [], []
    floor = next(i for i, b in enumerate(model.bodies) if b.kind == 1)
    c = time.perf_counter()
    for _ in range(steps):
        info = sim.step()
        sweeps.append(info.contact["sweeps"])
        reac.append(model.bodies[floor].reaction.copy())
    t_steps = time.perf_counter() - c
    t_nlgs = cs.timers["nlgs"] - t_nlgs0
    comm.Barrier()
    col = cs._colours
    dist = col.dist
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    mine = (col.n_owned, t_setup, t_steps, t_nlgs, 8 * dist.entries_sent if dist else 0,
            8 * dist.entries_recv if dist else 0, dist.messages if dist else 0, rss, cs.Wdel.blocks.shape[0],
            rss_now(), len(cs.cs.gap))
    rows = np.array(comm.gather(mine), dtype=float) if comm.size > 1 else np.array([mine], dtype=float)
    if comm.rank == 0 and show:
        nsw = sum(sweeps)
        h = hashlib.sha1(np.array(reac).tobytes() + np.array(sweeps).tobytes()).hexdigest()[:12]
        print(f"| {comm.size} | {n_bricks} ({len(model.bodies) - 1}) | {col.n} | {col.n_colours} | "
              f"{rows[:, 0].min():.0f}–{rows[:, 0].max():.0f} | {rows[:, 1].max():.1f} | "
              f"{1e3 * rows[:, 2].max() / steps:.1f} | {nsw / steps:.1f} | {1e3 * rows[:, 3].max() / max(nsw, 1):.3f} | "
              f"{rows[:, 4].max():.0f} / {rows[:, 5].max():.0f} | {rows[:, 6].max():.0f} | {rows[:, 7].max():.0f} | "
              f"{rows[:, 8].max():.0f} | {h} |", flush=True)
        print(f"\nRSS after the steps per rank: {rows[:, 9].min():.0f}–{rows[:, 9].max():.0f} MB (the peak above may "
              f"be the set-up's); contacts held per rank (its part of the set) {rows[:, 10].min():.0f}–"
              f"{rows[:, 10].max():.0f}", flush=True)
    parts = {k: 1e3 * (v - timers0.get(k, 0.0)) / steps for k, v in cs.timers.items()}
    every = comm.gather(parts) if comm.size > 1 else [parts]
    if comm.rank == 0 and show:  # the contact step's own timers (ContactStep.timers), per step, slowest rank
        print("contact step per step [ms], slowest rank: " + ", ".join(
            f"{k} {max(p[k] for p in every):.0f}" for k in parts)
            + f"; partitioned again {cs.rebalanced} times, contacts per rank at the end {rows[:, 0].min():.0f}–"
            f"{rows[:, 0].max():.0f}\n", flush=True)
    if ck_dir is not None:
        tn, mbmax, mbmin = checkpoint_times(sim, model, comm, ck_dir)
        if comm.rank == 0:
            print(f"\ncheckpoint of the {n_bricks}-brick wall on {comm.size} ranks: one piece per rank {tn:.3f} s "
                  f"(pieces {mbmin:.1f}–{mbmax:.1f} MB)\n", flush=True)
    col.destroy()


if __name__ == "__main__":
    from mpi4py import MPI
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sizes", nargs="*", type=int, default=[1000])
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--warm", type=int, default=2)
    ap.add_argument("--max-sweeps", type=int, default=1000, help="[contact] max_sweeps of the wall's steps")
    ap.add_argument("--checkpoint", metavar="DIR", help="also time the checkpoint after the steps, written in DIR "
                    "as one piece per rank")
    ap.add_argument("--geometry", choices=("frozen", "updated"), default="frozen",
                    help="[contact] geometry (updated: W, G and the colour solver every step)")
    ap.add_argument("--redetect-every", type=int, default=1, help="[contact] redetect_every (updated geometry)")
    ap.add_argument("--rebalance", type=float, default=None, help="[contact] rebalance (updated geometry on N > 1 "
                    "ranks; default: the case file's default)")
    a = ap.parse_args()
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        print(f"{a.warm} untimed steps, then {a.steps} timed steps\n\n| ranks | bricks (bodies) | contacts | colours | "
              "contacts per rank | setup [s] | ms/step | sweeps/step | ms/sweep (NLGS) | bytes sent / received per "
              "sweep per rank | messages per sweep per rank | peak RSS per rank [MB] | blocks of W per rank | sha1 "
              "(reactions, sweeps) |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|", flush=True)
    run(20, comm, 2, 1, show=False)  # warm-up: numba caches outside the timed runs
    for n in a.sizes:
        run(n, comm, a.steps, a.warm, max_sweeps=a.max_sweeps, ck_dir=a.checkpoint, geometry=a.geometry,
            redetect=a.redetect_every, rebalance=a.rebalance)
