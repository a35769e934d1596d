"""Rotation of deformable blocks as output (`[output] rotations` -> history.csv NAME.rot, 3D NAME.rotx/roty/rotz)
and the warning of a linear-kinematics run whose block rotates beyond the small-rotation bound (runner.py
_RotationWatch, docs/case-files.md "Warnings", docs/validation.md "Rotating blocks").

`body.rotation()` of a block without a frame is the mass-weighted best-fit small rotation of its displacement
field (BlockType.rotation_weights): for a displacement field that IS a small rigid motion, q = θ × (x − c) + t
(c any point), it returns θ exactly, whatever the translation, the placement of the block and the mass matrix."""
import json
import os

import numpy as np
import pytest

from fem_blocks.bodies import (BlockType, BlockType3D, DeformableBody, DeformableBody3D, Material, rotation,
                               rotation3d)
from fem_blocks.case import load_case
from fem_blocks.meshing import mesh_box, mesh_rectangle
from fem_blocks.runner import SMALL_ROTATION, convergence_line, run_case

pytestmark = pytest.mark.dolfinx
MAT = Material(E=1e9, nu=0.2, rho=2000.0, thickness=0.1)


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_rotation_of_a_small_rigid_motion_2d(mass):
    """Block 0.3 x 0.1 (P1 triangles) placed at 0.4 rad, position (1, 2); global field q = θ e_z × (x − p) + t with
    θ = 3e-3, p = (5, -1) (not the centre: the translation part differs) and t = (0.02, -0.01): rotation() = θ to
    1e-12 relative. A translation alone gives 0 to 1e-15 (catches a mass centre left out or taken wrong)."""
    bt = BlockType(mesh_rectangle(0.3, 0.1, 0.04), MAT, mass=mass)
    b = DeformableBody(bt, (1.0, 2.0), angle=0.4)
    x = b.reference_points
    th, p, t = 3e-3, np.array([5.0, -1.0]), np.array([0.02, -0.01])
    qg = th * np.column_stack([-(x[:, 1] - p[1]), x[:, 0] - p[0]]) + t
    b.q[:] = (qg @ b.R).ravel()  # type frame: R^T per node
    assert b.rotation() == pytest.approx(th, rel=1e-12)
    b.q[:] = (np.tile(t, (len(x), 1)) @ b.R).ravel()
    assert abs(b.rotation()) < 1e-15
    b.q[:] = (-qg @ b.R).ravel()  # sign: clockwise is negative
    assert b.rotation() == pytest.approx(-th, rel=1e-12)


def test_rotation_of_a_small_rigid_motion_3d():
    """Box 0.3 x 0.2 x 0.1 (hexahedra) placed by a skew rotation; global field q = φ × (x − p) + t with the rotation
    vector φ = (1, -2, 3) 1e-3: rotation() = φ in the global frame to 1e-12 (catches a rotation vector left in the
    type frame, or the inertia tensor replaced by its trace)."""
    bt = BlockType3D(mesh_box(0.3, 0.2, 0.1, divisions=(3, 2, 1)), MAT)
    R = rotation3d(np.array([0.3, -0.5, 0.7]))
    b = DeformableBody3D(bt, (1.0, 2.0, 3.0), R)
    x = b.reference_points
    phi, p, t = np.array([1.0, -2.0, 3.0]) * 1e-3, np.array([0.5, 4.0, -1.0]), np.array([0.01, 0.02, -0.03])
    qg = np.cross(phi, x - p) + t
    b.q[:] = (qg @ R).ravel()
    np.testing.assert_allclose(b.rotation(), phi, rtol=0, atol=1e-12 * np.linalg.norm(phi))


CASE = """
name = "turned"
[materials.m]
E = 1e9
nu = 0.2
rho = 2000.0
thickness = 0.1
[block_types.b]
geometry = "rectangle"
lx = 0.2
ly = 0.1
mesh_size = 0.1
material = "m"
[[blocks]]
type = "b"
name = "brick"
group = "bricks"
position = [-0.1, 0.0]
[[rigid_bodies]]
name = "table"
group = "table"
vertices = [[-0.3, -0.05], [0.3, -0.05], [0.3, 0.0], [-0.3, 0.0]]
[rigid_bodies.drivers]
x = {kind = "velocity", history = 0.0}
y = {kind = "velocity", history = 0.0}
rz = {kind = "displacement", history = {times = [0.0, 0.05], values = [0.0, ANGLE]}}
[[interfaces]]
between = ["bricks", "table"]
mu = 1.0
[contact]
geometry = "frozen"
[output]
paraview = false
crack_pattern = false
rotations = ["bricks"]
[[stages]]
duration = 0.06
h = 0.002
theta = 1.0
"""


def _turn(tmp_path, angle, capsys):
    """A brick (E = 1e9, 0.2 x 0.1 m) on a rigid table driven in rotation about its centre by `angle` over 0.05 s,
    frozen geometry, friction 1: the brick turns with the table. Returns (summary, history columns, stderr)."""
    p = tmp_path / "turned.toml"
    p.write_text(CASE.replace("ANGLE", repr(angle)))
    s = run_case(load_case(str(p)), str(tmp_path / "out"), progress=False)
    from fem_blocks.output.history import read_history
    return s, read_history(str(tmp_path / "out" / "history.csv")), capsys.readouterr().err


def test_block_turned_past_the_bound_in_frozen_geometry_warns_once(tmp_path, capsys):
    """Table turned by 0.012 rad: the brick's history column brick.rot follows the table's urz (the brick sticks:
    within 1e-4 rad, the transients when the table starts and stops: 7.5e-5 observed; 5e-8 in between), and the
    run warns once, at the first step where
    |θ| > 0.01 rad, naming the brick, the time and the angle: on stderr, in summary.json "warnings" and "rotation",
    and before the CLI's last line. The step is the first history row with brick.rot > 0.01 (read back from the
    file, not from the watch)."""
    s, h, err = _turn(tmp_path, 0.012, capsys)
    assert SMALL_ROTATION == 0.01
    np.testing.assert_allclose(h["brick.rot"], h["table.urz"], rtol=0, atol=1e-4)
    k = int(np.flatnonzero(np.abs(h["brick.rot"]) > 0.01)[0])
    first = s["rotation"]["first"]
    assert first["block"] == "brick" and first["step"] == int(h["step"][k])
    assert first["time"] == pytest.approx(h["time"][k], rel=1e-12) and first["rad"] == pytest.approx(h["brick.rot"][k])
    assert s["rotation"]["blocks_beyond"] == ["brick"]
    assert s["rotation"]["max_rad"] == pytest.approx(np.abs(h["brick.rot"]).max(), rel=1e-12)
    text = f"block 'brick' rotated by {h['brick.rot'][k]:.4g} rad at t = {h['time'][k]:.6g} s"
    assert err.count("small-rotation bound") == 1 and text in err
    assert sum(text in w for w in s["warnings"]) == 1
    last = convergence_line(s["convergence"]).splitlines()
    assert len(last) == 2 and text in last[0] and last[1].startswith("fem-blocks: contact solver: all")
    on_disk = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert on_disk["rotation"]["first"]["step"] == first["step"]


def test_block_turned_within_the_bound_does_not_warn(tmp_path, capsys):
    """The same run to 0.005 rad: no warning anywhere; the record's largest rotation is the column's."""
    s, h, err = _turn(tmp_path, 0.005, capsys)
    assert "small-rotation" not in err and not any("small-rotation" in w for w in s["warnings"])
    assert s["rotation"]["first"] is None and s["rotation"]["blocks_beyond"] == []
    assert s["rotation"]["max_rad"] == pytest.approx(np.abs(h["brick.rot"]).max(), rel=1e-12)
    assert 0.0049 < s["rotation"]["max_rad"] < 0.0051
    assert len(convergence_line(s["convergence"]).splitlines()) == 1


def test_rotation_columns_3d_names():
    """3D: one column per component of the rotation vector, named NAME.rotx/roty/rotz, for the blocks of a group."""
    from types import SimpleNamespace
    from fem_blocks.runner import history_columns, rotation_bodies
    model = SimpleNamespace(names=["a", "b", "base"], groups=["g", "g", "rigid"],
                            dofs=("x", "y", "z", "rx", "ry", "rz"), contact=None,
                            bodies=[SimpleNamespace(kind=0), SimpleNamespace(kind=0), SimpleNamespace(kind=1)])
    case = SimpleNamespace(output=dict(rotations=["b", "g"]), source="c.toml")
    ids = rotation_bodies(case, model)
    assert ids == [0, 1]
    cols = history_columns(model, ids)
    assert cols[-6:] == ["a.rotx", "a.roty", "a.rotz", "b.rotx", "b.roty", "b.rotz"]


@pytest.mark.parametrize("dim", [2, 3])
def test_rotation_weights_are_the_small_rotation_of_the_bodies(dim):
    """BlockType.rotation_weights() (one product per block type, the runner's warning) is body.rotation()'s best-fit
    small rotation (_PlacedBlock._small_rotation) as a linear map: equal to 1e-13 for random fields q (catches the
    two definitions drifting apart, e.g. a sign or a component order)."""
    rng = np.random.default_rng(3)
    if dim == 2:
        b = DeformableBody(BlockType(mesh_rectangle(0.3, 0.1, 0.04), MAT), (1.0, 2.0), angle=0.4)
    else:
        b = DeformableBody3D(BlockType3D(mesh_box(0.3, 0.2, 0.1, divisions=(3, 2, 1)), MAT), (1.0, 2.0, 3.0),
                             rotation3d(np.array([0.3, -0.5, 0.7])))
    for _ in range(3):
        b.q[:] = rng.standard_normal(b.q.size) * 1e-3
        th = b._small_rotation()
        np.testing.assert_allclose(b.type.rotation_weights() @ b.q, th, rtol=0, atol=1e-13 * np.abs(th).max())


def test_resumed_run_keeps_the_rotation_record_and_does_not_warn_again(tmp_path, capsys):
    """The watch's record is part of the checkpoint (run.json): the run turned to 0.012 rad, resumed (--force) with a
    second stage holding the table, reports the same first crossing in its summary, once, and prints no new
    warning line while it steps (catches a record lost on resume: the warning would be repeated at the first step
    of the resumed run, with its time)."""
    s1, _, err1 = _turn(tmp_path, 0.012, capsys)
    assert err1.count("small-rotation bound") == 1
    p = tmp_path / "turned.toml"
    p.write_text(CASE.replace("ANGLE", "0.012") + "[[stages]]\nduration = 0.01\nh = 0.002\ntheta = 1.0\n")
    s2 = run_case(load_case(str(p)), str(tmp_path / "out"), progress=False, resume=True, force=True)
    err2 = capsys.readouterr().err
    assert s2["steps"] == s1["steps"] + 5
    assert "small-rotation bound" not in err2
    assert s2["rotation"]["first"] == s1["rotation"]["first"]
    assert sum("small-rotation bound" in w for w in s2["warnings"]) == 1


def test_rotation_columns_of_a_3d_run(tmp_path):
    """A 3D case (tests/test_case3d.STACK: two blocks settling on a floor under gravity) with `rotations =
    ["blocks"]`: history.csv has b0.rotx/roty/rotz and b1.rotx/roty/rotz, finite and small (settlement: < 1e-3 rad),
    and the watch's largest |θ| over the run is at least the norm of every row's rotation vector (the same
    best-fit rotation: the norm of body.rotation() is |θ| for a block without frame)."""
    import sys
    sys.path.insert(0, os.path.dirname(__file__))
    from test_case3d import STACK
    from fem_blocks.output.history import read_history
    p = tmp_path / "s.toml"
    p.write_text(STACK.replace("[contact]\n", "[output]\nparaview = false\nrotations = [\"blocks\"]\n[contact]\n", 1))
    s = run_case(load_case(str(p)), str(tmp_path / "out"), progress=False)
    h = read_history(str(tmp_path / "out" / "history.csv"))
    cols = [f"{b}.rot{c}" for b in ("b0", "b1") for c in "xyz"]
    assert all(c in h for c in cols)
    rot = np.array([h[c] for c in cols]).T.reshape(-1, 2, 3)  # (rows, block, xyz)
    norm = np.linalg.norm(rot, axis=2)
    assert np.all(np.isfinite(rot)) and norm.max() < 1e-3 and norm.max() > 0
    assert s["rotation"]["max_rad"] == pytest.approx(norm.max(), rel=1e-9)


def test_check_rejects_an_unknown_rotation_name(tmp_path):
    """`fem-blocks check` matches `[output] rotations` to the built blocks as a run does (a name missing in the
    model is the same one-line error)."""
    from fem_blocks.check import check_case
    from fem_blocks.errors import InputError
    p = tmp_path / "c.toml"
    p.write_text(CASE.replace("ANGLE", "0.005").replace('rotations = ["bricks"]', 'rotations = ["table"]'))
    with pytest.raises(InputError, match=r"c\.toml: output\.rotations: 'table': expected the name of a deformable "
                                         r"block or of a group of blocks \('bricks', \.\.\.\); a rigid body's rotation "
                                         r"is already the history column NAME\.urz"):
        check_case(str(p))
    p.write_text(CASE.replace("ANGLE", "0.005"))
    check_case(str(p))
