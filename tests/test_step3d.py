"""3D time step (dynamics.Simulation + contact.step.ContactStep in dimension 3): acceptance tests against
closed forms and conservation laws (Moreau–Jean θ-method, Signorini–Coulomb, NLGS on 3x3 blocks)."""
import numpy as np
import pytest

from fem_blocks.bodies import (BlockType3D, DeformableBody3D, Driver, History, Material, RigidBody3D,
                               rotation3d)
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.errors import InputError
from fem_blocks.meshing import box_corners, mesh_box

G = 9.81
FIXED = {k: ("velocity", 0.0) for k in ("x", "y", "z", "rx", "ry", "rz")}
EZ = np.array([0.0, 0.0, 1.0])
TIGHT = dict(tol=1e-10, criterion="residual", max_sweeps=20000, check_every=5)


def incline(alpha, psi):
    """Q = R_z(psi) R_x(alpha): the incline of angle alpha (tilted about x, slope along y) then the whole scene
    rotated about the vertical by psi (slope direction off the axes for psi not a multiple of pi/2)."""
    return rotation3d(EZ, psi) @ rotation3d(np.array([1.0, 0.0, 0.0]), alpha)


def downhill(Q):
    """Unit steepest-descent direction of the plane of normal Q e_z under g = -G e_z."""
    n = Q @ EZ
    d = -EZ + n[2] * n
    return d / np.linalg.norm(d)


def angle(a, b):
    return float(np.arctan2(np.linalg.norm(np.cross(a, b)), np.dot(a, b)))


def floor_on(Q, size=4.0):
    return RigidBody3D(box_corners(size, size, 1.0, (-size / 2, -size / 2, -1.0)) @ Q.T, drivers=FIXED, name="floor")


def contact(interfaces, groups, **opts):
    return ContactStep(interfaces, groups, ContactOptions(**{**TIGHT, **opts}))


def on_floor(mu, **opts):
    return contact([InterfaceSpec("joint", ("block", "floor"), mu=mu, candidate="block")], ["floor", "block"], **opts)


def com_velocity(body):
    """Velocity of the centre of mass of a deformable body: sum_i m_i R u_i / m (lumped M)."""
    m = body.type.M.diagonal().reshape(-1, 3)[:, 0]
    return body.R @ (m @ body.u.reshape(-1, 3)) / m.sum()


# ----------------------------------------------------------------------------- rigid block on an incline
ALPHA = 0.4  # tan(alpha) = 0.4228


@pytest.mark.parametrize("psi", [0.0, 0.7])
@pytest.mark.parametrize("mu", [0.2, 0.6])
def test_rigid_block_on_incline(psi, mu):
    """Slides along the steepest slope with a = g (sin α - μ cos α) if μ < tan α, sticks otherwise; the incline
    rotated about the vertical (psi) gives the same motion."""
    Q = incline(ALPHA, psi)
    blk = RigidBody3D(box_corners(1.0, 1.0, 0.5, (-0.5, -0.5, 0.0)) @ Q.T, rho=2000.0, name="block")
    sim = Simulation([floor_on(Q), blk], 1e-3, 0.5, contact=on_floor(mu))
    n = 50
    for _ in range(n):
        info = sim.step()
    assert info.contact["converged"] and info.contact["active"] == 4
    v = blk.u[:3]
    assert np.linalg.norm(blk.u[3:]) <= 1e-10  # no tipping, no spin
    if mu < np.tan(ALPHA):
        assert info.contact["slip"] == 4
        a_exact = G * (np.sin(ALPHA) - mu * np.cos(ALPHA))
        assert abs(np.linalg.norm(v) / (n * sim.h) / a_exact - 1) <= 0.01
        assert angle(v, downhill(Q)) <= 1e-8
    else:
        assert np.linalg.norm(v) <= 1e-10


# ----------------------------------------------------------------------------- deformable block on an incline
@pytest.mark.parametrize("psi", [0.0, 0.7])
@pytest.mark.parametrize("mu", [0.2, 0.6])
def test_deformable_block_on_incline(psi, mu):
    """Hexahedral block (2x2x1 Q1, stiffness-proportional damping beta K, which leaves rigid motions undamped):
    the elastic transient of the first contact decays (first vertical mode: damping ratio ~0.35), then the
    centre of mass slides along the steepest slope with a = g (sin α - μ cos α): least-squares slope of its
    downhill velocity over the second half of 0.2 s, within 1 % (measured ~1e-9). Contact points at the nodes
    (placement "nodes": 9 points on 9 bottom nodes, W nonsingular and the frictional solution unique; with the
    default 4 points per face, 16 points on 9 nodes, W is singular and NLGS's Gauss–Seidel order picks one of
    several admissible impulse distributions, which drifts the direction by ~1e-6 rad)."""
    Q = incline(ALPHA, psi)
    bt = BlockType3D(mesh_box(1.0, 1.0, 0.5, divisions=(2, 2, 1)), Material(1e8, 0.2, 2000.0, beta=1e-3))
    blk = DeformableBody3D(bt, position=Q @ np.array([-0.5, -0.5, 0.0]), R=Q, name="block")
    itf = InterfaceSpec("joint", ("block", "floor"), mu=mu, candidate="block", placement="nodes")
    sim = Simulation([floor_on(Q), blk], 1e-3, 0.5, contact=contact([itf], ["floor", "block"]))
    n, d, nrm = 200, downhill(Q), Q @ EZ
    V = np.zeros((n, 3))
    for k in range(n):
        info = sim.step()
        V[k] = com_velocity(blk)
    assert info.contact["converged"] and info.contact["contacts"] == 9
    t = sim.h * np.arange(1, n + 1)
    v = V[-1]
    if mu < np.tan(ALPHA):
        a = np.polyfit(t[n // 2:], V[n // 2:] @ d, 1)[0]
        assert abs(a / (G * (np.sin(ALPHA) - mu * np.cos(ALPHA))) - 1) <= 0.01
        assert angle(v - (v @ nrm) * nrm, d) <= 1e-8
        assert abs(v @ nrm) <= 1e-8  # stays on the incline
    else:
        assert np.linalg.norm(v) <= 1e-7  # residual of the decaying elastic vibration (measured 4e-9)
        assert np.max(np.abs(blk.u)) <= 1e-6  # every node at rest, not only the centre of mass


# ----------------------------------------------------------------------------- stack of three blocks
def test_stack_of_three_deformable_blocks():
    """Three identical blocks (one BlockType3D: one factor, one batched solve) stacked on a rigid floor under
    gravity, quasi-static (velocity reset, θ = 1): at equilibrium the floor reaction (driver reaction and the sum
    of the contact forces) equals the total weight and the joint between blocks k and k+1 carries the weight of
    the blocks above, to 1e-6 relative."""
    bt = BlockType3D(mesh_box(1.0, 1.0, 0.5, divisions=(2, 2, 2)), Material(1e8, 0.25, 2000.0))
    blocks = [DeformableBody3D(bt, position=(-0.5, -0.5, 0.5 * k), name=f"b{k}") for k in range(3)]
    floor = floor_on(np.eye(3))
    itfs = [InterfaceSpec("bed", ("block", "floor"), mu=0.6, candidate="block"),
            InterfaceSpec("joint", ("block", "block"), mu=0.6)]
    cst = contact(itfs, ["floor", "block", "block", "block"])
    sim = Simulation([floor] + blocks, 1e-2, 1.0, velocity_reset=True, contact=cst)
    assert len(sim.groups) == 1 and sim.groups[0].members.size == 3
    for _ in range(40):
        info = sim.step()
    assert info.contact["converged"]
    W = bt.M.diagonal().sum() / 3 * G  # weight of one block (M row sums: 3 m per block, one per component)
    assert abs(W / (2000.0 * 0.5 * G) - 1) < 1e-12
    cs, r = cst.cs, cst.r
    Fz = np.einsum("a,a->a", r[:, 0], cs.n[:, 2])  # vertical component of the normal forces (normals are ±z)
    pair = {tuple(sorted(p)) for p in zip(cs.cand_body, cs.ant_body)}
    assert pair == {(0, 1), (1, 2), (2, 3)}
    for lo, above in ((0, 3), (1, 2), (2, 1)):
        sel = ((cs.cand_body == lo) & (cs.ant_body == lo + 1)) | ((cs.cand_body == lo + 1) & (cs.ant_body == lo))
        assert abs(np.abs(Fz[sel].sum()) / (above * W) - 1) <= 1e-6, (lo, Fz[sel].sum(), above * W)
    assert abs(floor.reaction[2] / (3 * W) - 1) <= 1e-6
    # Poisson expansion differs from block to block, so joint points carry friction, but its resultant vanishes
    # (horizontal equilibrium) and every point is inside its Coulomb disk
    Fh = r[:, 1:2] * cs.t + r[:, 2:3] * cs.s
    assert np.linalg.norm(Fh.sum(axis=0)) <= 1e-6 * W
    assert np.all(np.linalg.norm(r[:, 1:], axis=1) <= 0.6 * r[:, 0] * (1 + 1e-9))
