"""Contacts of blocks that turn on a corner, and the facing test of the narrow phase (issue #22).

The narrow phase examines a (candidate edge/face, antagonist edge/face) pair only if their outward normals are
within `max_angle` of opposite ([[interfaces]] max_angle, default 60°). Why 60° (docs/case-files.md "max_angle"):

* a corner of a right-angled block touching a flat antagonist: its two edges make θ and 90° − θ with the
  antagonist, so one of them is within 45° of facing at ANY tilt θ: max_angle must be ≥ 45° in 2D. In 3D a box
  on an edge: the same 45°; on a vertex, the three faces' normals are orthonormal, so the cosines of their angles
  with the antagonist's normal satisfy Σ cos² = 1 and the largest is ≥ 1/√3: one face is within 54.74° of facing.
  60° leaves 5.3° (3D vertex) and 15° (edge, 2D corner) of margin for the deformation and the penetration.
* an edge perpendicular to the antagonist (the side of a brick against the top of the brick below) is no contact
  surface: its only point in contact is the corner, already the end of the bottom edge; if the pair were
  examined, the corner would receive a share of the side edge as tributary length (overlap: half the side edge's
  overlap with the antagonist projected on it; nodes: half the side edge), i.e. a cohesive corner stronger than
  the joint. Excluded for tilts θ < 90° − max_angle = 30° (the first tests below).

The dynamic tests: a stiff deformable block standing on one corner on a rigid floor, released from rest. Rigid
solution (the same reduction as tests/test_rocking.py): with α = atan(b/h), R the half-diagonal and the pivot
fixed (μ = 2), the angle φ of the centre of mass from the vertical through the pivot obeys φ'' = p² sin φ,
p² = 3g/(4R) (I_O = 4/3 m R²); the block falls to the side its centre of mass is on and lands when φ = −α
(back on its base) or φ = 90° − α (on its side face), integrated with scipy's solve_ivp as the reference.
"""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fem_blocks.bodies import BlockType, DeformableBody, Driver, Material, RigidBody, rotation
from fem_blocks.contact import detection_2d as det
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.meshing import mesh_rectangle
from fem_blocks.specs import default_of


def test_default_facing_angle_bounds():
    """The default lies between the 3D vertex bound acos(1/√3) = 54.74° and 90° (perpendicular pairs out)."""
    a = default_of(InterfaceSpec, "max_angle")
    assert np.degrees(np.arccos(1 / np.sqrt(3))) + 5 <= a <= 90 - 25
    assert det.MAX_ANGLE == a


# ----------------------------------------------------------------------------- the spurious pair (static)
def corner_contacts(tilt_deg, placement, max_angle=None, b=0.4, h=0.2):
    """A b x h block (4 boundary nodes) tilted clockwise by tilt_deg about its bottom-right corner, which rests on
    the top of a 2 m wide floor block at the origin; one interface; the block is candidate (lower index)."""
    R = rotation(-np.radians(tilt_deg))
    blk = np.array([(-b, 0.0), (0.0, 0.0), (0.0, h), (-b, h)]) @ R.T
    floor = np.array([(-1.0, -0.1), (1.0, -0.1), (1.0, 0.0), (-1.0, 0.0)])
    kw = {} if max_angle is None else dict(max_angle=max_angle)
    itf = InterfaceSpec("i", ("a", "a"), alert=1e-3, placement=placement, **kw)
    bx = np.vstack([blk, floor])
    edges = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4]])
    body = np.r_[np.zeros(4, int), np.ones(4, int)]
    return det.detect(bx, body, np.r_[np.arange(4), np.arange(4)], edges, body[[0, 0, 0, 0, 4, 4, 4, 4]],
                      np.zeros(2, int), np.zeros(2, int), det.build_table([itf], {"a": 0}))


@pytest.mark.parametrize("placement", ["overlap", "nodes"])
@pytest.mark.parametrize("tilt", [2.0, 10.0, 29.0])
def test_side_edge_gives_the_corner_no_area(placement, tilt):
    """Block on its corner, tilted by less than 90° − max_angle: one contact, at the corner, normal +y, tributary
    length half the bottom edge (nodes) / half the bottom edge's overlap with the floor (overlap; the whole
    tilted edge projects on the floor: b/2 again). Opening the facing test to 89° adds the side edge's share
    (h/2 with nodes; min(h, d sin θ)/2 with overlap, d = 1 m of floor right of the corner projected on the side
    edge) — the bug this guards."""
    for ma, spurious in ((None, False), (89.0, True)):
        cs = corner_contacts(tilt, placement, ma)
        assert len(cs) == 1
        np.testing.assert_allclose(cs.point[0], [0.0, 0.0], atol=1e-15)
        np.testing.assert_allclose(cs.n[0], [0.0, 1.0], atol=1e-15)
        # overlap: the floor right of the corner (1 m) projects on the side edge over 1 m x sin θ
        extra = 0.2 / 2 if placement == "nodes" else min(0.2, 1.0 * np.sin(np.radians(tilt))) / 2
        want = 0.4 / 2 + (extra if spurious else 0.0)
        assert cs.area[0] == pytest.approx(want, rel=1e-12)


@pytest.mark.parametrize("placement", ["overlap", "nodes"])
@pytest.mark.parametrize("tilt", [0.0, 29.0, 31.0, 44.0, 45.0, 46.0, 59.0, 61.0, 89.0])
def test_corner_found_at_any_tilt(placement, tilt):
    """The corner is a contact at every tilt of a right-angled block (the 30° default lost it between 30° and
    60°: neither edge within 30° of facing)."""
    cs = corner_contacts(tilt, placement)
    at_corner = np.linalg.norm(cs.point, axis=1) < 1e-12
    assert at_corner.sum() == 1
    assert abs(cs.gap[at_corner][0]) < 1e-15
    if 30.0 < tilt < 60.0:
        assert len(corner_contacts(tilt, placement, 30.0)) == 0


# ----------------------------------------------------------------------------- a block falling from a corner (2D)
G, RHO = 9.81, 2000.0
BW, BH = 0.168, 0.2                      # α = atan(b/h) = 40.0°
ALPHA = np.arctan(BW / BH)
R_HALF = 0.5 * np.hypot(BW, BH)
P2 = 3 * G / (4 * R_HALF)


def rigid_landing(beta):
    """Rigid block on its corner, bottom edge at beta from the floor (clockwise about the bottom-right corner),
    released from rest: φ = beta − α (centre of mass right of the pivot when > 0), φ'' = p² sin φ; returns the
    side it falls to (+1: onto its right side face, tilt → 90°; -1: back on its base, tilt → 0) and the landing
    time."""
    phi0 = beta - ALPHA
    side = 1 if phi0 > 0 else -1
    target = np.pi / 2 - ALPHA if side > 0 else -ALPHA
    ev = lambda t, y: y[0] - target  # noqa: E731
    ev.terminal = True
    sol = solve_ivp(lambda t, y: [y[1], P2 * np.sin(y[0])], (0.0, 5.0), [phi0, 0.0], rtol=1e-12, atol=1e-14,
                    events=ev)
    return side, float(sol.t_events[0][0])


def fall_from_corner(beta, h=1e-3, max_angle=None, until=None):
    """Stiff deformable block (E = 1e10, Q4 2 x 2, consistent mass) with its bottom edge at beta [rad] from the
    rigid floor, the bottom-right corner on the floor at the origin; updated geometry (co-rotational block).
    Steps until it lands (tilt beta − rotation reaches 0 or 90°) or t > until. Returns times, tilts and the
    deepest penetration of a block node below the floor's top (y < 0) over the run."""
    floor = RigidBody([(-1.0, -0.1), (1.0, -0.1), (1.0, 0.0), (-1.0, 0.0)],
                      drivers={k: Driver("velocity", 0.0) for k in ("x", "y", "rz")}, name="floor")
    kw = {} if max_angle is None else dict(max_angle=max_angle)
    cs = ContactStep([InterfaceSpec("base", ("block", "floor"), mu=2.0, **kw)], ["block", "floor"],
                     ContactOptions(tol=1e-12, max_sweeps=1000, geometry="updated"))
    Rt = rotation(-beta)
    bt = BlockType(mesh_rectangle(BW, BH, BW / 2, cell="quad"), Material(E=1e10, nu=0.2, rho=RHO),
                   mass="consistent")
    blk = DeformableBody(bt, position=-Rt @ np.array([BW, 0.0]), angle=-beta, name="block")
    sim = Simulation([blk, floor], h=h, theta=0.5, contact=cs)
    ts, th, pen = [0.0], [beta], 0.0
    until = until or 1.5 * rigid_landing(beta)[1]
    while sim.time < until:
        sim.step()
        ts.append(sim.time)
        th.append(beta - blk.rotation())
        pen = max(pen, -float(blk.current_points()[:, 1].min()))
        if th[-1] <= 0.0 or th[-1] >= np.pi / 2:
            break
    return np.array(ts), np.array(th), pen


@pytest.mark.dolfinx
@pytest.mark.parametrize("beta_deg", [35.0, 45.0, 55.0])
def test_block_on_a_corner_falls_to_its_side_without_penetrating(beta_deg):
    """Released on its corner at 35° (centre of mass over the base side: falls back), 45° and 55° (beyond the
    pivot: topples onto its side face): lands on the side of its centre of mass, at the rigid landing time within
    1 % (h = 1e-3 s, 254-403 steps; observed +2.0e-3, +2.6e-3, +3.2e-3: the θ-scheme's lag), and no node goes below
    the floor's top by more than 1e-5 m, the landing step included (observed: none below it; with h = 2e-3 s the
    landing face arrives at ~1.6 mm per step, more than the 1 mm alert, and sinks 2e-4 m: the missed contact of
    tests below). With the former 30° facing limit neither edge of the corner faced the
    floor between 30° and 60°: the block fell through it (checked at 45°: the corner sinks by more than the block's
    size)."""
    beta = np.radians(beta_deg)
    side, t_land = rigid_landing(beta)
    ts, th, pen = fall_from_corner(beta)
    landed = th[-1] >= np.pi / 2 if side > 0 else th[-1] <= 0.0
    assert landed, f"did not land on the side of its centre of mass (tilt {np.degrees(th[-1]):.1f}°)"
    target = np.pi / 2 if side > 0 else 0.0
    t_num = ts[-2] + (ts[-1] - ts[-2]) * (th[-2] - target) / (th[-2] - th[-1])
    print(f"beta {beta_deg}: landing {t_num:.5f} s vs rigid {t_land:.5f} s ({t_num / t_land - 1:+.2e}), "
          f"penetration {pen:.3g} m, {len(ts) - 1} steps")
    assert t_num == pytest.approx(t_land, rel=0.01)
    assert pen <= 1e-5


@pytest.mark.dolfinx
def test_block_on_a_corner_falls_through_with_the_former_limit():
    """The failure the default fixes, with the former 30°: at 45° tilt no contact, the corner goes through."""
    beta = np.radians(45.0)
    ts, th, pen = fall_from_corner(beta, max_angle=30.0, until=0.1)
    assert pen > 0.01


# ----------------------------------------------------------------------------- contacts missed by fast bodies
IMPACT = """
name = "side_impact"
gravity = [0.0, 0.0]
[materials.stone]
E = 1e10
nu = 0.2
rho = 2000.0
thickness = 0.1
[block_types.b]
geometry = "rectangle"
lx = 0.1
ly = 0.1
mesh_size = 0.05
cell = "quad"
material = "stone"
mass = "consistent"
[[blocks]]
name = "blk"
type = "b"
position = [-0.1115, 0.0]   # its right side 11.5 mm from the wall: gaps 9.5, 7.5, ... 1.5, -0.5 mm at 2 mm per step
group = "blk"
initial_velocity = [2.0, 0.0]
[[rigid_bodies]]
name = "wall"
group = "wall"
vertices = [[0.0, -0.5], [0.2, -0.5], [0.2, 0.6], [0.0, 0.6]]
[rigid_bodies.drivers]
x = {kind = "velocity", history = 0.0}
y = {kind = "velocity", history = 0.0}
rz = {kind = "velocity", history = 0.0}
[[interfaces]]
name = "hit"
between = ["blk", "wall"]
mu = 0.0
alert = ALERT
[contact]
geometry = "updated"
tol = 1e-12
max_sweeps = 1000
[output]
paraview = false
[[stages]]
name = "throw"
duration = 0.012
h = 1e-3
theta = 0.5
"""


@pytest.mark.dolfinx
@pytest.mark.parametrize("alert", [1e-3, 1e-2])
def test_fast_side_impact_missed_contact_is_reported(tmp_path, alert, capsys):
    """A block thrown at a fixed wall at 2 m/s, h = 1e-3 s (2 mm per step, no gravity, μ = 0): with alert = 1 mm the
    right side is 1.5 mm from the wall at the start of step 6 (not a contact) and 0.5 mm inside at the start of step
    7: the run warns once (stderr and summary.json "warnings"), naming the interface, and records the depth 5e-4 m
    within 1e-6 m (the free flight is exact: constant velocity) and the suggested alert 2 (1 mm + 0.5 mm) = 3 mm;
    the push-out creates energy (observed: 4 J -> 8.99 J; asserted > 1.5 x). With alert = 1 cm the wall is found
    9.5 mm ahead: no warning, and the energy does not grow (θ = 1/2 conserves the elastic energy of the bounce,
    the contact only dissipates: E_end <= E_0 (1 + 1e-9)). The watch is a runner's: this runs the case file."""
    from fem_blocks.case import load_case
    from fem_blocks.runner import run_case
    p = tmp_path / "impact.toml"
    p.write_text(IMPACT.replace("ALERT", repr(alert)))
    s = run_case(load_case(str(p)), str(tmp_path / "out"), progress=False)
    err = capsys.readouterr().err
    m = s["missed_contacts"]
    from fem_blocks.output.history import read_history
    e = np.asarray(read_history(tmp_path / "out" / "history.csv")["total_energy"], float)
    print(f"alert {alert}: energy {e[0]:.6g} -> {e.max():.6g} J, missed {m}")
    if alert == 1e-3:
        assert m["first"] is not None and m["first"]["interface"] == "hit" and m["first"]["step"] == 7
        assert m["first"]["depth"] == pytest.approx(5e-4, abs=1e-6)
        assert m["first"]["suggested_alert"] == pytest.approx(3e-3, rel=1e-9)
        assert err.count("'hit'") == 1 and "alert >= 0.003" in err
        assert sum("was found" in w for w in s["warnings"]) == 1
        assert e.max() > 1.5 * e[0]  # what the warning is about (an unwarned run would look like a success)
    else:
        assert m == dict(steps=0, first=None, deepest=None)
        assert "was found" not in err
        assert e.max() <= e[0] * (1 + 1e-9)


@pytest.mark.dolfinx
@pytest.mark.parametrize("alert", [5e-3, 1e-3])
def test_box_on_an_edge_at_45_degrees_topples_without_penetrating(alert):
    """3D: a stiff deformable box (b = 0.168 along x, 0.1 along y, h = 0.2 along z; hexahedra 2 x 1 x 2,
    consistent mass) stands on its bottom edge along y, bottom face at 45° from a fixed rigid floor (z = 0), node
    contact points (corners need them: "positions" has none there), updated geometry, μ = 2, h = 2e-3 s (202 steps,
    7 s) and alert = 5 mm (the side face lands at ~1.6 mm per step: more than the default 1 mm). Its centre of mass
    is beyond the edge (α = 40°): it topples onto its side face at the rigid landing time (about the edge I_O =
    m (b² + h²)/3: the 2D reference) within 1 % (observed +4.9e-3), no node below the floor by more than 1e-5 m
    (observed: none), and it does not turn about the other axes (|rx|, |rz| <= 1e-6 rad; observed 2e-10). With the
    former 30° limit neither face at the edge would face the floor (both at 45°).
    The runner's missed-contact watch (runner._MissedContactWatch, fed the step records) stays silent while the
    box turns on its edge (the held edge contacts sit at the floor); with alert = 1 mm the side face's far nodes
    cross the alert band in the landing step: the watch reports the interface once, at the next detection (observed
    depth 5.8e-4 m, suggested alert 3.2 mm), while the fall itself is unchanged (landing +3.1e-3)."""
    from fem_blocks.bodies import BlockType3D, DeformableBody3D, RigidBody3D, rotation3d
    from fem_blocks.meshing import box_corners, mesh_box
    beta = np.radians(45.0)
    side, t_land = rigid_landing(beta)
    assert side > 0
    held = {k: Driver("velocity", 0.0) for k in ("x", "y", "z", "rx", "ry", "rz")}
    floor = RigidBody3D(box_corners(2.0, 1.0, 0.1, (-1.0, -0.5, -0.1)), rho=2000.0, drivers=held, name="floor")
    bt = BlockType3D(mesh_box(BW, 0.1, BH, divisions=(2, 1, 2)), Material(E=1e10, nu=0.2, rho=RHO),
                     mass="consistent")
    R = rotation3d(np.array([0.0, beta, 0.0]))  # about +y: the left edge (x = -b) lifts
    blk = DeformableBody3D(bt, position=-R @ np.array([BW, 0.05, 0.0]), R=R, name="block")
    cs = ContactStep([InterfaceSpec("base", ("block", "floor"), mu=2.0, placement="nodes", alert=alert)],
                     ["block", "floor"],
                     ContactOptions(tol=1e-12, max_sweeps=1000, geometry="updated"))
    sim = Simulation([blk, floor], h=2e-3, theta=0.5, contact=cs)
    from types import SimpleNamespace
    from fem_blocks.runner import _MissedContactWatch
    watch = _MissedContactWatch(SimpleNamespace(contact=cs), ["block", "floor"])
    ts, th, pen, off, warned = [0.0], [beta], 0.0, 0.0, []
    while sim.time < 1.5 * t_land:
        sim.step()
        w = watch.check(sim)
        if w:
            warned.append((len(ts), w))
        r = blk.rotation()
        ts.append(sim.time)
        th.append(beta + r[1])
        off = max(off, abs(r[0]), abs(r[2]))
        pen = max(pen, -float(blk.current_points()[:, 2].min()))
        if th[-1] >= np.pi / 2 or th[-1] <= 0.0:
            break
    assert th[-1] >= np.pi / 2, f"did not topple (tilt {np.degrees(th[-1]):.1f}°)"
    t_num = ts[-2] + (ts[-1] - ts[-2]) * (th[-2] - np.pi / 2) / (th[-2] - th[-1])
    for k in range(3):  # the impact on the side face: found at the next detections
        sim.step()
        pen = max(pen, -float(blk.current_points()[:, 2].min()))
        w = watch.check(sim)
        if w:
            warned.append((len(ts) + k, w))
    print(f"3D alert {alert}: landing {t_num:.5f} s vs rigid {t_land:.5f} s ({t_num / t_land - 1:+.2e}), penetration "
          f"{pen:.3g} m, off-axis rotation {off:.3g} rad, {len(ts) - 1} steps, warned {warned} {watch.state}")
    assert t_num == pytest.approx(t_land, rel=0.01)
    assert off <= 1e-6
    if alert == 5e-3:
        assert pen <= 1e-5
        assert not warned and watch.state["steps"] == 0
    else:
        assert len(warned) == 1 and "interface 'base'" in warned[0][1]
        assert watch.state["first"]["depth"] > 0.1 * alert


def test_max_angle_case_file_key(tmp_path):
    """[[interfaces]] max_angle reaches the detection table (cos of the angle, per interface); the default is the
    schema's; out of (0, 90) the case is refused (tests/bad_cases/543, 544)."""
    from fem_blocks.case import load_case
    text = IMPACT.replace("alert = ALERT", "alert = 1e-3\nmax_angle = 45.0")
    p = tmp_path / "c.toml"
    p.write_text(text)
    itf = load_case(str(p)).interfaces[0]
    assert itf.max_angle == 45.0
    assert det.build_table([itf], {"blk": 0, "wall": 1}).cos_max_angle[0] == pytest.approx(np.cos(np.pi / 4),
                                                                                          rel=1e-15)
    p.write_text(IMPACT.replace("ALERT", "1e-3"))
    assert load_case(str(p)).interfaces[0].max_angle == 60.0


# ----------------------------------------------------------------------------- 3D: the bound of a box's vertex
def _box(R, pivot):
    """8 corners and 6 outward quads of the unit box, rotated by R about its corner `pivot` placed at the origin."""
    from test_detection3d import HEX_FACES, UNIT
    V = (UNIT - UNIT[pivot]) @ R.T
    return V, HEX_FACES.copy()


@pytest.mark.parametrize("max_angle, found", [(None, True), (56.0, True), (54.0, False)])
def test_box_on_a_vertex_3d(max_angle, found):
    """A unit box standing on its vertex with its long diagonal vertical: its three faces at the vertex are all at
    acos(1/√3) = 54.74° from the floor (the worst tilt for a vertex: the three normals are orthonormal, so their
    cosines with the vertical satisfy Σ cos² = 1). The vertex (node placement) is a contact on the floor's top,
    gap 0, normal +z, with the default 60° and 56°, not with 54°."""
    from fem_blocks.contact import detection_3d as d3
    from fem_blocks.geometry import rotation3d
    d = np.array([1.0, 1.0, 1.0]) / np.sqrt(3)  # the diagonal from corner 0 to corner 6 -> +z
    axis = np.cross(d, [0.0, 0.0, 1.0])
    R = rotation3d(axis / np.linalg.norm(axis) * np.arccos(d[2]))
    assert np.allclose(R @ d, [0, 0, 1], atol=1e-15)
    blk = _box(R, 0)
    floor = (np.array([[-1, -1, -0.2], [1, -1, -0.2], [1, 1, -0.2], [-1, 1, -0.2],
                       [-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float), _box(np.eye(3), 0)[1])
    flat = d3.flatten_boundaries([blk[0], floor[0]], [blk[1], floor[1]])
    table = d3.simple_table(alert=1e-3, placement="nodes", max_angle=max_angle)
    cs = d3.detect(*flat, np.zeros(2, int), np.zeros(2, int), table)
    at_vertex = np.linalg.norm(cs.point, axis=1) < 1e-12
    assert at_vertex.sum() == (1 if found else 0)
    if found:
        assert abs(cs.gap[at_vertex][0]) < 1e-15
        np.testing.assert_allclose(cs.n[at_vertex][0], [0, 0, 1], atol=1e-15)
