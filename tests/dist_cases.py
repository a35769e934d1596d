"""Small cases for the runs on several MPI ranks (tests/test_dist_run.py) and the driver that runs them under
mpirun: `mpirun -n N python tests/dist_cases.py DIR NAME...` runs `fem-blocks run DIR/NAME.toml --out DIR/NAME.N`
for each NAME on the N ranks of one launch (cli._main with COMM_WORLD, as `mpirun fem-blocks run` does) and writes
DIR/codes.N.json: the exit status of every rank for every case."""
import json
import os
import sys

WALL = """name = "{name}"
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
{joint}
[[interfaces]]
name = "f"
between = ["bricks", "foundation"]
mu = 0.7
[contact]
order = "colours"
tol = {tol}
max_sweeps = {max_sweeps}
on_nonconvergence = "{policy}"
[output]
paraview = {paraview}
checkpoint_every = {ck}
[[stages]]
name = "g"
duration = {duration}
h = 1e-3
theta = 1.0
velocity_reset = true
"""

DRY = 'mu = 0.7'
MIXED = ('law = "mixed"\nk_n = 82e9\nk_s = 36e9\nf_t = 0.25e6\nc = 0.35e6\nG_I = 18.0\nG_II = 125.0\n'
         'tan_phi = 0.75')

WALL3D = """name = "{name}"
dimension = 3
gravity = [0.0, 0.0, -9.81]
[materials.brick]
E = 5.0e9
nu = 0.2
rho = 2000.0
[wall3d]
material = "brick"
courses = 2
bricks_per_course = 2
brick_length = 0.25
brick_width = 0.12
brick_height = 0.065
joint = 0.0
half_bricks = true
divisions = [2, 1, 1]
group = "bricks"
[wall3d.foundation]
depth = 0.1
overhang = 0.05
[contact]
order = "colours"
tol = 1e-4
max_sweeps = 300
[[interfaces]]
name = "joints"
between = ["bricks", "bricks"]
mu = 0.7
placement = "nodes"
[[interfaces]]
name = "foundation"
between = ["bricks", "foundation"]
candidate = "bricks"
mu = 0.7
placement = "nodes"
[output]
paraview = false
[[stages]]
name = "gravity"
duration = 0.03
h = 0.01
theta = 1.0
velocity_reset = true
"""


READERS = """[output]
joints = [["brick0", "brick4"], ["brick20", "brick21"]]
joints_paraview = true
rotations = ["brick3", "brick18"]
gauges = [{name = "low", block = "brick0", point = [0.1, 0.03]},
          {name = "high", block = "brick21", point = [0.85, 0.27]}]
"""


def wall(name, courses=3, per=2, joint=DRY, tol=1e-5, max_sweeps=400, policy="warn", paraview="false", ck=0,
         duration=0.004):
    return WALL.format(name=name, courses=courses, per=per, joint=joint, tol=tol, max_sweeps=max_sweeps,
                       policy=policy, paraview=paraview, ck=ck, duration=duration)


CASES = {
    "dry": wall("dry", paraview="true"),
    "mixed": wall("mixed", joint=MIXED),
    "wall3d": WALL3D.format(name="wall3d").replace("paraview = false", "paraview = true"),
    "one_brick": wall("one_brick", courses=1, per=1, paraview="true"),  # 2 bodies: on 3 ranks one rank owns none
    "fail": wall("fail", max_sweeps=3, policy="fail"),          # stopped by the solver policy: exit 1 on every rank
    "bad": wall("bad").replace("mu = 0.7\n[contact]", "mu = -0.7\n[contact]"),  # invalid: exit 2 on every rank
    "long": wall("long", ck=2, duration=0.012, paraview="true"),  # checkpoints every 2 steps (the resume test)
    "newton": wall("newton").replace('order = "colours"', 'solver = "newton"\ncriterion = "residual"')
                            .replace("tol = 1e-05", "tol = 1e-08"),  # the Newton's linear solves shared by the ranks
    "guard": wall("guard").replace("[contact]", "[checks]\nmax_penetration = 1e-9\n[contact]", 1),  # a run check stops
    # the joints' outputs from the gathered record, the outputs that read one body at every step (gauges, rotations)
    # on a wall large enough for each rank to leave bodies unstepped (dynamics.py "Bodies stepped per rank"); its
    # last checkpoint holds the partition
    "joints": wall("joints", courses=5, per=4, joint=MIXED, tol=1e-4, max_sweeps=2000, paraview="true",
                   ck=2).replace("[output]\n", READERS, 1),
}


def write_cases(d, names):
    for n in names:
        with open(os.path.join(d, f"{n}.toml"), "w") as f:
            f.write(CASES[n])


if __name__ == "__main__":
    from mpi4py import MPI
    from fem_blocks import cli
    d, names = sys.argv[1], sys.argv[2:]
    comm = MPI.COMM_WORLD
    size = comm.Get_size()
    resume = "--resume" in names
    names = [n for n in names if n != "--resume"]
    codes = {}
    for n in names:
        argv = ["run", os.path.join(d, f"{n}.toml"), "--out", os.path.join(d, f"{n}.{size}"), "--quiet"]
        codes[n] = comm.gather(cli._main(argv + (["--resume"] if resume else []), comm), root=0)
    if comm.Get_rank() == 0:
        with open(os.path.join(d, f"codes.{size}{'.resume' if resume else ''}.json"), "w") as f:
            json.dump(codes, f)
