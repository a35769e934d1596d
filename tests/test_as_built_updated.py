"""`reference = "as_built"` in updated geometry (docs/case-files.md `reference`, contact/step.py): each contact of the
initial set carries its initial gap as an offset with its key, g_eff = g − g0 − g_built, g_built = (g − g0) at t = 0.

Set-up (2D, g = 9.81 downwards, no code-derived expectation): a stiff deformable block b × h = 0.2 × 0.1 m (E = 1e10,
Q4, lumped mass) stands with its left bottom corner at the origin on a rigid table whose top is the line
y = −s x, s = W / b, W = 0.5 mm: a wedge joint whose gap grows from 0 under the left corner to W under the right one
(alert 2 mm > W). Built full, so closed as built.

1. Table fixed (θ = 1, h = 1 ms, 30 steps): the joint carries the block's weight, the block neither falls nor turns;
   updated geometry gives the frozen geometry's answer: the table reaction = weight within 1e-9 in both after the
   elastic transient of the first steps (6e-4 of the weight at step 1), the two reaction histories within 1e-6 of
   the weight, centre of pressure and block displacement within 1e-9 m of the frozen run's (observed: 7.8e-13,
   3.6e-14 m, 3.4e-17 m; the elastic settlement is 9.7e-9 m), the block's rotation below 1e-6 rad. Control: the
   joint nominal (no offset: the right corner 0.5 mm open) lets the block turn onto the wedge by W/b = 2.5e-3 rad
   (within 5 %; observed 0.0001 %), which is what a bug dropping the offset would do.
2. Table turning (rigid rotation of the pair): the table turns clockwise about the origin by 0.3 rad (ramped up over
   0.1 s, then 1 rad/s; μ = 1 > tan 0.3, and the block's centre stays well inside its base, tan α = b/h = 2): the
   block turns with it (rotation relative to the table below 1e-4 rad against the 2.5e-3 rad of a joint without
   offset; observed 2.0e-5 rad, from the first step on), every contact stays closed and active (|g_eff| at the end
   of each step below 1e-7 m; observed 1e-15 m), and the block keeps its shape (boundary edge lengths within 1e-5:
   observed 2.2e-6, its elastic strain under its weight on five support points; a linear-kinematics block turned by
   0.3 rad would stretch by ≈ 4.5 %).
"""
import numpy as np
import pytest

from fem_blocks.bodies import BlockType, DeformableBody, Driver, Material, RigidBody, rotation
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.meshing import mesh_rectangle

pytestmark = pytest.mark.dolfinx
G, B, H, RHO, W = 9.81, 0.2, 0.1, 2000.0, 5e-4
S = W / B
TABLE = [(-0.3, -0.1), (0.3, -0.1), (0.3, -S * 0.3), (-0.3, S * 0.3)]
FIX = {k: Driver("velocity", 0.0) for k in ("x", "y", "rz")}
OMEGA, T1, TILT = 1.0, 0.1, 0.3


def block():
    bt = BlockType(mesh_rectangle(B, H, B / 4, cell="quad"), Material(E=1e10, nu=0.2, rho=RHO))
    return DeformableBody(bt, name="block")


def contact(geometry, reference="as_built"):
    itf = InterfaceSpec("bed", ("block", "table"), mu=1.0, alert=2e-3, candidate="block", reference=reference)
    return ContactStep([itf], ["block", "table"], ContactOptions(tol=1e-10, max_sweeps=20000, geometry=geometry))


def centre_of_pressure(sim):
    rec = sim.last_contact
    x = sim.contact.contact_points(rec.cs)[:, 0]
    return float((rec.r[:, 0] * x).sum() / rec.r[:, 0].sum())


def stand(geometry, reference="as_built", steps=30):
    blk = block()
    table = RigidBody(TABLE, drivers=dict(FIX), name="table")
    sim = Simulation([blk, table], h=1e-3, theta=1.0, contact=contact(geometry, reference))
    weight = RHO * B * H * G  # thickness 1 m
    reactions = []
    for _ in range(steps):
        sim.step()
        reactions.append(table.reaction[1] / weight)
    return dict(reactions=np.array(reactions), cop=centre_of_pressure(sim), u=blk.displacement_global().copy(),
                rot=float(blk.rotation()) if geometry == "updated" else None, sim=sim)


def test_wedge_joint_as_built_updated_carries_the_frozen_load():
    fr, up = stand("frozen"), stand("updated")
    for r in (fr, up):  # the weight once the elastic transient of the first steps (6e-4 of it) has decayed
        assert np.abs(r["reactions"][-10:] - 1).max() <= 1e-9
    assert np.abs(up["reactions"] - fr["reactions"]).max() <= 1e-6  # the same transient too
    assert abs(up["cop"] - fr["cop"]) <= 1e-9
    assert np.abs(up["u"] - fr["u"]).max() <= 1e-9
    assert np.abs(fr["u"]).max() <= 1e-6  # elastic settlement only
    assert abs(up["rot"]) <= 1e-6
    assert up["sim"].contact.g_built.max() == pytest.approx(W, rel=1e-5)  # the gap under the right corner


def test_wedge_joint_nominal_updated_turns_onto_the_wedge():
    """Control: the same joint nominal (no offset) is open under the right corner: the block turns onto the wedge."""
    up = stand("updated", reference="nominal", steps=150)
    assert up["rot"] == pytest.approx(-S, rel=0.05)


def tilt(t):
    t = np.asarray(t, dtype=float)
    return np.where(t < T1, 0.5 * OMEGA * t * t / T1, OMEGA * (t - 0.5 * T1))


def test_wedge_joint_as_built_stays_closed_on_a_turning_table():
    h = 2e-3
    t_end = TILT / OMEGA + 0.5 * T1
    c0 = RigidBody(TABLE, drivers=dict(FIX)).center0
    ts = np.arange(int(np.ceil(t_end / h)) + 2) * h
    c = np.array([rotation(-b) @ c0 for b in tilt(ts)])  # about the origin (the block's left bottom corner)
    drv = {"x": Driver("displacement", {"times": ts, "values": c[:, 0] - c0[0]}),
           "y": Driver("displacement", {"times": ts, "values": c[:, 1] - c0[1]}),
           "rz": Driver("displacement", {"times": ts, "values": -tilt(ts)})}
    blk, table = block(), RigidBody(TABLE, drivers=drv, name="table")
    e = blk.type.mesh.boundary_edges
    x0 = blk.reference_points
    l0 = np.linalg.norm(x0[e[:, 1]] - x0[e[:, 0]], axis=1)
    sim = Simulation([blk, table], h=h, theta=0.5, contact=contact("updated"))
    rel, gap, stretch = 0.0, 0.0, 0.0
    while sim.time < t_end - 1e-12:
        sim.step()
        rec = sim.last_contact
        assert rec.stats["converged"] and rec.stats["active"] == rec.stats["contacts"] > 0
        rel = max(rel, abs(blk.rotation() - table.q[2]))
        gap = max(gap, float(np.abs(rec.gt_end).max()))
        x = blk.current_points()
        stretch = max(stretch, float(np.abs(np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1) / l0 - 1).max()))
    assert table.q[2] == pytest.approx(-TILT, rel=1e-9)
    assert rel <= 1e-4
    assert gap <= 1e-7
    assert stretch <= 1e-5
