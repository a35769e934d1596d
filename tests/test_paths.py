"""Paths no other test ran: foundation keys (overhang, split, settlement), the dome's pier_group, rigid-body inertia
and moments in mm-N-MPa, clockwise rigid polygons, a step with no contact, the CLI's exit status 1,
DeformableBody.velocity_global (the NaN guards on displacements and contact impulses: tests/test_guards.py).
Expectations from closed forms or hand computations."""
import json
import math
import os

import numpy as np
import pytest

from fem_blocks.bodies import BlockType, DeformableBody, Material, RigidBody
from fem_blocks.case import load_case, parse_case
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.expand import expand
from fem_blocks.meshing import mesh_rectangle
from fem_blocks.model import build_model
from fem_blocks.output.history import read_history
from fem_blocks.runner import run_case

pytestmark = pytest.mark.dolfinx
from test_run_contact import CASE  # noqa: E402  (3-brick prism on a foundation, gravity to equilibrium)

from _paths import ROOT  # noqa: E402

SETTLE = """
name = "settle"
[materials.brick]
E = 5e9
nu = 0.2
rho = 2000.0
thickness = 0.1
[wall]
type = "running_bond"
material = "brick"
brick_length = 0.2
brick_height = 0.05
courses = 2
bricks_per_course = 3
half_bricks = true
mesh_size = 0.1
[wall.foundation]
depth = 0.05
overhang = 0.03
split = [0.25]
[wall.foundation.settlement]
part = 1
history = {times = [0.0, 0.01, 1.0], values = [0.0, 0.0, -2e-3]}
[contact]
tol = 1e-8
max_sweeps = 200000
[[interfaces]]
between = ["bricks", "bricks"]
mu = 0.6
placement = "nodes"
[[interfaces]]
between = ["bricks", "foundation"]
mu = 0.6
placement = "nodes"
[[stages]]
duration = 0.03
h = 0.01
theta = 1.0
velocity_reset = true
"""


def test_foundation_overhang_split_and_settlement(tmp_path):
    """[wall.foundation] overhang, split and settlement: two rigid parts spanning [x0 - o, cut] and [cut, x1 + o]
    under the wall, top face at the wall's base; the settling part follows its history exactly, the other stays."""
    p = tmp_path / "settle.toml"
    p.write_text(SETTLE)
    case = expand(load_case(str(p)))
    rigid = {r.name: np.asarray(r.vertices) for r in case.rigid_bodies}
    assert sorted(rigid) == ["foundation0", "foundation1"]
    f0, f1 = rigid["foundation0"], rigid["foundation1"]
    assert (f0[:, 0].min(), f0[:, 0].max()) == pytest.approx((-0.03, 0.25), abs=1e-12)
    assert (f1[:, 0].min(), f1[:, 0].max()) == pytest.approx((0.25, 0.63), abs=1e-12)  # 3 bricks = 0.6 m + 0.03
    for f in (f0, f1):
        assert (f[:, 1].min(), f[:, 1].max()) == pytest.approx((-0.05, 0.0), abs=1e-12)
    s = run_case(case, str(tmp_path / "out"), progress=False)
    assert s["status"] == "completed"
    h = read_history(tmp_path / "out" / "history.csv")
    t = np.asarray(h["time"])
    expected = np.interp(t, [0.0, 0.01, 1.0], [0.0, 0.0, -2e-3])
    assert np.abs(np.asarray(h["foundation1.uy"]) - expected).max() <= 1e-15
    assert np.all(np.asarray(h["foundation0.uy"]) == 0.0)


def test_dome_pier_group_names_the_piers():
    """[dome] pier_group: the piers are rigid bodies of that group, and interfaces refer to it."""
    import tomllib
    path = os.path.join(ROOT, "demos", "dome.toml")
    with open(path, "rb") as f:
        data = tomllib.load(f)
    old = data["dome"].get("pier_group", "piers")
    data["dome"]["pier_group"] = "supports"
    for itf in data["interfaces"]:
        itf["between"] = ["supports" if g == old else g for g in itf["between"]]
        if itf.get("candidate") == old:
            itf["candidate"] = "supports"
    case = expand(parse_case(data, path))
    piers = [r for r in case.rigid_bodies if r.group == "supports"]
    assert len(piers) >= 1 and not [r for r in case.rigid_bodies if r.group == old]
    assert any("supports" in i.groups for i in case.interfaces)


RIGID_MM = """
name = "rigid_units"
units = "%s"
gravity = [0.0, 0.0]
[[rigid_bodies]]
name = "r"
vertices = [[0.0, 0.0], [%r, 0.0], [%r, %r], [0.0, %r]]
mass = %r
inertia = %r
[rigid_bodies.forces]
rz = %r
[[stages]]
duration = 0.5
h = 0.1
"""


def test_rigid_mass_inertia_and_moment_in_mm_N_MPa(tmp_path):
    """The same free rigid plate in SI and in mm-N-MPa (mass in t, inertia in t mm², moment in N mm): the same body
    and, under a constant moment M, the same rotation φ(t) = M t²/(2 I) (θ = 1/2 exact for a constant force)."""
    L, m, inertia, M = 0.4, 50.0, 0.7, 3.0
    si = (tmp_path / "si.toml", RIGID_MM % ("SI", L, L, L, L, m, inertia, M))
    mm = (tmp_path / "mm.toml", RIGID_MM % ("mm-N-MPa", L * 1e3, L * 1e3, L * 1e3, L * 1e3, m * 1e-3, inertia * 1e3,
                                             M * 1e3))
    rot = {}
    for p, text in (si, mm):
        p.write_text(text)
        case = load_case(str(p))
        body = build_model(case).bodies[0]
        assert body.mass == pytest.approx([m, m, inertia], rel=1e-12)
        assert body.forces[2](0.3) == pytest.approx(M, rel=1e-12)
        run_case(case, str(tmp_path / p.stem), progress=False)
        rot[p.stem] = np.asarray(read_history(tmp_path / p.stem / "history.csv")["r.urz"])
    t = np.arange(1, 6) * 0.1
    np.testing.assert_allclose(rot["si"][-5:], M * t ** 2 / (2 * inertia), rtol=1e-12)
    np.testing.assert_allclose(rot["mm"], rot["si"], rtol=1e-12)


RIGID3D = """
name = "rigid3d_inertia"
units = "mm-N-MPa"
dimension = 3
gravity = [0.0, 0.0, 0.0]
[[rigid_bodies]]
name = "r"
size = [400.0, 300.0, 200.0]
origin = [0.0, 0.0, 0.0]
mass = 0.05
inertia = [2000.0, 3000.0, 4000.0]
[rigid_bodies.forces]
rz = 8000.0
[[stages]]
duration = 0.4
h = 0.1
"""


def test_3d_rigid_inertia_key_reaches_the_body(tmp_path):
    """`inertia = [Ixx, Iyy, Izz]` of a 3D rigid body (t mm²) is the body's inertia (kg m²), not the box's own,
    and a moment about z (N mm) turns it at M t²/(2 Izz)."""
    p = tmp_path / "r3.toml"
    p.write_text(RIGID3D)
    case = load_case(str(p))
    body = build_model(case).bodies[0]
    assert body.mass == pytest.approx(50.0, rel=1e-12)
    np.testing.assert_allclose(body.inertia0, np.diag([2.0, 3.0, 4.0]), rtol=1e-12, atol=0)
    run_case(case, str(tmp_path / "out"), progress=False)
    urz = np.asarray(read_history(tmp_path / "out" / "history.csv")["r.urz"])
    t = np.arange(1, 5) * 0.1
    np.testing.assert_allclose(urz[-4:], 8.0 * t ** 2 / (2 * 4.0), rtol=1e-10)


def test_clockwise_rigid_polygon_is_the_same_body():
    """Vertices given clockwise describe the same polygon: same mass, inertia and centre as counter-clockwise,
    and a block resting on it carries its weight (contact detection needs the counter-clockwise boundary)."""
    V = np.array([[0.0, 0.0], [0.6, 0.0], [0.6, 0.1], [0.0, 0.1]])
    a = RigidBody(V, rho=2000.0, thickness=0.1)
    b = RigidBody(V[::-1], rho=2000.0, thickness=0.1)
    np.testing.assert_allclose(b.mass, a.mass, rtol=1e-14)
    np.testing.assert_allclose(b.center, [0.3, 0.05], rtol=1e-14)
    m = 2000.0 * 0.6 * 0.1 * 0.1
    assert a.mass[0] == pytest.approx(m, rel=1e-14) and a.mass[2] == pytest.approx(m * (0.36 + 0.01) / 12, rel=1e-12)
    # a rigid block resting on a fixed clockwise floor: floor reaction = weight
    floor = RigidBody(V[::-1] - [0.0, 0.1], thickness=0.1, drivers={k: ("velocity", 0.0) for k in ("x", "y", "rz")})
    blk = RigidBody([[0.1, 0.0], [0.5, 0.0], [0.5, 0.2], [0.1, 0.2]], rho=2000.0, thickness=0.1)
    cs = ContactStep([InterfaceSpec("j", ("a", "b"), mu=0.5)], ["b", "a"], ContactOptions(tol=1e-12, max_sweeps=1000))
    sim = Simulation([floor, blk], h=1e-3, theta=1.0, velocity_reset=True, contact=cs)
    for _ in range(3):
        sim.step()
    W = 2000.0 * 0.4 * 0.2 * 0.1 * 9.81
    assert floor.reaction[1] == pytest.approx(W, rel=1e-9)  # the driver holds the floor up against the block's weight
    assert abs(blk.q[1]) < 1e-9


def test_step_with_no_contact_is_free_flight():
    """Two blocks far apart: detection finds nothing, the step runs with no contact and a rigid body falls as
    q = -g t²/2 (θ = 1/2 exact for constant gravity)."""
    blk = RigidBody([[0, 0], [0.2, 0], [0.2, 0.1], [0, 0.1]], rho=2000.0, thickness=0.1)
    far = RigidBody([[5, 0], [5.2, 0], [5.2, 0.1], [5, 0.1]], rho=2000.0, thickness=0.1)
    cs = ContactStep([InterfaceSpec("j", ("a", "a"), mu=0.5)], ["a", "a"], ContactOptions(tol=1e-12))
    sim = Simulation([blk, far], h=1e-2, theta=0.5, contact=cs)
    for _ in range(10):
        info = sim.step()
        assert info.contact.get("contacts", 0) == 0
    assert blk.q[1] == pytest.approx(-0.5 * 9.81 * 0.1 ** 2, rel=1e-12)


def test_cli_exit_status_1_on_policy_fail(tmp_path, cli):
    """`on_nonconvergence = "fail"`: the CLI exits 1 after writing the outputs, with the reason on stderr."""
    text = CASE.replace("tol = 1e-10\nmax_sweeps = 100000", 'tol = 1e-12\nmax_sweeps = 2\non_nonconvergence = "fail"')
    p = tmp_path / "c.toml"
    p.write_text(text)
    out = tmp_path / "out"
    r = cli("run", p, "--out", out, "--quiet")  # in this process (conftest.cli): an uncaught error would raise
    assert r.returncode == 1, r.stderr
    assert "did not converge" in r.stderr
    assert json.loads((out / "summary.json").read_text())["status"].startswith("stopped:")


def test_velocity_global_is_R_u():
    """DeformableBody.velocity_global: nodal velocities of a rotated instance in the global frame, v = R u with
    R the rotation by the instance's angle, computed here from cos/sin."""
    bt = BlockType(mesh_rectangle(0.2, 0.1, 0.1), Material(E=1e9, nu=0.2, rho=2000.0))
    ang = 0.3
    b = DeformableBody(bt, (1.0, 2.0), angle=ang)
    rng = np.random.default_rng(3)
    b.u[:] = rng.standard_normal(b.u.size)
    U = b.u.reshape(-1, 2)
    c, s = math.cos(ang), math.sin(ang)
    expected = np.column_stack([c * U[:, 0] - s * U[:, 1], s * U[:, 0] + c * U[:, 1]])
    np.testing.assert_allclose(b.velocity_global(), expected, rtol=0, atol=1e-14)
