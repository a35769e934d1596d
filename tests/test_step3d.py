"""3D time step (dynamics.Simulation + contact.step.ContactStep in dimension 3): acceptance tests against
closed forms and conservation laws (Moreau–Jean θ-method, Signorini–Coulomb, NLGS on 3x3 blocks)."""
import numpy as np
import pytest

from fem_blocks.bodies import (BlockType3D, DeformableBody3D, Driver, History, Material, RigidBody3D,
                               rotation3d)
from fem_blocks.contact.detection_3d import update_geometry
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
        assert abs(np.linalg.norm(v) / (n * sim.h) / a_exact - 1) <= 1e-9  # brief: 1 %; measured ~1e-13
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
    downhill velocity over the second half of 0.2 s, within 1e-6 (brief: 1 %; measured ~3e-9). Contact points at the nodes
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
        assert abs(a / (G * (np.sin(ALPHA) - mu * np.cos(ALPHA))) - 1) <= 1e-6  # brief: 1 %
        assert angle(v - (v @ nrm) * nrm, d) <= 1e-8
        assert abs(v @ nrm) <= 1e-8  # stays on the incline
    else:
        assert np.linalg.norm(v) <= 1e-7  # residual of the decaying elastic vibration (measured 4e-9)
        assert np.max(np.abs(blk.u)) <= 1e-6  # every node at rest, not only the centre of mass


# ----------------------------------------------------------------------------- stack of three blocks
@pytest.mark.parametrize("geometry", ["frozen", "updated"])
def test_stack_of_three_deformable_blocks(geometry):
    """Three identical blocks (one BlockType3D: one factor, one batched solve) stacked on a rigid floor under
    gravity, quasi-static (velocity reset, θ = 1): at equilibrium the floor reaction (driver reaction and the sum
    of the contact forces) equals the total weight and the joint between blocks k and k+1 carries the weight of
    the blocks above, to 1e-9 relative (brief: 1e-6; measured 2e-15). Frozen geometry, or updated (re-detection
    every 5 steps, detection_3d.update_geometry on the deformed boundaries in between)."""
    bt = BlockType3D(mesh_box(1.0, 1.0, 0.5, divisions=(2, 2, 2)), Material(1e8, 0.25, 2000.0))
    blocks = [DeformableBody3D(bt, position=(-0.5, -0.5, 0.5 * k), name=f"b{k}") for k in range(3)]
    floor = floor_on(np.eye(3))
    itfs = [InterfaceSpec("bed", ("block", "floor"), mu=0.6, candidate="block"),
            InterfaceSpec("joint", ("block", "block"), mu=0.6)]
    cst = contact(itfs, ["floor", "block", "block", "block"], geometry=geometry, redetect_every=5)
    sim = Simulation([floor] + blocks, 1e-2, 1.0, velocity_reset=True, contact=cst)
    assert len(sim.groups) == 1 and sim.groups[0].members.size == 3
    for _ in range(40):
        info = sim.step()
    assert info.contact["converged"]
    W = bt.M.diagonal().sum() / 3 * G  # weight of one block (M row sums: 3 m per block, one per component)
    assert abs(W / (2000.0 * 0.5 * G) - 1) < 1e-12
    cs, r = sim.last_contact.cs, sim.last_contact.r
    F = r[:, :1] * cs.n + r[:, 1:2] * cs.t + r[:, 2:3] * cs.s  # global force of each contact (updated: frames
    Fz = F[:, 2]                                                # of the deformed faces, not exactly ±z)
    pair = {tuple(sorted(p)) for p in zip(cs.cand_body, cs.ant_body)}
    assert pair == {(0, 1), (1, 2), (2, 3)}
    for lo, above in ((0, 3), (1, 2), (2, 1)):
        sel = ((cs.cand_body == lo) & (cs.ant_body == lo + 1)) | ((cs.cand_body == lo + 1) & (cs.ant_body == lo))
        assert abs(np.abs(Fz[sel].sum()) / (above * W) - 1) <= 1e-9, (lo, Fz[sel].sum(), above * W)
    assert abs(floor.reaction[2] / (3 * W) - 1) <= 1e-9
    # Poisson expansion differs from block to block, so joint points carry friction, but its resultant vanishes
    # (horizontal equilibrium) and every point is inside its Coulomb disk
    for lo in range(3):
        sel = ((cs.cand_body == lo) & (cs.ant_body == lo + 1)) | ((cs.cand_body == lo + 1) & (cs.ant_body == lo))
        assert np.linalg.norm(F[sel, :2].sum(axis=0)) <= 1e-9 * W
    assert np.all(np.linalg.norm(r[:, 1:], axis=1) <= 0.6 * r[:, 0] * (1 + 1e-9))


# ----------------------------------------------------------------------------- rigid block dropped flat
def drop_scene(redetect_every=4):
    floor = floor_on(np.eye(3))
    blk = RigidBody3D.box(1.0, 0.8, 0.5, origin=(-0.5, -0.4, 0.02), rho=2000.0, name="block")
    itf = InterfaceSpec("joint", ("block", "floor"), mu=0.5, alert=0.05, candidate="block")
    cst = contact([itf], ["floor", "block"], geometry="updated", redetect_every=redetect_every)
    return Simulation([floor, blk], 1e-3, 0.5, contact=cst), blk, cst


@pytest.mark.parametrize("theta", [0.5, 1.0])
def test_rigid_block_dropped_flat(theta):
    """Drop from 2 cm, updated geometry (re-detection every 4 steps, detection_3d.update_geometry in between):
    the contact points never penetrate the floor beyond the solver tolerance (gaps recomputed from the current
    positions after every step), free flight changes the energy by exactly -(θ - 1/2) m h² g² per step
    (conserved for θ = 1/2), and the total energy never grows (per step <= 1e-9 m g z0, the NLGS residual being 1e-10).
    θ = 1: the impact is inelastic and the block ends at rest on the floor (E = -m g z0). θ = 0.5: the Signorini
    condition on the gap-shifted velocity v_N + ḡ/(hθ) closes the gap exactly in the impact step, and in the
    next step ḡ = h(1-θ) v_N,i < 0 forces v_N,i+1 = -v_N,i: the block rebounds (energy lost in the impact
    step only), a known property of the position-level θ = 0.5 scheme (docs/architecture.md)."""
    sim, blk, cst = drop_scene()
    sim.set_step(1e-3, theta)
    z0 = blk.current_points()[:, 2].min()
    E, vz = [sim.info().total_energy], []
    gmin, hit = np.inf, None
    for k in range(150):
        info = sim.step()
        E.append(info.total_energy)
        vz.append(blk.u[2])
        s = cst.scene
        gmin = min(gmin, update_geometry(cst.cs, s.positions(), s.bfaces).gap.min())
        if hit is None and info.contact["active"]:
            hit = k
    E = np.array(E)
    scale = 2000.0 * 0.4 * G * z0  # potential energy released by the fall (E goes from 0 to -scale)
    assert hit is not None and abs((hit + 1) * sim.h - np.sqrt(2 * z0 / G)) <= 2 * sim.h
    # free flight: ΔE = -(θ - 1/2) m h² g² per step (conserved for θ = 1/2)
    assert abs(E[hit] - E[0] + hit * (theta - 0.5) * 800.0 * (sim.h * G) ** 2) <= 1e-12 * scale
    assert np.all(np.diff(E) <= 1e-9 * scale)
    assert E[hit + 1] < E[hit] - 0.1 * scale  # the impact dissipates
    assert gmin >= -1e-9
    if theta == 1.0:
        assert abs(E[-1] + scale) <= 1e-9 * scale and np.linalg.norm(blk.u) <= 1e-9
        assert abs(blk.current_points()[:, 2].min()) <= 1e-9
        assert info.contact["contacts"] == 4 and info.contact["active"] == 4
    else:
        assert abs(vz[hit + 1] + vz[hit]) <= 1e-9  # the rebound after the impact step: v_N,i+1 = -v_N,i
        assert vz[hit + 1] > 0.5 * np.sqrt(2 * G * z0)


def test_checkpoint_round_trip_3d():
    """export_state / restore_state in 3D (rigid orientation, ContactSet, GBlocks, warm start): a run
    restored at step 40 of the drop continues exactly as the uninterrupted run."""
    sim, blk, cst = drop_scene()
    for _ in range(40):
        sim.step()
    state = {**sim.export_state(), **cst.export_state()}
    for _ in range(40):
        sim.step()
    sim2, blk2, cst2 = drop_scene()
    sim2.restore_state(state)
    cst2.restore_state(sim2, state)
    for _ in range(40):
        sim2.step()
    assert "sim.body1.orientation" in state and state["contact.P"].shape == (4, 3)
    assert np.array_equal(blk2.q, blk.q) and np.array_equal(blk2.u, blk.u)
    assert np.array_equal(blk2.orientation, blk.orientation) and np.array_equal(cst2.P, cst.P)


# ----------------------------------------------------------------------------- platen test
def test_block_under_driven_platen():
    """Unit cube (2x2x2 Q1) between a fixed rigid floor and a massless rigid platen driven down by δ, frictionless
    contacts (lateral Poisson expansion free), quasi-static (velocity reset, θ = 1), no gravity: homogeneous
    uniaxial stress (exact for Q1), reaction of the platen's driver = E A δ / L and the lateral strain = ν δ / L,
    within 1e-8 (brief: 1 %; measured 1e-15 and 6e-13)."""
    E, nu, L, delta = 1e7, 0.25, 1.0, 1e-3
    bt = BlockType3D(mesh_box(L, L, L, divisions=(2, 2, 2)), Material(E, nu, 1000.0))
    blk = DeformableBody3D(bt, position=(-0.5, -0.5, 0.0), name="block")
    drv = dict(FIXED)
    drv["z"] = Driver("displacement", History([0.0, 0.1, 1.0], [0.0, -delta, -delta]))
    platen = RigidBody3D.box(2.0, 2.0, 0.2, origin=(-1.0, -1.0, L), drivers=drv, name="platen")
    itfs = [InterfaceSpec(f"j{k}", ("block", g), mu=0.0, candidate="block") for k, g in enumerate(("floor", "platen"))]
    cst = contact(itfs, ["floor", "block", "platen"])
    sim = Simulation([floor_on(np.eye(3)), blk, platen], 1e-2, 1.0, gravity=(0.0, 0.0, 0.0), velocity_reset=True,
                     contact=cst)
    for _ in range(40):
        info = sim.step()
    assert info.contact["converged"] and info.contact["contacts"] == 32
    F = E * L * L * delta / L
    assert abs(-platen.reaction[2] / F - 1) <= 1e-8
    assert np.max(np.abs(platen.reaction[[0, 1, 3, 4, 5]])) <= 1e-6 * F  # no friction, centred load
    X = bt.mesh.points
    width = np.ptp((X + blk.q.reshape(-1, 3))[:, 0])
    assert abs((width - L) / L / (nu * delta / L) - 1) <= 1e-8


def test_dimension_mixing_rejected():
    bt = BlockType3D(mesh_box(1.0, 1.0, 1.0, divisions=(1, 1, 1)), Material(1e7, 0.2, 1000.0))
    from fem_blocks.bodies import RigidBody
    with pytest.raises(InputError, match="share the dimension"):
        Simulation([DeformableBody3D(bt), RigidBody([(0, 0), (1, 0), (1, 1)], rho=1.0)], 1e-3)
    with pytest.raises(InputError, match="gravity"):
        Simulation([DeformableBody3D(bt)], 1e-3, gravity=(0.0, -9.81))


# ----------------------------------------------------------------------------- no contact: 3D free motions
def test_free_fall_and_spin_3d():
    """Without contact: a deformable block in free fall (θ = 0.5) has the centre-of-mass velocity g t and
    conserves kinetic + elastic + gravity energy (trapezoidal rule), to 1e-12; a rigid box spinning about a
    principal axis (no gyroscopic moment) keeps ω and its orientation after n steps is exp([n h ω]x); a torque-free
    spin about a non-principal axis (tumbling) keeps the angular momentum I ω within 1e-4 and the kinetic energy
    within 1e-7 over 100 steps of h |ω| = 2.3e-3 (explicit gyroscopic moment: first order; measured 5e-5, 7e-9)."""
    bt = BlockType3D(mesh_box(1.0, 0.6, 0.4, divisions=(2, 1, 1)), Material(1e7, 0.3, 1000.0))
    blk = DeformableBody3D(bt, R=rotation3d((1.0, 2.0, 3.0), 0.5))
    rb = RigidBody3D.box(1.0, 0.6, 0.4, rho=1000.0, origin=(5.0, 0.0, 0.0))
    w0 = np.array([0.0, 0.0, 3.0])
    rb.u[3:] = w0
    sim = Simulation([blk, rb], 1e-3, 0.5)
    E0 = sim.info().total_energy
    for _ in range(100):
        info = sim.step()
    assert np.allclose(com_velocity(blk), [0.0, 0.0, -G * sim.time], rtol=0, atol=1e-12)
    assert np.allclose(rb.u[:3], [0.0, 0.0, -G * sim.time], rtol=0, atol=1e-12)
    rigid_rot = 0.5 * float(w0 @ rb.inertia0 @ w0)
    assert abs(info.total_energy - E0) <= 1e-12 * (info.kinetic + rigid_rot)
    assert np.allclose(rb.u[3:], w0, atol=1e-14)
    assert np.allclose(rb.orientation, rotation3d(w0 * sim.time), atol=1e-13)
    rb2 = RigidBody3D.box(1.0, 0.6, 0.4, rho=1000.0)
    rb2.u[3:] = (1.0, 0.5, 2.0)
    sim2 = Simulation([rb2], 1e-3, 0.5, gravity=(0.0, 0.0, 0.0))
    L0, K0 = rb2.inertia @ rb2.u[3:], sim2.info().kinetic
    for _ in range(100):
        info = sim2.step()
    assert np.linalg.norm(rb2.inertia @ rb2.u[3:] - L0) <= 1e-4 * np.linalg.norm(L0)
    assert abs(info.kinetic / K0 - 1) <= 1e-7


def test_solver_and_law_options_3d():
    """Interface laws run in 3D with NLGS; with the global Newton solver (Coulomb only in 3D) they are rejected
    with an InputError naming the interface; Newton gives the NLGS motion of the sliding rigid block."""
    def incline_sim(itf, **opts):
        Q = incline(ALPHA, 0.7)
        blk = RigidBody3D(box_corners(1.0, 1.0, 0.5, (-0.5, -0.5, 0.0)) @ Q.T, rho=2000.0, name="block")
        return Simulation([floor_on(Q), blk], 1e-3, 0.5, contact=contact([itf], ["floor", "block"], **opts)), blk

    glue = InterfaceSpec("glue", ("block", "floor"), law="elastic", candidate="block",
                         params={"mu": 0.2, "c_N": 1e9, "c_T": 1e9})
    sim, _ = incline_sim(glue, solver="newton")
    with pytest.raises(InputError, match="interfaces.glue.law"):
        sim.step()
    sim, blk = incline_sim(glue)
    for _ in range(5):
        info = sim.step()
    assert info.contact["converged"]
    itf = InterfaceSpec("joint", ("block", "floor"), mu=0.2, candidate="block")
    sim, blk = incline_sim(itf, solver="newton")
    ref_sim, ref = incline_sim(itf)
    for _ in range(20):
        sim.step()
        ref_sim.step()
    assert np.allclose(blk.u, ref.u, rtol=0, atol=1e-9)


def test_rotation_displacement_driver_3d():
    """A displacement driver on a 3D rotation dof sets the orientation exactly: Rot(t) = exp([φ(t) e_z]x) with the
    θ-rule increments completed by the remaining rotation, whatever θ."""
    drivers = {k: ("velocity", 0.0) for k in ("x", "y", "z", "rx", "ry")}
    drivers["rz"] = Driver("displacement", History([0.0, 0.05, 0.1], [0.0, 0.3, 0.2]))
    rb = RigidBody3D.box(1.0, 0.6, 0.4, rho=1000.0, drivers=drivers)
    sim = Simulation([rb], 1e-3, 0.7)
    for _ in range(80):
        sim.step()
    phi = rb.drivers[5].history(sim.time)
    assert np.allclose(rb.orientation, rotation3d(EZ, phi), atol=1e-13) and abs(rb.q[5] - phi) <= 1e-13
    assert abs(rb.u[5] - (0.2 - 0.3) / 0.05) <= 1e-9


# ----------------------------------------------------------------------------- interface laws in the 3D time step
@pytest.mark.parametrize("pull", [30e3, 150e3])
def test_fremond_joint_pulled_3d(pull):
    """Rigid 1 x 1 x 0.5 m block (1000 kg) glued on a fixed floor by a Frémond–Cangémi joint (c_N = 1e9 N/m³,
    w = 10 J/m²: peak tension √(w c_N) A = 100 kN), pulled up by a constant force, quasi-static (θ = 1, velocity
    reset). Below the peak the joint opens by (F - m g)/(c_N A) with β = 1 (Y = c_N u² < w); above it the joint
    breaks (β → 0) and the block leaves."""
    c_N, w, m = 1e9, 10.0, 1000.0
    blk = RigidBody3D(box_corners(1.0, 1.0, 0.5, (-0.5, -0.5, 0.0)), mass=m, forces={"z": pull}, name="block")
    itf = InterfaceSpec("joint", ("block", "floor"), law="fremond", candidate="block",
                        params=dict(c_N=c_N, c_T=c_N, w=w, mu=0.7))
    cst = contact([itf], ["floor", "block"], tol=1e-12)
    sim = Simulation([floor_on(np.eye(3)), blk], 1e-3, 1.0, velocity_reset=True, contact=cst)
    for _ in range(30):
        info = sim.step()
    assert info.contact["converged"]
    from fem_blocks.laws import S_BETA
    lift = blk.q[2]
    if pull < np.sqrt(w * c_N):
        u_exact = (pull - m * G) / c_N
        assert abs(lift / u_exact - 1) <= 1e-8
        assert np.all(cst.state[:, S_BETA] == 1.0)
        assert np.linalg.norm(blk.q[3:]) <= 1e-12  # no tilt
    else:
        assert np.all(cst.state[:, S_BETA] < 1e-3)
        assert lift > 10 * np.sqrt(w / c_N)


@pytest.mark.parametrize("geometry", ["frozen", "updated"])
@pytest.mark.parametrize("reference", ["nominal", "as_built"])
def test_joint_reference_as_built(reference, geometry):
    """A rigid block placed 1 mm above the floor (alert 5 mm). Nominal reference: the joint is open, the block
    falls the 1 mm before it lands. `reference = "as_built"`: the joint is closed as built (reference gap = initial
    gap), the floor carries the weight from the first step and the block does not move (≤ 1e-12 m). The same in
    updated geometry (the initial contacts carry their 1 mm as an offset, contact/step.py)."""
    m = 1000.0
    blk = RigidBody3D(box_corners(1.0, 1.0, 0.5, (-0.5, -0.5, 1e-3)), mass=m, name="block")
    itf = InterfaceSpec("joint", ("block", "floor"), mu=0.5, alert=5e-3, candidate="block", reference=reference)
    floor = floor_on(np.eye(3))
    sim = Simulation([floor, blk], 1e-3, 1.0, contact=contact([itf], ["floor", "block"], geometry=geometry))
    sim.step()
    if reference == "as_built":
        assert abs(floor.reaction[2] / (m * G) - 1) <= 1e-9
        for _ in range(20):
            sim.step()
        assert abs(blk.q[2]) <= 1e-12
    else:
        assert abs(floor.reaction[2]) <= 1e-9 * m * G  # still in free fall
        for _ in range(40):
            sim.step()
        assert abs(blk.q[2] + 1e-3) <= 1e-9  # landed on the floor


def test_joint_reference_checked():
    with pytest.raises(InputError, match="interfaces.j.reference"):
        InterfaceSpec("j", ("a", "b"), reference="built")


def test_contact_fallback_newton_option(monkeypatch):
    """[contact] fallback = "newton": the option reaches the NLGS call of the time step (stack of 3 rigid boxes on a
    floor at equilibrium: reactions = weight to 1e-9) and bad combinations are rejected."""
    from fem_blocks.solver import driver
    seen = []
    real = driver.nlgs_then_newton

    def spy(problem, options, *a, **k):
        seen.append(options.fallback)
        return real(problem, options, *a, **k)
    monkeypatch.setattr(driver, "nlgs_then_newton", spy)
    boxes = [RigidBody3D(box_corners(1.0, 1.0, 0.5, (-0.5, -0.5, 0.5 * k)), mass=100.0, name=f"b{k}") for k in range(3)]
    itfs = [InterfaceSpec("bed", ("block", "floor"), mu=0.6, candidate="block"),
            InterfaceSpec("joint", ("block", "block"), mu=0.6)]
    floor = floor_on(np.eye(3))
    cst = contact(itfs, ["floor", "block", "block", "block"], fallback="newton", tol=1e-10)
    sim = Simulation([floor] + boxes, 1e-3, 1.0, velocity_reset=True, contact=cst)
    for _ in range(5):
        info = sim.step()
    assert info.contact["converged"]
    assert seen.count("newton") == 5  # solve() dispatches to the fallback path once per step
    assert abs(floor.reaction[2] / (300.0 * G) - 1) <= 1e-9
    with pytest.raises(InputError, match="contact.fallback"):
        ContactOptions(fallback="newton", criterion="change")
    with pytest.raises(InputError, match="contact.fallback"):
        ContactOptions(fallback="yes")
