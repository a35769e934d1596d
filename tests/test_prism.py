"""Compression prism: apparent Young's modulus of a stack-bonded prism with compliant bed joints equals the
series formula E = (h_b + t_j)/(h_b/E_b + t_j/E_j), i.e. joint stiffness k_n = E_b E_j / (t_j (E_b - E_j)),
within 1 % (expanded bricks of height h_b + t_j, slow platen ramp, theta = 1)."""
import numpy as np
import pytest

from fem_blocks.bodies import BlockType, DeformableBody, Driver, Material, RigidBody
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.meshing import mesh_rectangle

pytestmark = pytest.mark.dolfinx
Eb, Ej, hb, tj, T, Lb = 16.7e9, 4.0e9, 0.052, 0.010, 0.1, 0.21
KN = Eb * Ej / (tj * (Eb - Ej))


@pytest.mark.parametrize("law, params", [
    ("elastic", dict(c_N=KN, c_T=KN / 2.3, mu=0.0)),
    ("mixed", dict(k_n=KN, k_s=KN / 2.3, f_t=2.5e5, c=3.5e5, G_I=18.0, G_II=125.0, tan_phi=0.75)),
])
def test_prism_modulus_series_formula(law, params):
    n, h, steps, d = 5, 2e-5, 500, 2e-5
    mat = Material(E=Eb, nu=0.15, rho=2500.0, thickness=T)
    bt = BlockType(mesh_rectangle(Lb, hb + tj, 0.031), mat)
    blocks = [DeformableBody(bt, (0.0, i * (hb + tj))) for i in range(n)]
    H = n * (hb + tj)
    base = RigidBody([(-0.05, -0.05), (Lb + 0.05, -0.05), (Lb + 0.05, 0), (-0.05, 0)], thickness=T,
                     drivers={k: Driver("velocity", 0.0) for k in ("x", "y", "rz")})
    platen = RigidBody([(-0.05, H), (Lb + 0.05, H), (Lb + 0.05, H + 0.05), (-0.05, H + 0.05)], thickness=T,
                       drivers={"x": Driver("velocity", 0.0), "rz": Driver("velocity", 0.0),
                                "y": Driver("displacement", {"times": [0, 0.8 * steps * h], "values": [0, -d]})})
    cs = ContactStep([InterfaceSpec("bed", ("b", "b"), law=law, params=params),
                      InterfaceSpec("platens", ("b", "r"), mu=0.0)],
                     ["b"] * n + ["r", "r"], ContactOptions(tol=1e-10, max_sweeps=5000))
    sim = Simulation(blocks + [base, platen], h=h, theta=1.0, contact=cs, gravity=(0.0, 0.0))
    for _ in range(steps):
        info = sim.step()
        assert info.contact["converged"]
    stress = -platen.reaction[1] / (Lb * T)
    X = bt.mesh.points
    mid = np.isclose(X[:, 1], 0.5 * (hb + tj))  # nodes at mid-height of a block (mesh has a node row there)
    assert mid.sum() > 0
    u1 = blocks[0].displacement_global()[mid, 1].mean()
    u4 = blocks[3].displacement_global()[mid, 1].mean()
    strain = -(u4 - u1) / (3 * (hb + tj))  # gauge: three brick + joint units
    E_series = (hb + tj) / (hb / Eb + tj / Ej)
    assert stress / strain == pytest.approx(E_series, rel=0.01)


CASE_PRISM = """
name = "prism_expanded"
gravity = [0.0, 0.0]
[materials.brick]
E = 16.7e9
nu = 0.15
rho = 2500.0
thickness = 0.1
[wall]
type = "prism"
bricks = 5
material = "brick"
brick_length = 0.21
brick_height = 0.052
joint = 0.010
expanded = true
mesh_size = 0.031
[wall.foundation]
depth = 0.05
overhang = 0.05
[wall.beam]
depth = 0.05
overhang = 0.05
[wall.beam.drivers]
x = {kind = "velocity", history = 0.0}
rz = {kind = "velocity", history = 0.0}
y = {kind = "displacement", history = {times = [0.0, 0.008], values = [0.0, -2e-5]}}
[contact]
tol = 1e-10
max_sweeps = 5000
[[interfaces]]
name = "bed"
between = ["bricks", "bricks"]
law = "elastic"
c_N = %r
c_T = %r
mu = 0.0
[[interfaces]]
name = "platens"
between = ["bricks", "foundation"]
mu = 0.0
[[interfaces]]
name = "top"
between = ["bricks", "beam"]
mu = 0.0
[[stages]]
duration = 0.01
h = 2e-5
theta = 1.0
"""


def test_prism_case_file_expanded_bricks_series_formula(tmp_path):
    """[wall] type = "prism", expanded = true, through the case file: a stack-bonded prism has no head joints,
    so its blocks are L x (h_b + t_j) (not L + t_j wide), and the apparent modulus is the series formula within
    1 % (a 220 mm wide block would make the stress R/(L T) 4.8 % too high)."""
    from fem_blocks.case import load_case
    from fem_blocks.model import build_model
    path = tmp_path / "prism.toml"
    path.write_text(CASE_PRISM % (KN, KN / 2.3))
    case = load_case(str(path))
    model = build_model(case)
    bricks = [b for b in model.bodies if isinstance(b, DeformableBody)]
    assert len(bricks) == 5
    X = bricks[0].type.mesh.points
    assert np.ptp(X[:, 0]) == pytest.approx(Lb, rel=1e-12)  # width: the brick length, no head joint
    assert np.ptp(X[:, 1]) == pytest.approx(hb + tj, rel=1e-12)  # height: brick + one bed joint
    st = case.stages[0]
    sim = Simulation(model.bodies, h=st.h, theta=st.theta, gravity=model.gravity,
                     velocity_reset=st.velocity_reset, contact=model.contact)
    for _ in range(500):
        assert sim.step().contact["converged"]
    platen = model.bodies[model.index("beam")]
    stress = -platen.reaction[1] / (Lb * T)
    mid = np.isclose(X[:, 1], 0.5 * (hb + tj))
    assert mid.sum() > 0
    u1 = bricks[0].displacement_global()[mid, 1].mean()
    u4 = bricks[3].displacement_global()[mid, 1].mean()
    strain = -(u4 - u1) / (3 * (hb + tj))
    E_series = (hb + tj) / (hb / Eb + tj / Ej)
    assert stress / strain == pytest.approx(E_series, rel=0.01)
