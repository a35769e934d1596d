"""Partition of a running-bond wall across MPI ranks (fem_blocks/distributed/partition.py, issue #24).

The wall of bench_wall.py (bricks 0.25 x 0.06 m, Q1 0.03 m, about twice as wide as high, dry joints μ = 0.7,
alert 1 mm) as a case file ([wall] running_bond on a rigid foundation), built by build_model on every rank, then
partitioned by PETSc MatPartitioning ("ptscotch") on the body-contact graph. Rank 0 prints one markdown row: ranks,
bodies, contacts, graph edges, edge cut (cut edges; Σ contact weights), bodies / ghosts / contacts per rank
(min–max), times [s] (model build, graph, partition, local ghosts + detection; max over ranks), peak RSS per rank,
the interface contacts a rank sends per Gauss–Seidel sweep (exchange_lists: owned contacts sharing a body with a
contact of another rank; 16 bytes each in 2D) and its neighbour ranks.

Usage: mpirun -n N .venv/bin/python bench/bench_partition.py [n_bricks ...] [--method ptscotch]
"""
import argparse
import os
import resource
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
from fem_blocks.case import load_case  # noqa: E402
from fem_blocks.distributed import partition as dp  # noqa: E402
from fem_blocks.model import build_model  # noqa: E402

CASE = """name = "wall_{n}"
gravity = [0.0, -9.81]
[materials.brick]
E = 5e9
nu = 0.2
rho = 1800.0
thickness = 0.12
[wall]
type = "running_bond"
material = "brick"
brick_length = 0.25
brick_height = 0.06
courses = {courses}
bricks_per_course = {per}
mesh_size = 0.03
cell = "quad"
group = "bricks"
[wall.foundation]
depth = 0.2
overhang = 0.1
[[interfaces]]
name = "j"
between = ["bricks", "bricks"]
mu = 0.7
[[interfaces]]
name = "f"
between = ["bricks", "foundation"]
mu = 0.7
"""
STAGE = """[[stages]]
name = "g"
duration = 0.01
h = 1e-3
"""


def wall_case(n_bricks, directory, settings=STAGE):
    """The case file of the wall of about n_bricks bricks in `directory`: CASE, then `settings` (the [contact] table
    and the stages; bench_dist.py gives its own)."""
    per = max(2, int(round(np.sqrt(n_bricks * 0.25 / 0.5))))  # as bench_wall.build
    courses = max(1, int(round(n_bricks / per)))
    path = os.path.join(directory, f"wall_{n_bricks}.toml")
    with open(path, "w") as f:
        f.write(CASE.format(n=n_bricks, courses=courses, per=per) + settings)
    return path


def run(n_bricks, comm, method, show=True):
    with tempfile.TemporaryDirectory() as d:  # one case file per rank (the same text)
        path = wall_case(n_bricks, d)
        comm.Barrier()
        c = time.perf_counter()
        model = build_model(load_case(path))
        t_model = time.perf_counter() - c
    comm.Barrier()
    rp = dp.partition_model(model, comm, method)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    mine = (len(rp.owned), len(rp.ghost), rp.n_contacts, t_model, rp.timers["graph"], rp.timers["partition"],
            rp.timers["local"], rss, sum(len(v) for v in rp.send.values()), len(rp.send))
    rows = np.array(comm.gather(mine), dtype=float) if comm.size > 1 else np.array([mine], dtype=float)
    if comm.rank == 0 and show:
        mm = lambda k, f="{:.0f}": f.format(rows[:, k].min()) + "–" + f.format(rows[:, k].max())  # noqa: E731
        print(f"| {comm.size} | {len(model.bodies)} | {int(rows[:, 2].sum())} | {rp.graph_edges} | {rp.cut_edges} "
              f"({rp.edge_cut}) | {mm(0)} | {mm(1)} | {mm(2)} | {rows[:, 3].max():.1f} | {rows[:, 4].max():.2f} | "
              f"{rows[:, 5].max():.3f} | {rows[:, 6].max():.2f} | {mm(7)} | {mm(8)} ("
              f"{16 * rows[:, 8].min():.0f}–{16 * rows[:, 8].max():.0f} B) | {mm(9)} |", flush=True)


if __name__ == "__main__":
    from mpi4py import MPI
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sizes", nargs="*", type=int, default=[1000])
    ap.add_argument("--method", default="ptscotch")
    a = ap.parse_args()
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        print(f"method {a.method}\n\n| ranks | bodies | contacts | graph edges | edge cut: edges (contacts) | "
              "bodies per rank | ghosts per rank | contacts per rank | model [s] | graph [s] | partition [s] | "
              "local [s] | peak RSS per rank [MB] | interface contacts sent per rank per sweep (bytes, 2 doubles each) | "
              "neighbour ranks |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
              flush=True)
    run(20, comm, a.method, show=False)  # warm-up: numba compilation (cache) outside the timed runs
    for n in a.sizes:
        run(n, comm, a.method)
