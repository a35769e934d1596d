"""2D contact engine acceptance tests: incline, pusher, stack, murette, arch, bad input.

Closed forms: sliding s(t) = g (sin a - mu cos a) t^2 / 2; pusher force mu m g; reactions at every joint
of a stack equal the weight above; ground reaction equals the wall's weight."""
import numpy as np
import pytest

from fem_blocks import builders
from fem_blocks.bodies import BlockType, DeformableBody, Driver, Material, RigidBody, rotation
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.errors import InputError
from fem_blocks.meshing import mesh_polygon, mesh_rectangle

pytestmark = pytest.mark.dolfinx
G = 9.81
FIXED = {k: ("velocity", 0.0) for k in ("x", "y", "rz")}


def fixed_body(vertices):
    return RigidBody(vertices, drivers={k: Driver(*v) for k, v in FIXED.items()}, name="ground")


def incline_scene(alpha, mu, deformable):
    R = rotation(alpha)
    base = np.array([[-3, -0.5], [3, -0.5], [3, 0], [-3, 0]]) @ R.T
    if deformable:
        bt = BlockType(mesh_rectangle(0.4, 0.2, 0.1), Material(E=1e10, nu=0.2, rho=1000.0, thickness=1.0))
        blk = DeformableBody(bt, position=(0, 0), angle=alpha)
    else:
        blk = RigidBody(np.array([[0, 0], [0.4, 0], [0.4, 0.2], [0, 0.2]]) @ R.T, rho=1000.0)
    cs = ContactStep([InterfaceSpec("i", ("block", "ground"), mu=mu)], ["block", "ground"],
                     ContactOptions(tol=1e-12, max_sweeps=10000))
    return blk, fixed_body(base), cs


def slope_displacement(blk, alpha):
    e = rotation(alpha)[:, 0]
    if blk.kind == 1:
        return float(blk.q[:2] @ e)
    m = blk.type.M.diagonal()
    d = blk.displacement_global()
    return float((m[0::2] @ d) @ e / m[0::2].sum())


@pytest.mark.parametrize("deformable", [False, True], ids=["rigid", "deformable"])
def test_block_on_incline(deformable):
    alpha = np.deg2rad(20.0)
    # mu > tan(alpha): stays put
    blk, ground, cs = incline_scene(alpha, 0.5, deformable)
    sim = Simulation([blk, ground], h=2e-3, theta=1.0 if deformable else 0.5, contact=cs)
    for _ in range(500):
        sim.step()
    if deformable:  # the block deforms under its weight; the contact points must not slip
        from fem_blocks.contact import kinematics_2d as kin
        slip = kin.local_velocity(cs.G, cs.scene.gather("q"), cs.scene.U_offset)[:, 1]
        assert np.abs(slip).max() < 1e-9
    else:
        assert abs(slope_displacement(blk, alpha)) < 1e-9
    # mu < tan(alpha): slides with a = g (sin a - mu cos a)
    mu = 0.2
    blk, ground, cs = incline_scene(alpha, mu, deformable)
    sim = Simulation([blk, ground], h=2e-3, theta=0.5, contact=cs)
    for _ in range(500):
        sim.step()
    a = G * (np.sin(alpha) - mu * np.cos(alpha))
    s = -slope_displacement(blk, alpha)
    assert s == pytest.approx(0.5 * a * sim.time ** 2, rel=0.01)
    if not deformable:
        assert s == pytest.approx(0.5 * a * sim.time ** 2, rel=1e-10)  # theta = 1/2 is exact here


@pytest.mark.parametrize("deformable", [False, True], ids=["rigid", "deformable"])
def test_pusher_reaction_is_friction(deformable):
    mu, v0, rho = 0.4, 0.05, 2000.0
    L, H = 0.3, 0.15
    if deformable:
        bt = BlockType(mesh_rectangle(L, H, 0.05), Material(E=1e8, nu=0.2, rho=rho, thickness=1.0))
        blk = DeformableBody(bt, position=(0.0, 0.0))
    else:
        blk = RigidBody([(0, 0), (L, 0), (L, H), (0, H)], rho=rho)
    m = rho * L * H
    ground = fixed_body([(-1, -0.2), (2, -0.2), (2, 0), (-1, 0)])
    ramp = {"times": [0.0, 0.1, 10.0], "values": [0.0, v0, v0]}
    pusher = RigidBody([(-0.1, 0.02), (0.0, 0.02), (0.0, 0.12), (-0.1, 0.12)],
                       drivers={"x": Driver("velocity", ramp), "y": Driver("velocity", 0.0),
                                "rz": Driver("velocity", 0.0)}, name="pusher")
    cs = ContactStep([InterfaceSpec("floor", ("block", "ground"), mu=mu),
                      InterfaceSpec("push", ("block", "pusher"), mu=0.0)],
                     ["block", "ground", "pusher"], ContactOptions(tol=1e-12, max_sweeps=20000))
    sim = Simulation([blk, ground, pusher], h=1e-3, theta=1.0, contact=cs)
    R = []
    for k in range(600):
        sim.step()
        if sim.time > 0.3:
            R.append(pusher.reaction[0])
    assert np.mean(R) == pytest.approx(mu * m * G, rel=0.005)
    assert pusher.q[0] == pytest.approx(v0 * (sim.time - 0.05), abs=1e-3 * v0)  # theta = 1 rectangle rule


def stack(n=10):
    mat = Material(E=1e9, nu=0.2, rho=2000.0, thickness=0.1)
    bt = BlockType(mesh_rectangle(0.3, 0.1, 0.05), mat)
    blocks = [DeformableBody(bt, (0.0, 0.1 * i)) for i in range(n)]
    floor = fixed_body([(-0.5, -0.2), (0.8, -0.2), (0.8, 0), (-0.5, 0)])
    cs = ContactStep([InterfaceSpec("joint", ("b", "b"), mu=0.6), InterfaceSpec("floor", ("b", "floor"), mu=0.6)],
                     ["b"] * n + ["floor"], ContactOptions(tol=1e-12, max_sweeps=200000))
    return blocks, floor, cs, 2000.0 * 0.3 * 0.1 * 0.1


def test_stack_reactions_equal_weight_above():
    n = 10
    blocks, floor, cs, m = stack(n)
    sim = Simulation(blocks + [floor], h=1e-2, theta=1.0, contact=cs, velocity_reset=True)
    for _ in range(20):
        info = sim.step()
    assert info.contact["converged"]
    c, r = sim.last_contact.cs, sim.last_contact.r
    for j in range(n):
        below = n if j == 0 else j - 1  # the floor is body n
        sel = ((c.cand_body == j) & (c.ant_body == below)) | ((c.cand_body == below) & (c.ant_body == j))
        assert sel.sum() > 0
        assert r[sel, 0].sum() == pytest.approx((n - j) * m * G, rel=1e-6)
    assert floor.reaction[1] == pytest.approx(n * m * G, rel=1e-6)
    assert sim.last_contact.gt_end.min() > -1e-9


def test_murette_running_bond_equilibrium():
    """12-course running-bond wall (thesis §7.1) of deformable bricks on a rigid floor, velocity reset."""
    L, H, courses = 0.2, 0.05, 12
    blocks = builders.running_bond(courses, 4, L, H)
    mat = Material(E=5e9, nu=0.2, rho=1800.0, thickness=0.1)
    types = {}
    bodies, groups = [], []
    for b in blocks:
        if b.size_key not in types:
            types[b.size_key] = BlockType(mesh_rectangle(b.length, b.height, 0.05, cell="triangle"), mat)
        bodies.append(DeformableBody(types[b.size_key], (b.x, b.y)))
        groups.append("bricks")
    floor = fixed_body([(-0.5, -0.1), (1.3, -0.1), (1.3, 0.0), (-0.5, 0.0)])
    cs = ContactStep([InterfaceSpec("joints", ("bricks", "bricks"), mu=0.7),
                      InterfaceSpec("floor", ("bricks", "ground"), mu=0.7)],
                     groups + ["ground"], ContactOptions(tol=1e-6, max_sweeps=100000))
    sim = Simulation(bodies + [floor], h=1e-3, theta=1.0, contact=cs, velocity_reset=True)
    for _ in range(300):
        info = sim.step()
    weight = sum(mat.rho * b.length * b.height * mat.thickness for b in blocks) * G
    assert floor.reaction[1] == pytest.approx(weight, rel=1e-6)
    c, r = sim.last_contact.cs, sim.last_contact.r
    bed = np.abs(c.n[:, 1]) > 0.9
    for cb, ab in set(zip(c.cand_body[bed], c.ant_body[bed])):
        sel = bed & (c.cand_body == cb) & (c.ant_body == ab)
        assert r[sel, 0].sum() > 0, f"bed joint between bodies {cb} and {ab} is open"
    assert info.max_velocity < 1e-6


def arch_scene(t_over_R, n=15, R=1.0, mu=0.5):
    """Semicircular arch of n identical voussoirs (one rotated block type) on two fixed rigid supports."""
    t = t_over_R * R
    ri, re = R - t / 2, R + t / 2
    dth = np.pi / n
    a = np.linspace(-dth / 2, dth / 2, 5)
    poly = np.concatenate([np.column_stack([ri * np.cos(a), ri * np.sin(a)]),
                           np.column_stack([re * np.cos(a[::-1]), re * np.sin(a[::-1])])])
    bt = BlockType(mesh_polygon(poly, t / 4), Material(E=1e10, nu=0.2, rho=2000.0, thickness=1.0))
    vous = [DeformableBody(bt, (0.0, 0.0), angle=np.pi - (k + 0.5) * dth) for k in range(n)]
    left = fixed_body([(-re - 0.2, -0.5), (-ri + 0.2, -0.5), (-ri + 0.2, 0.0), (-re - 0.2, 0.0)])
    right = fixed_body([(ri - 0.2, -0.5), (re + 0.2, -0.5), (re + 0.2, 0.0), (ri - 0.2, 0.0)])
    cs = ContactStep([InterfaceSpec("joints", ("v", "v"), mu=mu), InterfaceSpec("supports", ("v", "s"), mu=mu)],
                     ["v"] * n + ["s", "s"], ContactOptions(tol=1e-8, max_sweeps=50000))
    return vous, [left, right], cs


@pytest.mark.parametrize("t_over_R, stands", [(0.15, True), (0.08, False)])
def test_arch_stands_or_collapses(t_over_R, stands):
    vous, sup, cs = arch_scene(t_over_R)
    sim = Simulation(vous + sup, h=2e-3, theta=1.0, contact=cs)
    crown = vous[len(vous) // 2]
    for _ in range(150):
        sim.step()
    drop = -crown.displacement_global()[:, 1].mean()
    if stands:
        assert drop < 1e-4 and sim.info().max_velocity < 1e-3
    else:
        assert drop > 5e-3


def test_overlap_at_start_is_an_error():
    blocks, floor, cs, m = stack(2)
    blocks[1].position = blocks[1].position - np.array([0.0, 0.02])  # 2 cm into the block below
    sim = Simulation(blocks + [floor], h=1e-2, theta=1.0, contact=cs)
    with pytest.raises(InputError, match=r"bodies 0 and 1 overlap at the start by 0\.02 m"):
        sim.step()


def test_bad_interface_parameters():
    with pytest.raises(InputError, match=r"interfaces\.j\.mu = -0\.1: expected mu >= 0"):
        InterfaceSpec("j", ("a", "a"), mu=-0.1)
    with pytest.raises(InputError, match=r"interfaces\.j\.alert"):
        InterfaceSpec("j", ("a", "a"), alert=0.0)
    with pytest.raises(InputError, match=r"interfaces\.j\.g0"):
        InterfaceSpec("j", ("a", "a"), g0=-1e-3)
    with pytest.raises(InputError, match="group 'c' has no body"):
        ContactStep([InterfaceSpec("j", ("a", "c"))], ["a", "a"])


def test_contacts_survive_a_change_of_time_step():
    """Stages with different h rebuild the step operators; contacts must keep acting on the new state."""
    blocks, floor, cs, m = stack(3)
    sim = Simulation(blocks + [floor], h=1e-3, theta=1.0, contact=cs, velocity_reset=True)
    for _ in range(50):
        sim.step()
    sim.set_step(2e-3, 1.0)
    for _ in range(50):
        sim.step()
    assert floor.reaction[1] == pytest.approx(3 * m * G, rel=1e-4)
    assert sim.info().max_velocity < 1e-6


def test_updated_geometry_follows_large_sliding():
    """A block pushed from one rigid slab onto the next: with re-detection ('updated' geometry) the second
    slab carries the whole weight at the end; the first carries nothing."""
    m_rho, L, H = 1000.0, 0.2, 0.1
    blk = RigidBody([(0.05, 0), (0.05 + L, 0), (0.05 + L, H), (0.05, H)], rho=m_rho)
    s1 = RigidBody([(-0.5, -0.1), (0.3, -0.1), (0.3, 0), (-0.5, 0)],
                   drivers={k: Driver("velocity", 0.0) for k in ("x", "y", "rz")}, name="s1")
    s2 = RigidBody([(0.3, -0.1), (1.5, -0.1), (1.5, 0), (0.3, 0)],
                   drivers={k: Driver("velocity", 0.0) for k in ("x", "y", "rz")}, name="s2")
    pusher = RigidBody([(-0.05, 0.02), (0.05, 0.02), (0.05, 0.08), (-0.05, 0.08)],
                       drivers={"x": Driver("velocity", 0.5), "y": Driver("velocity", 0.0),
                                "rz": Driver("velocity", 0.0)}, name="pusher")
    cs = ContactStep([InterfaceSpec("floor", ("b", "s"), mu=0.3), InterfaceSpec("push", ("b", "p"), mu=0.0)],
                     ["b", "s", "s", "p"], ContactOptions(geometry="updated", tol=1e-10, max_sweeps=10000))
    sim = Simulation([blk, s1, s2, pusher], h=1e-3, theta=1.0, contact=cs)
    for _ in range(1000):  # 0.5 m of travel
        sim.step()
    weight = m_rho * L * H * G
    assert blk.center[0] > 0.3 + L / 2 + 0.05  # fully on the second slab
    assert s2.reaction[1] == pytest.approx(weight, rel=1e-6)
    assert abs(s1.reaction[1]) < 1e-9 * weight
    assert sim.last_contact.gt_end.min() > -1e-9


def test_residual_criterion_in_time_stepping():
    """With criterion = 'residual' each step stops on the natural-map residual ‖F‖/‖q‖ <= tol, and the residual
    reported (recomputed from the returned impulses) meets it."""
    blocks, floor, cs, m = stack(3)
    cs.opts = ContactOptions(tol=1e-10, max_sweeps=200000, criterion="residual", check_every=5)
    sim = Simulation(blocks + [floor], h=1e-2, theta=1.0, contact=cs, velocity_reset=True)
    for _ in range(5):
        info = sim.step()
        assert info.contact["converged"] and info.contact["residual"] <= 1e-10
    assert floor.reaction[1] == pytest.approx(3 * m * G, rel=1e-8)
    with pytest.raises(InputError, match="contact.criterion = 'energy'"):
        ContactOptions(criterion="energy")
