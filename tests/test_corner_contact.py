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
