"""Joint resultants and the line of thrust (issue #23, output/joints.py).

Closed forms:
- lever rule: two contacts of one joint with normal forces p1, p2 at ξ1, ξ2: N = p1 + p2, point of application
  (p1 ξ1 + p2 ξ2) / N, the same whichever body is the candidate (action–reaction);
- a block (b × h) at rest on a table under gravity tilted by α (= a table tilted by α): the table's resultant on
  the block balances the weight, N = m g cos α, T = m g sin α, and its line of action passes through the centre of
  mass, so it crosses the joint at e = (h/2) tan α from its middle: it reaches the toe (e = b/2) at tan α = b/h;
- a stack of blocks at rest: the joint under block k carries the weight of the blocks above it (N = Σ m g)."""
import numpy as np
import pytest
from types import SimpleNamespace

from fem_blocks.output.joints import history_columns, history_values, joint_resultants

G, B, H, RHO = 9.81, 0.1, 0.3, 2000.0


def cs2(cand, ant, points, n, area):
    n = np.asarray(n, float)
    return SimpleNamespace(cand_body=np.asarray(cand), ant_body=np.asarray(ant), point=np.asarray(points, float),
                           n=n, t=np.column_stack([-n[:, 1], n[:, 0]]), area=np.asarray(area, float))


@pytest.mark.parametrize("flip", [False, True])
def test_lever_rule_either_orientation(flip):
    """Horizontal joint y = 0 of length 1 between body 0 (below) and body 1 (above); points at x = 0.25, 0.75
    ('positions' placement, tributary 0.5 each). p1 = 3, p2 = 1 N (+ tangential 0.5, 0.25 N)."""
    p, q = np.array([3.0, 1.0]), np.array([0.5, 0.25])
    if not flip:   # candidate = upper body 1; n = outward normal of body 0 = +y
        cs = cs2([1, 1], [0, 0], [[0.25, 0], [0.75, 0]], [[0, 1], [0, 1]], [0.5, 0.5])
    else:          # candidate = lower body 0; n = outward normal of body 1 = -y; same physical forces
        cs = cs2([0, 0], [1, 1], [[0.25, 0], [0.75, 0]], [[0, -1], [0, -1]], [0.5, 0.5])
    # physical force of body 0 on body 1 at each point: (-q, p) in x, y. Not flipped: t = (-1, 0), r = (p, q) on
    # body 1. Flipped: t = (1, 0), r = force of body 1 on body 0 = (q, -p) = p n + q t: r = (p, q) again
    r = np.column_stack([p, q])
    j = joint_resultants(cs, r)
    assert j.bodies.tolist() == [[0, 1]] and j.n_contacts.tolist() == [2]
    assert np.allclose(j.force[0], [-q.sum(), p.sum()], rtol=0, atol=1e-14)
    assert j.N[0] == pytest.approx(4.0, abs=1e-14) and j.T[0] == pytest.approx(0.75, abs=1e-14)
    assert np.allclose(j.normal[0], [0, 1]) and np.allclose(j.middle[0], [0.5, 0])
    assert j.half_width[0] == pytest.approx(0.5, abs=1e-14)
    x_app = (3 * 0.25 + 1 * 0.75) / 4  # lever rule
    assert np.allclose(j.point[0], [x_app, 0], atol=1e-14)
    assert abs(j.ecc[0]) == pytest.approx(0.5 - x_app, abs=1e-14) and j.inside[0]


def test_triangular_pressure_edge_of_kern_and_open_joint():
    """'overlap' placement: points at both ends (tributary 0.5 each); p at x = 0 only: the point of application
    is the corner (|e| = half-width, still inside); a tension-only pair (N < 0): no point, not inside; a pair
    with no force: NaN."""
    cs = cs2([1, 1, 2, 2, 3, 3], [0, 0, 1, 1, 2, 2], [[0, 0], [1, 0], [0, 1], [1, 1], [0, 2], [1, 2]],
             [[0, 1]] * 6, [0.5] * 6)
    r = np.array([[2.0, 0], [0, 0], [-1.0, 0], [-1.0, 0], [0, 0], [0, 0]])
    j = joint_resultants(cs, r)
    assert j.bodies.tolist() == [[0, 1], [1, 2], [2, 3]]
    assert np.allclose(j.point[0], [0, 0], atol=1e-14) and abs(j.ecc[0]) == pytest.approx(0.5, abs=1e-14)
    assert j.inside.tolist() == [True, False, False]
    assert np.isnan(j.ecc[1]) and np.isnan(j.ecc[2]) and j.N[1] == pytest.approx(-2.0)


def test_history_columns_and_values():
    cs = cs2([1, 1], [0, 0], [[0.25, 0], [0.75, 0]], [[0, 1], [0, 1]], [0.5, 0.5])
    j = joint_resultants(cs, np.array([[1.0, 0], [1.0, 0]]))
    names = ["base", "brick"]
    assert history_columns(names, [(1, 0)]) == ["brick|base.N", "brick|base.T", "brick|base.e"]
    v = history_values(j, [(1, 0), (0, 2)], names + ["x"])
    assert v["brick|base.N"] == 2.0 and v["brick|base.e"] == 0.0 and np.isnan(v["base|x.e"])


def test_3d_eccentricity_two_axes():
    """A 1 x 1 joint in z = 0 with 4 points at (±1/4, ±1/4) (tributary 1/4 each); normal loads 1, 2, 3, 4:
    point of application = load-weighted mean of the points, half-widths 1/2."""
    pts = np.array([[0.25, 0.25, 0], [0.75, 0.25, 0], [0.25, 0.75, 0], [0.75, 0.75, 0]])
    n = np.tile([0.0, 0, 1], (4, 1))
    cs = SimpleNamespace(cand_body=np.ones(4, int), ant_body=np.zeros(4, int), point=pts, n=n,
                         t=np.tile([1.0, 0, 0], (4, 1)), s=np.tile([0.0, 1, 0], (4, 1)), area=np.full(4, 0.25))
    w = np.array([1.0, 2, 3, 4])
    j = joint_resultants(cs, np.column_stack([w, np.zeros(4), np.zeros(4)]))
    assert j.N[0] == pytest.approx(10.0)
    assert np.allclose(j.point[0], w @ pts / w.sum(), atol=1e-14)
    assert np.allclose(j.half_width[0], [0.5, 0.5], atol=1e-14) and j.inside[0]


# ----------------------------------------------------------------------------- simulations
def tilted_block(tan_alpha, steps=150, h=2e-3):
    """A b x h block (2 x 6 Q4, E = 10 GPa) at rest on a fixed rigid table, gravity tilted by α (default 2D
    placement, μ = 0.8 > tan α). Returns the joint resultants of the last step and the block's mass."""
    from fem_blocks.bodies import BlockType, DeformableBody, Driver, Material, RigidBody
    from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
    from fem_blocks.dynamics import Simulation
    from fem_blocks.meshing import mesh_rectangle
    bt = BlockType(mesh_rectangle(B, H, B / 2, cell="quad"), Material(E=1e10, nu=0.2, rho=RHO, thickness=1.0))
    blk = DeformableBody(bt, position=(0.0, 0.0))
    table = RigidBody([(-0.5, -0.1), (0.6, -0.1), (0.6, 0.0), (-0.5, 0.0)],
                      drivers={k: Driver("velocity", 0.0) for k in ("x", "y", "rz")}, name="table")
    step = ContactStep([InterfaceSpec("base", ("block", "table"), mu=0.8)], ["block", "table"],
                       ContactOptions(tol=1e-12, max_sweeps=20000))
    a = np.arctan(tan_alpha)
    sim = Simulation([blk, table], h=h, theta=1.0, contact=step, gravity=(G * np.sin(a), -G * np.cos(a)))
    for _ in range(steps):
        sim.step()
    rec = sim.last_contact
    return joint_resultants(rec.cs, rec.r, step.contact_points(rec.cs), step.joint_lengths(rec.cs)), RHO * B * H


@pytest.mark.dolfinx
@pytest.mark.parametrize("ratio", [0.5, 0.95, 1.0])
def test_tilting_table_resultant_moves_to_the_toe(ratio):
    """tan α = ratio b/h: e = (h/2) tan α = ratio b/2 toward the toe (x = b), N = m g cos α, T = m g sin α,
    after 0.3 s at rest (θ = 1). Observed: N, T within 1e-11 relative; the point within 1e-7 b below the
    overturning angle and 7e-5 b of the toe at tan α = b/h (the block is at the limit: the toe carries everything)."""
    tan_a = ratio * B / H
    j, m = tilted_block(tan_a)
    a = np.arctan(tan_a)
    assert len(j) == 1 and j.inside[0]
    assert j.N[0] == pytest.approx(m * G * np.cos(a), rel=1e-9)
    assert j.T[0] == pytest.approx(m * G * np.sin(a), rel=1e-9)
    assert j.half_width[0] == pytest.approx(B / 2, rel=1e-12)
    assert j.point[0][0] - B / 2 == pytest.approx(0.5 * H * tan_a, abs=(1e-3 if ratio == 1.0 else 1e-6) * B)


@pytest.fixture(scope="module")
def arch_at_rest():
    """demos/arch.toml (15 voussoirs, intrados R = 1 m, ring depth 0.3 m, μ = 0.5, θ = 1, h = 2e-3 s) with mesh
    size t/2, run 0.2 s: at rest. Returns (model, joint resultants of the last step)."""
    import os
    import tomllib
    from fem_blocks.case import parse_case
    from fem_blocks.dynamics import Simulation
    from fem_blocks.model import build_model
    from _paths import DEMOS
    with open(os.path.join(DEMOS, "arch.toml"), "rb") as f:
        doc = tomllib.load(f)
    doc["arch"]["mesh_size"] = 0.15
    case = parse_case(doc, "arch.toml")
    model = build_model(case)
    st = case.stages[0]
    sim = Simulation(model.bodies, h=st.h, theta=st.theta, gravity=model.gravity, contact=model.contact)
    for _ in range(100):
        sim.step()
    rec, step = sim.last_contact, model.contact
    return model, joint_resultants(rec.cs, rec.r, step.contact_points(rec.cs), step.joint_lengths(rec.cs))


VOUSSOIR_WEIGHT = RHO * G * 0.5 * np.sin(np.pi / 15) * (1.3 ** 2 - 1.0 ** 2)  # trapezoid (straight faces), 1 m thick


@pytest.mark.dolfinx
def test_arch_line_of_thrust_inside_every_joint(arch_at_rest):
    """16 joints (14 between voussoirs, 2 on the piers), each compressed, its point of application inside it."""
    model, j = arch_at_rest
    vous = [i for i, nm in enumerate(model.names) if nm.startswith("voussoir")]
    assert len(vous) == 15
    inner = [k for k in range(len(j)) if set(j.bodies[k]) <= set(vous)]
    springing = [k for k in range(len(j)) if len(set(j.bodies[k]) & set(vous)) == 1]
    assert len(inner) == 14 and len(springing) == 2
    assert np.all(j.N > 0) and np.all(j.inside)
    assert np.allclose(j.half_width, 0.15, rtol=1e-5)  # ring depth / 2 (updated geometry: overlaps of the moved blocks)


@pytest.mark.dolfinx
def test_arch_joint_resultants_balance_the_weight(arch_at_rest):
    """Statics: on every voussoir the joint resultants balance its weight (m g = ρ g A, A the trapezoid between radii 1 and 1.3 m, from the
    geometry), and the two springing joints carry the weight of the whole arch (15 m g)."""
    model, j = arch_at_rest
    vous = [i for i, nm in enumerate(model.names) if nm.startswith("voussoir")]
    for v in vous:
        f = sum((1 if b == v else -1) * j.force[k] for k, (a, b) in enumerate(j.bodies) if v in (a, b))
        assert np.allclose(f, [0.0, VOUSSOIR_WEIGHT], rtol=0, atol=1e-6 * VOUSSOIR_WEIGHT), (model.names[v], f)
    on_arch = sum((1 if b in vous else -1) * j.force[k] for k, (a, b) in enumerate(j.bodies)
                  if (a in vous) != (b in vous))
    assert np.allclose(on_arch, [0.0, 15 * VOUSSOIR_WEIGHT], rtol=0, atol=1e-6 * 15 * VOUSSOIR_WEIGHT)


BRICK_CASE = """
[materials.m]
E = 1e9
nu = 0.2
rho = 2000.0
[block_types.b]
geometry = "rectangle"
lx = 0.2
ly = 0.1
mesh_size = 0.1
material = "m"
[[blocks]]
type = "b"
name = "brick"
position = [-0.1, 0.0]
[[rigid_bodies]]
name = "base"
group = "base"
vertices = [[-1.0, -0.1], [1.0, -0.1], [1.0, 0.0], [-1.0, 0.0]]
[rigid_bodies.drivers]
x = {kind = "velocity", history = 0.0}
y = {kind = "velocity", history = 0.0}
rz = {kind = "velocity", history = 0.0}
[[interfaces]]
between = ["blocks", "base"]
mu = 0.5
[output]
joints = [["brick", "base"]]
joints_paraview = true
line_of_thrust = true
[[stages]]
duration = 0.02
h = 0.001
theta = 1.0
"""


@pytest.mark.dolfinx
def test_run_writes_joint_history_paraview_and_line_of_thrust(tmp_path):
    """A 0.2 x 0.1 m brick (1 m thick, 2000 kg/m³) resting on a fixed base: history.csv brick|base.N = its weight
    m g = 392.4 N and e = 0 (symmetric), T = 0; joints.pvd holds one point at the joint's middle (x = 0, y = 0)
    with N; line_of_thrust.png and summary.json "line_of_thrust" (1 compressed joint, none outside)."""
    import csv
    import json
    import meshio
    from fem_blocks.cli import main
    case = tmp_path / "brick.toml"
    case.write_text(BRICK_CASE)
    out = tmp_path / "out"
    assert main(["run", str(case), "--out", str(out), "--quiet"]) == 0
    rows = list(csv.DictReader(open(out / "history.csv")))
    w = 2000.0 * 0.2 * 0.1 * 9.81
    last = rows[-1]
    assert float(last["brick|base.N"]) == pytest.approx(w, rel=1e-6)
    assert abs(float(last["brick|base.T"])) < 1e-6 * w and abs(float(last["brick|base.e"])) < 1e-6 * 0.1
    s = json.load(open(out / "summary.json"))
    assert s["line_of_thrust"] == dict(png="line_of_thrust.png", joints=1, compressed=1, outside=[])
    assert (out / "line_of_thrust.png").stat().st_size > 1000
    vtus = sorted((out / "paraview").glob("joints_*.vtu"))
    m = meshio.read(vtus[-1])
    assert len(m.points) == 1 and np.allclose(m.points[0, :2], [0.0, 0.0], atol=1e-6)
    assert m.point_data["N"][0] == pytest.approx(w, rel=1e-6) and m.point_data["inside"][0] == 1


def test_joints_writer_3d_frame(tmp_path):
    """JointsWriter (3D): one vertex per joint at the point of application, N and the 2-vector e in the file."""
    import meshio
    from fem_blocks.contact.result import ContactResult
    from fem_blocks.output.joints import JointsWriter
    pts = np.array([[0.25, 0.25, 0], [0.75, 0.25, 0], [0.25, 0.75, 0], [0.75, 0.75, 0]])
    cs = SimpleNamespace(cand_body=np.ones(4, int), ant_body=np.zeros(4, int), point=pts,
                         n=np.tile([0.0, 0, 1], (4, 1)), t=np.tile([1.0, 0, 0], (4, 1)),
                         s=np.tile([0.0, 1, 0], (4, 1)), area=np.full(4, 0.25), gap=np.zeros(4))
    w = np.array([1.0, 1, 1, 5])
    r = np.column_stack([w, np.zeros(4), np.zeros(4)])
    rec = ContactResult(dim=3, stats={}, cs=cs, r=r, P=r * 1e-3)
    JointsWriter(str(tmp_path), 3).write(0.0, rec)
    m = meshio.read(tmp_path / "joints_000000.vtu")
    assert np.allclose(m.points[0], w @ pts / w.sum(), atol=1e-14)
    assert m.point_data["N"][0] == pytest.approx(8.0) and m.point_data["e"].shape[0] == 1


@pytest.mark.dolfinx
def test_check_names_an_unknown_joint_body(capsys):
    """`fem-blocks check` matches the [output] joints names to the built bodies as a run does (exit 2)."""
    import os
    from fem_blocks.cli import main
    path = os.path.join(os.path.dirname(__file__), "bad_cases", "570_output_joints_unknown_body.toml")
    assert main(["check", path]) == 2
    assert "output.joints: 'wall'" in capsys.readouterr().err
