"""Two geometric rules checked against the geometry, not against the rule's own code:

* a single-component clamp (`components = "x"` or `"y"`, a GLOBAL component) on a block rotated by a multiple of
  90°: the clamped nodes keep a zero global velocity in that component, the other component moves;
* the bed/head interface split: between two groups with a `bed` and a `head` interface, contacts on the
  horizontal joints take the bed interface and contacts on the vertical joints the head one (located by their
  position in a known layout)."""
import numpy as np
import pytest

from fem_blocks.bodies import BlockType, Clamp, DeformableBody, Driver, Material, RigidBody
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.meshing import mesh_rectangle


@pytest.mark.parametrize("quarter", [1, 2, 3, -1])
@pytest.mark.parametrize("comp", ["x", "y"])
def test_single_component_clamp_on_rotated_block(quarter, comp):
    """Block 0.4 x 0.2 rotated by quarter·90° about its type origin; the nodes of the global box around the
    type-frame edge X = 0 are clamped in the global component `comp`. Gravity (3, -9.81) loads both global
    components. After 3 steps the clamped nodes' global velocity R u_type (R from cos/sin of the angle) is zero in
    `comp` (to 1e-12 of the largest velocity: R's entries cos(π/2) ~ 6e-17) and not in the other component."""
    bt = BlockType(mesh_rectangle(0.4, 0.2, 0.1, cell="quad"),
                   Material(E=1e9, nu=0.2, rho=2000.0, thickness=0.1), name="b")
    angle = quarter * np.pi / 2
    c, s = np.cos(angle), np.sin(angle)
    R = np.array([[c, -s], [s, c]])
    X = bt.mesh.points
    edge = np.flatnonzero(np.abs(X[:, 0]) < 1e-12)          # type-frame edge X = 0 (3 nodes)
    xg = X[edge] @ R.T                                       # its global positions (position = origin)
    box = (xg[:, 0].min() - 1e-6, xg[:, 0].max() + 1e-6, xg[:, 1].min() - 1e-6, xg[:, 1].max() + 1e-6)
    body = DeformableBody(bt, angle=angle, clamps=[Clamp(box=box, components=comp)])
    sim = Simulation([body], h=1e-4, theta=0.5, gravity=(3.0, -9.81))
    for _ in range(3):
        sim.step()
    v = body.u.reshape(-1, 2) @ R.T                          # global nodal velocities
    k, other = {"x": (0, 1), "y": (1, 0)}[comp]
    vmax = np.abs(v).max()
    assert vmax > 0
    assert np.abs(v[edge, k]).max() <= 1e-12 * vmax
    assert np.abs(v[edge, other]).min() > 1e-3 * vmax
    free = np.setdiff1d(np.arange(len(X)), edge)
    assert np.abs(v[free, k]).max() > 1e-3 * vmax


FIX = {k: Driver("velocity", 0.0) for k in ("x", "y", "rz")}


def test_bed_head_split_by_joint_position():
    """Rigid bricks A = [0, 0.2] x [0, 0.1], B = [0.2, 0.4] x [0, 0.1] side by side on a fixed base, C =
    [0.1, 0.3] x [0.1, 0.2] on both. Interfaces bricks-bricks: bed (μ = 0.8) and head (μ = 0.3); bricks-base: any
    (μ = 0.6). Every brick-brick contact on the vertical joint x = 0.2, 0 < y < 0.1 is head, every one on y = 0.1
    is bed, every contact on y = 0 is the base interface; the per-contact friction follows."""
    T = 0.1
    rect = lambda x0, y0, x1, y1: [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]  # noqa: E731
    bodies = [RigidBody(rect(-0.1, -0.1, 0.5, 0.0), drivers=dict(FIX), thickness=T, name="base"),
              RigidBody(rect(0.0, 0.0, 0.2, 0.1), rho=2000.0, thickness=T, name="A"),
              RigidBody(rect(0.2, 0.0, 0.4, 0.1), rho=2000.0, thickness=T, name="B"),
              RigidBody(rect(0.1, 0.1, 0.3, 0.2), rho=2000.0, thickness=T, name="C")]
    # placement "positions" (1/4 and 3/4 of each edge): points inside the joints, away from the corners where
    # bed and head joints meet (the default "overlap" puts them at the corners)
    specs = [InterfaceSpec("bed", ("bricks", "bricks"), mu=0.8, orientation="bed", placement="positions"),
             InterfaceSpec("head", ("bricks", "bricks"), mu=0.3, orientation="head", placement="positions"),
             InterfaceSpec("base", ("bricks", "base"), mu=0.6, placement="positions")]
    cs = ContactStep(specs, ["base", "bricks", "bricks", "bricks"], ContactOptions(tol=1e-10, max_sweeps=10000))
    sim = Simulation(bodies, h=1e-3, theta=1.0, contact=cs, velocity_reset=True)
    sim.step()
    c = cs.cs
    x, y = c.point[:, 0], c.point[:, 1]
    on_head = (np.abs(x - 0.2) < 1e-9) & (y > 1e-9) & (y < 0.1 - 1e-9)
    on_bed = np.abs(y - 0.1) < 1e-9
    on_base = np.abs(y) < 1e-9
    assert on_head.sum() >= 2 and on_bed.sum() >= 2 and on_base.sum() >= 2
    assert np.all(on_head | on_bed | on_base)
    assert np.all(c.interface[on_head] == 1) and np.all(c.interface[on_bed] == 0)
    assert np.all(c.interface[on_base] == 2)
    np.testing.assert_array_equal(cs.mu, np.where(on_head, 0.3, np.where(on_bed, 0.8, 0.6)))
