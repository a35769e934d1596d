"""3D case files (`dimension = 3`) through the runner: closed forms (floor reaction = weight, platen reaction =
E A δ / L), resume after SIGKILL bitwise identical, 3D keys and their errors, the wall3d_push demo through the CLI.
2D cases are unchanged (tests/test_case.py, test_run_contact.py, test_resume.py)."""
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from fem_blocks.case import load_case, parse_case, quick
from fem_blocks.errors import InputError
from fem_blocks.output.checkpoint import read_checkpoint
from fem_blocks.output.history import read_history
from fem_blocks.runner import run_case

pytestmark = pytest.mark.dolfinx
from _paths import ROOT  # noqa: E402
FIXED = """x = {kind = "velocity", history = 0.0}
y = {kind = "velocity", history = 0.0}
z = {kind = "velocity", history = 0.0}
rx = {kind = "velocity", history = 0.0}
ry = {kind = "velocity", history = 0.0}
rz = {kind = "velocity", history = 0.0}
"""

# two 0.5 x 0.4 x 0.3 boxes stacked on a fixed floor; the upper one placed by a 180° rotation about z (x = R X + c)
STACK = """
name = "stack3d"
dimension = 3
gravity = [0.0, 0.0, -9.81]
[materials.stone]
E = 1e8
nu = 0.2
rho = 2000.0
[block_types.cube]
geometry = "box"
size = [0.5, 0.4, 0.3]
divisions = [1, 1, 1]
material = "stone"
[[blocks]]
name = "b0"
type = "cube"
position = [0.0, 0.0, 0.0]
[[blocks]]
name = "b1"
type = "cube"
position = [0.5, 0.4, 0.3]
rotation_axis = [0, 0, 1]
rotation_angle = 180
[[rigid_bodies]]
name = "floor"
size = [1.0, 1.0, 0.2]
origin = [-0.25, -0.25, -0.2]
group = "floor"
[rigid_bodies.drivers]
""" + FIXED + """
[contact]
tol = 1e-10
criterion = "residual"
max_sweeps = 20000
[[interfaces]]
between = ["blocks", "blocks"]
mu = 0.6
placement = "nodes"
[[interfaces]]
between = ["blocks", "floor"]
candidate = "blocks"
mu = 0.6
placement = "nodes"
[[stages]]
name = "gravity"
duration = 0.2
h = 0.01
theta = 1.0
velocity_reset = true
[stages.stop_at_equilibrium]
max_velocity = 1e-9
min_steps = 5
"""


def _case(tmp_path, text, name="case.toml"):
    p = tmp_path / name
    p.write_text(text)
    return load_case(str(p))


def test_stack_floor_reaction_equals_weight(tmp_path):
    """After the gravity stage the fixed floor's driver carries the weight W = 2 ρ V g (Rz = W to 1e-6) and its
    moment about the floor's centre (0.25, 0.25, -0.1) is that of W at the stack's axis (0.25, 0.2):
    Rrx = -0.05 W, Rry = 0, to 1e-6 W m; the other reactions vanish."""
    case = _case(tmp_path, STACK)
    assert case.dimension == 3 and case.gravity == (0.0, 0.0, -9.81)
    R = case.blocks[1].R
    assert np.allclose(R, np.diag([-1.0, -1.0, 1.0]), atol=1e-15)
    s = run_case(case, str(tmp_path / "out"), progress=False)
    assert s["status"] == "completed" and s["stages"][0]["stopped"].startswith("equilibrium")
    h = read_history(str(tmp_path / "out" / "history.csv"))
    W = 2 * 2000.0 * 0.5 * 0.4 * 0.3 * 9.81
    assert abs(h["floor.Rz"][-1] / W - 1) <= 1e-6
    assert abs(h["floor.Rrx"][-1] / (-0.05 * W) - 1) <= 1e-6
    assert max(abs(h[f"floor.R{d}"][-1]) for d in ("x", "y", "ry", "rz")) <= 1e-6 * W
    assert h["contacts"][-1] == 8 and h["converged"][-1] == 1
    for f in ("paraview/blocks.pvd", "paraview/contacts.pvd", "summary.json", "blocks.png", "checkpoint.npz"):
        assert (tmp_path / "out" / f).exists(), f


PLATEN = """
name = "platen3d"
dimension = 3
gravity = [0.0, 0.0, 0.0]
[materials.m]
E = 1e7
nu = 0.25
rho = 1000.0
[block_types.cube]
geometry = "box"
size = [1.0, 1.0, 1.0]
divisions = [2, 2, 2]
material = "m"
[[blocks]]
name = "block"
type = "cube"
position = [-0.5, -0.5, 0.0]
group = "block"
[[rigid_bodies]]
name = "floor"
size = [4.0, 4.0, 1.0]
origin = [-2.0, -2.0, -1.0]
group = "floor"
[rigid_bodies.drivers]
""" + FIXED + """
[[rigid_bodies]]
name = "platen"
corners = [[-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1], [-1, -1, 1.2], [1, -1, 1.2], [1, 1, 1.2], [-1, 1, 1.2]]
group = "platen"
[rigid_bodies.drivers]
""" + FIXED + """
[contact]
tol = 1e-10
criterion = "residual"
max_sweeps = 20000
check_every = 5
[[interfaces]]
between = ["block", "floor"]
candidate = "block"
mu = 0.0
[[interfaces]]
between = ["block", "platen"]
candidate = "block"
mu = 0.0
[[stages]]
name = "press"
duration = 0.4
h = 0.01
theta = 1.0
velocity_reset = true
output_every = 10
[stages.drivers.platen]
z = {kind = "displacement", history = {times = [0.0, 0.1, 1.0], values = [0.0, -1e-3, -1e-3]}}
"""


def test_driven_platen_reaction_is_E_A_delta_over_L(tmp_path):
    """Unit cube (2x2x2 Q1) between a fixed floor and a massless platen (8 corners) driven down by δ = 1 mm in a
    stage, frictionless, no gravity, quasi-static: homogeneous uniaxial stress, platen reaction Rz = E A δ / L
    to 1e-6 (tests/test_step3d.py, here through the case file and the runner); the stage driver gives the
    force-displacement curve."""
    case = _case(tmp_path, PLATEN)
    assert case.output["curve"] == dict(body="platen", force="z", displacement="z")
    s = run_case(case, str(tmp_path / "out"), progress=False)
    h = read_history(str(tmp_path / "out" / "history.csv"))
    F = 1e7 * 1.0 * 1e-3 / 1.0
    assert abs(-h["platen.Rz"][-1] / F - 1) <= 1e-6
    assert abs(h["platen.uz"][-1] + 1e-3) <= 1e-15
    assert max(abs(h[f"platen.R{d}"][-1]) for d in ("x", "y", "rx", "ry", "rz")) <= 1e-6 * F
    assert abs(h["floor.Rz"][-1] / F - 1) <= 1e-6
    assert h["contacts"][-1] == 32
    assert s["force_displacement"] == "force_displacement.png"
    assert (tmp_path / "out" / "force_displacement.png").exists()


# a free rigid box (6 dofs) on a deformable block on a fixed floor: gravity, then a force and a moment about z
# make it slide and turn on the block (rigid rotations, friction state, two time steps must survive a restart)
RESUME = STACK.replace('name = "stack3d"', 'name = "resume3d"').replace("max_sweeps = 20000", "max_sweeps = 3000").replace(
    "duration = 0.2\n", "duration = 0.05\n").replace("""[[rigid_bodies]]
name = "floor\"""", """[[rigid_bodies]]
name = "lid"
size = [0.3, 0.2, 0.1]
origin = [0.1, 0.1, 0.6]
rho = 2000.0
group = "lid"
[[rigid_bodies]]
name = "floor\"""").replace("""[[stages]]
name = "gravity\"""", """[[interfaces]]
between = ["lid", "blocks"]
candidate = "lid"
mu = 0.6
placement = "nodes"
[output]
checkpoint_every = 4
stress = false
[[stages]]
name = "gravity\"""").replace("""[stages.stop_at_equilibrium]
max_velocity = 1e-9
min_steps = 5
""", """[[stages]]
name = "push"
duration = 0.3
h = 0.0025
theta = 1.0
output_every = 7
[stages.forces.lid]
x = 75.0
rz = 4.0
""")
assert RESUME.count("duration = 0.05") == 1 and RESUME.count('name = "lid"') == 1 and RESUME.count("[output]") == 1 and 'name = "push"' in RESUME


def _launch(case, out):
    """`fem-blocks run CASE --out OUT --quiet` in a process of its own (to be killed)."""
    cmd = [sys.executable, "-m", "fem_blocks.cli", "run", str(case), "--out", str(out), "--quiet"]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)


def test_resume_3d_after_sigkill_is_bitwise_identical(tmp_path, cli):
    """A 3D run killed (SIGKILL) after its checkpoint at step >= 30 and resumed gives bitwise the same history and
    final state (rigid orientation included) as an uninterrupted run (the approach of tests/test_resume.py). The
    killed run is a process of its own; the reference and the resume run in this one (conftest.cli)."""
    path = tmp_path / "case.toml"
    path.write_text(RESUME)
    ref = tmp_path / "ref"
    s = run_case(load_case(str(path)), str(ref), progress=False)
    assert s["status"].startswith("completed") and s["steps"] == 5 + 120  # (its gravity steps end above 1e-10)
    out = tmp_path / "killed"
    proc = _launch(path, out)
    t0, step = time.monotonic(), None
    while time.monotonic() - t0 < 120 and proc.poll() is None:
        try:
            step = int(read_checkpoint(out / "checkpoint.npz")["sim.step"])
        except Exception:  # noqa: BLE001 - not written yet, or being replaced
            step = None
        if step is not None and step >= 30:
            break
        time.sleep(0.005)
    assert proc.poll() is None, "the run ended before the kill"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert int(read_checkpoint(out / "checkpoint.npz")["sim.step"]) < 125  # killed mid-run
    p = cli("run", path, "--out", out, "--quiet", "--resume")
    assert p.returncode == s["exit_status"], p.stderr  # 3: completed with unconverged (gravity) steps
    assert (out / "history.csv").read_text() == (ref / "history.csv").read_text()
    assert json.loads((out / "summary.json").read_text())["convergence"] == s["convergence"]  # across the resume
    a, b = read_checkpoint(out / "checkpoint.npz"), read_checkpoint(ref / "checkpoint.npz")
    keys = sorted(k for k in a if k.startswith(("sim.", "contact.")))
    assert keys == sorted(k for k in b if k.startswith(("sim.", "contact.")))
    assert any(k.endswith(".orientation") for k in keys)
    for k in keys:
        assert np.array_equal(a[k], b[k]), k
    lid = [k for k in keys if k.endswith(".orientation")][0]
    assert abs(np.arctan2(a[lid][1, 0], a[lid][0, 0])) > 1e-3  # the lid did turn about z
    h = read_history(str(ref / "history.csv"))
    assert 0.01 < h["lid.ux"][-1] < 0.15 and abs(h["lid.urz"][-1]) > 0.05  # and slid, staying on the block


def test_quick_halves_divisions_and_3d_keys(tmp_path):
    case = quick(_case(tmp_path, PLATEN))
    assert case.block_types["cube"].divisions == (1, 1, 1) and case.stages[0].h == 0.02
    with pytest.raises(InputError, match=r"blocks\[0\].angle: not used in dimension 3"):
        parse_case({**_toml(STACK), "blocks": [{"type": "cube", "angle": 10.0}]}, "x.toml")
    two_d = _toml(STACK)
    del two_d["dimension"]
    with pytest.raises(InputError, match=r"gravity: expected a list of 2 finite numbers"):
        parse_case(two_d, "x.toml")


def _toml(text):
    import tomllib
    return tomllib.loads(text)


def test_wall3d_push_quick_through_the_cli(tmp_path):
    """demos/wall3d_push.toml --quick through the CLI: the push stops at its target displacement, the
    foundation carries the weight of the 14 bricks + the beam after the gravity stage (to 1e-6), outputs written.
    Every step converges (the demo redoes the first push steps, where sliding starts, as sub-steps: without it 4 of
    the 30 push steps ended at ≈ 3e-6 > 1e-8), so the CLI exits 0."""
    from fem_blocks.cli import main
    out = tmp_path / "wp"
    rc = main(["run", os.path.join(ROOT, "demos", "wall3d_push.toml"), "--out", str(out), "--quick", "--quiet"])
    s = json.loads((out / "summary.json").read_text())
    h = read_history(str(out / "history.csv"))
    n_bad = int(np.sum(h["converged"][1:] == 0))
    assert rc == 0 and n_bad == 0 and s["convergence"]["unconverged_steps"] == 0
    assert s["status"].startswith("completed") and s["stages"][1]["stopped"].startswith("target displacement 0.003")
    g = int(np.flatnonzero(h["stage"] == 0)[-1])
    W = 9.81 * (2000.0 * 0.75 * 0.12 * 4 * 0.065 + 7800.0 * 0.75 * 0.12 * 0.1)
    assert abs(h["foundation.Rz"][g] / W - 1) <= 1e-6
    assert s["n_bodies"] == 14 + 2
    for f in ("paraview/blocks.pvd", "paraview/contacts.pvd", "blocks.png", "force_displacement.png"):
        assert (out / f).exists(), f


def test_3d_block_types_file_hexahedron_box_and_rotation(tmp_path):
    """The three 3D block-type geometries through build_model: a .geo file (tetrahedra), 8 corners (a sheared
    hexahedron), a tetrahedral box; the lumped mass of each instance is ρV (to 1e-12), and the placement
    x = R X + c with R = 90° about x maps the file's box [0, .3] x [0, .2] x [0, .1] onto
    [0, .3] x [-.1, 0] x [0, .2] + c (to 1e-15)."""
    from fem_blocks.model import build_model
    (tmp_path / "box.geo").write_text('SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 0.3, 0.2, 0.1};\n'
                                      'Physical Surface("xmin") = {1};\nPhysical Volume("block") = {1};\n')
    text = """dimension = 3
[materials.m]
E = 1e9
nu = 0.2
rho = 1000.0
[block_types.f]
geometry = "file"
file = "box.geo"
mesh_size = 0.1
material = "m"
[block_types.h]
geometry = "hexahedron"
corners = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.2, 0, 1], [1.2, 0, 1], [1.2, 1, 1], [0.2, 1, 1]]
divisions = [2, 2, 2]
material = "m"
[block_types.b]
geometry = "box"
size = [0.5, 0.5, 0.5]
mesh_size = 0.25
cell = "tetrahedron"
material = "m"
[[blocks]]
type = "f"
position = [5.0, 0.0, 0.0]
rotation_axis = [2.0, 0.0, 0.0]
rotation_angle = 90.0
[[blocks.clamps]]
tag = "xmin"
[[blocks]]
type = "h"
position = [0.0, 0.0, 0.0]
[[blocks]]
type = "b"
position = [0.0, 3.0, 0.0]
[[stages]]
duration = 0.01
h = 0.01
"""
    model = build_model(_case(tmp_path, text))
    f, h, b = model.bodies
    assert f.type.mesh.cell_type == "tetrahedron" and h.type.mesh.cells.shape == (8, 8)
    assert b.type.mesh.cells.shape == (6 * 8, 4)
    for body, V in ((f, 0.3 * 0.2 * 0.1), (h, 1.0), (b, 0.125)):
        assert abs(body.type.M.diagonal().sum() / 3 / (1000.0 * V) - 1) <= 1e-12
    X = f.reference_points
    assert np.allclose([X.min(axis=0), X.max(axis=0)], [[5.0, -0.1, 0.0], [5.3, 0.0, 0.2]], rtol=0, atol=1e-15)
    on_xmin = np.flatnonzero(np.abs(f.type.mesh.points[:, 0]) <= 1e-12)  # the clamped face x = 0 (type frame)
    assert on_xmin.size >= 4 and np.array_equal(np.flatnonzero(f.clamped), np.sort(np.r_[3 * on_xmin,
                                                                                         3 * on_xmin + 1,
                                                                                         3 * on_xmin + 2]))
