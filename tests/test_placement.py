"""Mesh independence of dry-joint stability with the default candidate placement (issue #18, item 3).

A hinge must be able to form at a block's corner whatever the mesh. Closed form: a rigid block of width b and
height h on a table tilted by alpha (friction high enough to prevent sliding) overturns about its lower corner
when the resultant of its weight leaves the base, tan(alpha) = b / h. The block here is deformable but stiff
(E = 1e10 Pa: elastic shift of the centre of mass ~1e-8 m against a margin of 5e-4 m at 1 %)."""
import numpy as np
import pytest

from types import SimpleNamespace

from fem_blocks.bodies import BlockType, DeformableBody, Driver, Material, RigidBody
from fem_blocks.contact import detection_2d as det
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.errors import InputError

from _split_detection import check_parts
from fem_blocks.meshing import mesh_rectangle

pytestmark = pytest.mark.dolfinx
G = 9.81
B, H = 0.1, 0.2  # block width and height [m]: overturning at tan(alpha) = B/H = 0.5


def detect_two(poly0, poly1, placement, thickness=1.0):
    """Contact points of body 0 (candidate) on body 1, both given as counter-clockwise boundary polygons (their
    vertices are the boundary nodes), one interface with `placement`."""
    itf = SimpleNamespace(name="i", groups=("a", "a"), g0=0.0, alert=1e-3, placement=placement,
                          positions=(0.25, 0.75), candidate=None, orientation="any", thickness=thickness)
    bx = np.vstack([poly0, poly1]).astype(float)
    n0, n1 = len(poly0), len(poly1)
    edges = np.vstack([np.column_stack([np.arange(n0), np.roll(np.arange(n0), -1)]),
                       n0 + np.column_stack([np.arange(n1), np.roll(np.arange(n1), -1)])])
    body = np.r_[np.zeros(n0, int), np.ones(n1, int)]
    cs = det.detect(bx, body, np.r_[np.arange(n0), np.arange(n1)], edges, body, np.zeros(2, int), np.zeros(2, int),
                    det.build_table([itf], {"a": 0}))
    o = np.argsort(cs.point[:, 0])
    return cs.point[o], cs.area[o], cs.cand_body[o]


# block [0, 1] x [0, 1] with its bottom edge in two elements (node at x = 0.5)
BLOCK = [(0, 0), (0.5, 0), (1, 0), (1, 1), (0, 1)]


def test_overlap_points_at_the_antagonist_corners_inside_a_candidate_edge():
    """Antagonist [0.2, 0.7] x [-1, 0] under the block: its corners fall inside the block's bottom edges. Points at
    x = 0.2, 0.5 (the block's node), 0.7; tributary lengths by the trapezoidal rule on [0.2, 0.5] and [0.5, 0.7]:
    0.15, 0.15 + 0.1, 0.1 (sum = overlap 0.5, times the thickness 0.1). 'nodes' finds only x = 0.5 (a narrower
    antagonist inside one edge would get none), 'positions' 0.375 and 0.625."""
    sup = [(0.2, -1), (0.7, -1), (0.7, 0), (0.2, 0)]
    x, a, cb = detect_two(BLOCK, sup, "overlap", thickness=0.1)
    assert np.allclose(x, [[0.2, 0], [0.5, 0], [0.7, 0]], atol=1e-15)
    assert np.allclose(a, [0.015, 0.025, 0.01], rtol=1e-12) and np.all(cb == 0)
    x, a, _ = detect_two(BLOCK, sup, None, thickness=0.1)  # the default is 'overlap'
    assert np.allclose(x, [[0.2, 0], [0.5, 0], [0.7, 0]], atol=1e-15)
    x, a, _ = detect_two(BLOCK, sup, "nodes")
    assert np.allclose(x, [[0.5, 0]]) and np.allclose(a, [0.5])
    x, _, _ = detect_two(BLOCK, [(0.1, -1), (0.4, -1), (0.4, 0), (0.1, 0)], "nodes")
    assert len(x) == 0
    x, _, _ = detect_two(BLOCK, [(0.1, -1), (0.4, -1), (0.4, 0), (0.1, 0)], "overlap")
    assert np.allclose(x, [[0.1, 0], [0.4, 0]], atol=1e-15)


def test_overlap_equals_nodes_on_matching_meshes():
    """Block on a wider support whose top edge has nodes at the block's nodes: the overlap ends are the block's
    three bottom nodes, with lengths 0.25, 0.5, 0.25 (as 'nodes')."""
    sup = [(-1, -1), (2, -1), (2, 0), (1, 0), (0.5, 0), (0, 0), (-1, 0)]
    for placement in ("overlap", "nodes"):
        x, a, _ = detect_two(BLOCK, sup, placement)
        assert np.allclose(x, [[0, 0], [0.5, 0], [1, 0]], atol=1e-15)
        assert np.allclose(a, [0.25, 0.5, 0.25], rtol=1e-12)


def many_args(polys, placement, thickness=1.0, kind=None):
    """detect's arguments for bodies given as counter-clockwise boundary polygons (body i = polys[i]), one interface;
    kind: per body (0 deformable, 1 rigid), default all deformable."""
    itf = SimpleNamespace(name="i", groups=("a", "a"), g0=0.0, alert=1e-3, placement=placement,
                          positions=(0.25, 0.75), candidate=None, orientation="any", thickness=thickness)
    bx = np.vstack(polys).astype(float)
    edges, body, local, start = [], [], [], 0
    for i, p in enumerate(polys):
        n = len(p)
        edges.append(start + np.column_stack([np.arange(n), np.roll(np.arange(n), -1)]))
        body.append(np.full(n, i))
        local.append(np.arange(n))
        start += n
    body = np.concatenate(body)
    nb = len(polys)
    return (bx, body, np.concatenate(local), np.vstack(edges), body, np.zeros(nb, int) if kind is None else kind,
            np.zeros(nb, int), det.build_table([itf], {"a": 0}))


def detect_many(polys, placement, thickness=1.0):
    """Contact set of bodies given as counter-clockwise boundary polygons (body i = polys[i]), one interface."""
    return det.detect(*many_args(polys, placement, thickness))


def test_overlap_node_at_a_head_joint_keeps_both_bodies():
    """Running bond: the block's bottom node x = 0.5 sits on the head joint between two supports [-1, 0.5] and
    [0.5, 2]. Each pair's points sum to its overlap (0.5 each: x = 0 and 0.5 with the left support, 0.5 and 1 with
    the right one, 0.25 each by the trapezoidal rule), the node carrying one point per support. Bug caught (found
    by the EN 1052-1 wallet): one point per candidate node kept one support only, and the joint lost 0.25 of its
    length (a quarter of each bed joint of a running-bond wallet at every such node)."""
    blk = [(0, 0), (0.5, 0), (1, 0), (1, 1), (0, 1)]
    left = [(-1, -1), (0.5, -1), (0.5, 0), (0, 0), (-1, 0)]
    right = [(0.5, -1), (2, -1), (2, 0), (1, 0), (0.5, 0)]
    cs = detect_many([blk, left, right], "overlap", thickness=0.1)
    for ant, xs in ((1, [0.0, 0.5]), (2, [0.5, 1.0])):
        on = (cs.ant_body == ant) & (cs.cand_body == 0)   # (the supports' head joint is a pair of its own)
        assert np.allclose(np.sort(cs.point[on, 0]), xs, atol=1e-15)
        assert cs.area[on].sum() == pytest.approx(0.05, rel=1e-12)   # 0.5 x thickness 0.1
    assert len(np.unique(cs.key)) == len(cs.key)


def test_placement_key_errors():
    with pytest.raises(InputError, match=r"interfaces\.j\.placement = 'ends': expected 'overlap', 'nodes' or "
                                         r"'positions'"):
        InterfaceSpec("j", ("a", "a"), placement="ends")
    assert InterfaceSpec("j", ("a", "a")).placement is None  # the default: 'overlap' in 2D, 'positions' in 3D


def test_overlap_placement_is_2d_only_in_case_files(tmp_path):
    import sys
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))
    from test_case3d import STACK
    from fem_blocks.case import load_case
    p = tmp_path / "c.toml"
    p.write_text(STACK.replace('placement = "nodes"', 'placement = "overlap"', 1))
    with pytest.raises(InputError, match=r"c\.toml.*interfaces\[0\]\.placement.*'overlap': expected 'positions' "
                                         r"or 'nodes' in 3D"):
        load_case(str(p))
    p.write_text(STACK.replace('placement = "nodes"\n', ''))
    assert all(i.placement is None for i in load_case(str(p)).interfaces)


def heel_uplift(n_across, tan_alpha, steps=200, h=2e-3):
    """Block meshed with n_across Q4 elements across its width, on a fixed rigid table, gravity tilted by alpha
    (the same as tilting the table) from t = 0; default interface placement. Returns the largest vertical
    displacement of the block's bottom-left corner (the heel: the block overturns about its right corner)."""
    bt = BlockType(mesh_rectangle(B, H, B / n_across, cell="quad"),
                   Material(E=1e10, nu=0.2, rho=2000.0, thickness=1.0))
    blk = DeformableBody(bt, position=(0.0, 0.0))
    table = RigidBody([(-0.5, -0.1), (0.6, -0.1), (0.6, 0.0), (-0.5, 0.0)],
                      drivers={k: Driver("velocity", 0.0) for k in ("x", "y", "rz")}, name="table")
    cs = ContactStep([InterfaceSpec("base", ("block", "table"), mu=0.8)], ["block", "table"],
                     ContactOptions(tol=1e-10, max_sweeps=10000))
    a = np.arctan(tan_alpha)
    sim = Simulation([blk, table], h=h, theta=1.0, contact=cs, gravity=(G * np.sin(a), -G * np.cos(a)))
    heel = int(np.flatnonzero((np.abs(bt.mesh.points[:, 0]) < 1e-12) & (np.abs(bt.mesh.points[:, 1]) < 1e-12))[0])
    up = 0.0
    for _ in range(steps):
        sim.step()
        up = max(up, float(blk.displacement_global()[heel, 1]))
    return up


@pytest.mark.parametrize("n_across", [1, 2, 4])
def test_tilting_table_overturns_at_b_over_h_for_any_mesh(n_across):
    """tan(alpha) = 0.99 b/h: the block stands (heel uplift < 1e-5 m after 0.4 s: elastic, 5e-7 m observed with
    4 elements); 1.01 b/h: it overturns
    (the 1 % excess moment grows with the rotation, time constant sqrt(I_corner / (m g r)) = 0.12 s: uplift
    > 1 mm after 0.4 s). With candidate points at 1/4 and 3/4 of each edge the hinge sat b/(4n) inside the
    corner and the block overturned at tan(alpha) = (1 - 1/(2n)) b/h (0.5, 0.75, 0.875 b/h)."""
    assert heel_uplift(n_across, 0.99 * B / H) < 1e-5
    assert heel_uplift(n_across, 1.01 * B / H) > 1e-3


# ----------------------------------------------------------------------------- the shipped arch
def demo_arch_stands(t, divisor, duration=0.3):
    """demos/arch.toml (intrados radius 1 m, 15 voussoirs, mu = 0.5, theta = 1, h = 2e-3 s) with ring depth t [m]
    and mesh size t/divisor, default placement: True if the crown has dropped by less than 1 mm after `duration`
    (elastic settlement ~1e-6 m), False as soon as it drops more (bench/bench_arch_placement.py, the long version)."""
    import os
    import tomllib
    from fem_blocks.case import parse_case
    from fem_blocks.model import build_model
    from _paths import DEMOS
    with open(os.path.join(DEMOS, "arch.toml"), "rb") as f:
        doc = tomllib.load(f)
    doc["arch"]["ring_depth"], doc["arch"]["mesh_size"] = t, t / divisor
    case = parse_case(doc, "arch.toml")
    assert all(i.placement is None for i in case.interfaces)  # the demo uses the default placement
    model = build_model(case)
    st = case.stages[0]
    sim = Simulation(model.bodies, h=st.h, theta=st.theta, gravity=model.gravity, contact=model.contact)
    crown = model.bodies[model.index("voussoir7")]
    for _ in range(int(round(duration / st.h))):
        sim.step()
        if -crown.displacement_global()[:, 1].mean() > 1e-3:
            return False
    return True


def t_of(t_over_rc):
    """Ring depth t with t / R_centre = t_over_rc for the intrados radius 1 m (R_centre = 1 + t/2)."""
    return t_over_rc / (1 - t_over_rc / 2)


@pytest.mark.parametrize("divisor", [2, 4])
def test_demo_arch_limit_thickness_mesh_independent(divisor):
    """Milankovitch: a semicircular arch (continuous radial joints) stands down to t/R = 0.1075 (R the centre-line
    radius); with joints at 15 discrete places the thrust line need only fit at the joints, so the discrete
    arch stands at least down to that. 1 % above it the arch stands with mesh size t/2 and t/4; 3 % below it
    both collapse (the crown drops by 1 mm within 0.12 s). bench/bench_arch_placement.py bisects the limit with
    mesh t/2 and t/8 (t/R = 0.1061 and 0.1065; t/8 takes minutes, hence t/4 here). With candidate points at
    1/4 and 3/4 of each element edge the hinges sat t/8 (mesh t/2) inside the corners: the arch collapsed up
    to t/R = 0.141 with mesh t/2."""
    assert demo_arch_stands(t_of(1.01 * 0.1075), divisor)
    assert not demo_arch_stands(t_of(0.97 * 0.1075), divisor)


def _brick(x0, y0, w, h, n_bottom, n_top):
    """Counter-clockwise boundary of a w x h brick at (x0, y0), its bottom edge in n_bottom elements, its top edge in
    n_top (non-matching meshes between courses)."""
    bottom = [(x0 + w * k / n_bottom, y0) for k in range(n_bottom)]
    top = [(x0 + w - w * k / n_top, y0 + h) for k in range(n_top)]
    return bottom + [(x0 + w, y0)] + top + [(x0, y0 + h)]


@pytest.mark.parametrize("placement", ["overlap", "nodes", "positions"])
def test_detection_of_some_candidate_bodies_is_the_whole_detections_rows(placement):
    """detect(..., bodies=mask) (a rank's own bodies on N > 1 ranks) gives the whole detection's contacts whose
    candidate body is in the mask, every field bit for bit and in the same order, and the parts of a partition merged
    by key give the whole set. A running-bond wall of 4 courses on a foundation, each brick's bottom and top edges in
    1 to 4 elements drawn at random (non-matching meshes: overlap points at antagonist corners, candidate nodes
    facing two bricks, tributary lengths of several matches), courses lifted by up to the alert distance.
    The foundation is rigid: the bricks on it are its candidates though numbered above it. Expectation: the whole
    detection (tested above for each placement). Catches: the subset's broad phase on its own grid (pairs, hence the
    overlap sums and ties, in another order), a neighbour body missing (a contact lost near the border of the mask,
    e.g. the foundation for the bricks on it), the matches not filtered by their candidate (other bodies' contacts
    kept)."""
    rng = np.random.default_rng(11)
    w, h = 0.4, 0.2
    polys = [[(-0.5, -0.2), (2.5, -0.2), (2.5, 0.0), (-0.5, 0.0)]]
    for row in range(4):
        for k in range(5 + row % 2):
            x0 = k * w - (0.5 * w if row % 2 else 0.0)
            y0 = row * h + rng.uniform(0.0, 5e-4) + row * 5e-4
            polys.append(_brick(x0 + rng.uniform(-1e-4, 1e-4), y0, w, h, *rng.integers(1, 5, 2)))
    nb = len(polys)
    kind = (np.arange(nb) == 0).astype(int)  # the foundation rigid: the bricks above it are its candidates (a body
    #                                          numbered below its candidates, as the case-file order allows)
    args = many_args(polys, placement, kind=kind)
    whole = det.detect(*args)
    assert len(whole) > 40 and np.any(whole.ant_body == 0) and np.all(whole.cand_body != 0)
    check_parts(det.detect, args, whole, nb, rng, placement)  # (tests/_split_detection.py)
