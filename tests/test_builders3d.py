"""3D builders: running-bond wall and dome of the thesis §7.2.1.c / §7.2.2.a.

Checked against closed forms: total volumes (wall with an opening: course by course; dome: each voussoir's
cross-section in its mid-meridian frame, and without joints the pyramids from the centre), no overlap
(separating axes, plus an independent facing-face analysis), joint thickness between every pair of facing
faces (exact t for head joints and aligned bed joints; the bounded wedge of staggered dome bed joints), blocks
of a course = one prototype rotated (1e-12), counts, piers under the right blocks, input validation."""
import math

import numpy as np
import pytest

from fem_blocks.builders3d import (dome, dome_voussoir, overlapping_pairs, rot_z, running_bond_wall)
from fem_blocks.errors import InputError
from fem_blocks.meshing import HEX_FACES, cell_volumes_3d, check_hex_corners

T = 0.03  # thesis joint


# ----------------------------------------------------------------------------- independent geometry helpers
def _clip(subject, clipper):
    """Sutherland-Hodgman: convex polygon `subject` (k, 2) clipped by the convex CCW polygon `clipper`."""
    out = [np.asarray(p, float) for p in subject]
    for i in range(len(clipper)):
        a, b = clipper[i], clipper[(i + 1) % len(clipper)]
        inp, out = out, []
        for j in range(len(inp)):
            p, q = inp[j], inp[(j + 1) % len(inp)]
            sp = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
            sq = (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0])
            if sp >= 0:
                out.append(p)
            if (sp >= 0) != (sq >= 0):
                out.append(p + (q - p) * sp / (sp - sq))
        if not out:
            break
    return np.array(out).reshape(-1, 2)


def _area(P):
    x, y = P[:, 0], P[:, 1]
    return 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)


def _centroid(P):
    x, y = P[:, 0], P[:, 1]
    cr = x * np.roll(y, -1) - np.roll(x, -1) * y
    return np.array([np.sum((x + np.roll(x, -1)) * cr), np.sum((y + np.roll(y, -1)) * cr)]) / (6 * _area(P))


def facing_faces(C, reach):
    """Every pair of facing faces of the hexahedra C (nb, 8, 3) (planar faces): outward normals opposite within
    8 deg, projections overlapping with positive area, and |gap| < reach. Returns rows
    (i, face_i, j, face_j, gap_min, gap_max, gap_at_overlap_centroid, overlap_area); the gap is measured along
    face i's normal from face i's plane to face j's plane (linear over the overlap: extremes at its vertices)."""
    F = C[:, HEX_FACES]
    N = np.cross(F[:, :, 2] - F[:, :, 0], F[:, :, 3] - F[:, :, 1])
    N /= np.linalg.norm(N, axis=-1, keepdims=True)
    lo, hi = C.min(1) - reach, C.max(1) + reach
    rows = []
    for i in range(len(C)):
        js = np.flatnonzero(np.all(lo <= hi[i], 1) & np.all(hi >= lo[i], 1))
        for j in js[js > i]:
            for fa in range(6):
                for fb in range(6):
                    na, nb = N[i, fa], N[j, fb]
                    if na @ nb > -0.99:
                        continue
                    o = F[i, fa, 0]
                    e1 = F[i, fa, 1] - o
                    e1 /= np.linalg.norm(e1)
                    e2 = np.cross(na, e1)
                    pa = np.c_[(F[i, fa] - o) @ e1, (F[i, fa] - o) @ e2]
                    pb = np.c_[(F[j, fb] - o) @ e1, (F[j, fb] - o) @ e2]
                    pa = pa if _area(pa) > 0 else pa[::-1]
                    pb = pb if _area(pb) > 0 else pb[::-1]
                    ov = _clip(pb, pa)
                    if len(ov) < 3 or _area(ov) <= 1e-9 * _area(pa):
                        continue
                    P3 = o + ov[:, :1] * e1 + ov[:, 1:] * e2
                    g = (F[j, fb, 0] - P3) @ nb / (na @ nb)
                    c = _centroid(ov)
                    gc = (F[j, fb, 0] - (o + c[0] * e1 + c[1] * e2)) @ nb / (na @ nb)
                    if -reach < g.min() and g.max() < reach:
                        rows.append((i, fa, j, fb, g.min(), g.max(), gc, _area(ov)))
    return np.array(rows).reshape(-1, 8)


def hex_volume(C):
    return cell_volumes_3d(np.asarray(C).reshape(-1, 3), np.arange(8 * len(C)).reshape(-1, 8), "hexahedron")


# ----------------------------------------------------------------------------- dome
@pytest.fixture(scope="module")
def thesis_dome():
    return dome(piers=4)


def test_dome_counts_prototypes_and_rotation(thesis_dome):
    L = thesis_dome
    assert len(L.blocks) == 264 and len(L.prototypes) == 12 and len(L.rigid) == 4 and L.joint == T
    nb, a = 22, math.pi / 22
    C = L.corners()
    for b in L.blocks:
        P = L.prototypes[b.key]
        assert np.abs(b.corners - (P @ b.R.T + b.position)).max() < 1e-12
        # blocks of a course identical up to the rotation about z by their azimuth (running bond: odd courses
        # shifted by half a pitch): rotate back onto block 0 of course 0's frame
        theta = 2 * a * b.index + (a if b.course % 2 else 0.0)
        assert np.allclose(b.R, rot_z(theta), atol=1e-15, rtol=0)
        first = C[nb * b.course] @ rot_z(a if b.course % 2 else 0.0)  # block 0 of the course, back to azimuth 0
        assert np.abs(b.corners @ rot_z(theta) - first).max() < 1e-12
        check_hex_corners(b.corners)  # positively oriented, not folded
    # the prototype of each course is symmetric about its mid-meridian plane y = 0 (mirror y -> -y maps corner
    # i of the front face onto the back face: 0<->3, 1<->2, 4<->7, 5<->6)
    for P in L.prototypes.values():
        M = P[[3, 2, 1, 0, 7, 6, 5, 4]] * [1, -1, 1]
        assert np.abs(M - P).max() < 1e-12


def _section_volume(ri, re, phi0, phi1, a, t):
    """Closed-form volume of one voussoir. In the frame of its mid-meridian plane (x radial horizontal, z up)
    the intrados, extrados and bed planes contain the y direction, so they cut a quadrilateral Q in the (x, z)
    plane: the chords through (r cos(phi) cos(a), r sin(phi)) for r = ri, re, and the bed lines
    sin(phi) x - cos(phi) cos(a) z = 0 moved by t/2 into the block; the head planes bound
    |y| <= tan(a) (x - x0) with x0 = t / (2 sin a). Hence V = 2 tan(a) A_Q (xbar_Q - x0)."""
    def line_r(r):  # (normal, offset) of the chord line through the two points
        p0 = np.array([r * math.cos(phi0) * math.cos(a), r * math.sin(phi0)])
        p1 = np.array([r * math.cos(phi1) * math.cos(a), r * math.sin(phi1)])
        n = np.array([p1[1] - p0[1], p0[0] - p1[0]])
        return n, n @ p0

    def line_bed(phi, s):
        n = s * np.array([-math.sin(phi), math.cos(phi) * math.cos(a)])
        return n / np.linalg.norm(n), t / 2

    def meet(l1, l2):
        return np.linalg.solve(np.array([l1[0], l2[0]]), np.array([l1[1], l2[1]]))

    Q = np.array([meet(line_r(ri), line_bed(phi0, 1)), meet(line_r(re), line_bed(phi0, 1)),
                  meet(line_r(re), line_bed(phi1, -1)), meet(line_r(ri), line_bed(phi1, -1))])
    A = abs(_area(Q))
    xbar = _centroid(Q if _area(Q) > 0 else Q[::-1])[0]
    return 2 * math.tan(a) * A * (xbar - t / (2 * math.sin(a)))


def test_dome_volume_closed_forms(thesis_dome):
    ri, re, nc, nb = 2.0, 2.48, 12, 22
    a = math.pi / nb
    D = 0.5 * math.pi * nc / (nc + 1) / nc
    V = thesis_dome.volumes()
    exact = nb * sum(_section_volume(ri, re, k * D, (k + 1) * D, a, T) for k in range(nc))
    assert abs(V.sum() - exact) < 1e-12 * exact
    per_course = V.reshape(nc, nb)
    assert np.ptp(per_course, axis=1).max() < 1e-13  # identical blocks in a course
    # the thesis: a bed-course block weighs "about 170 kg" (2500 kg/m^3: 173 kg)
    assert 165 < 2500 * per_course[0, 0] < 180
    # without joints every voussoir = pyramid(centre, extrados face) - pyramid(centre, intrados face):
    # V = (re^3 - ri^3)/3 * det-volume of the unit trapezoid, summed over courses
    L0 = dome(joint=0.0, running_bond=False)
    unit = 0.0
    for k in range(nc):
        P = [np.array([math.cos(p) * math.cos(s * a), math.cos(p) * math.sin(s * a), math.sin(p)])
             for p, s in ((k * D, -1), (k * D, 1), ((k + 1) * D, 1), ((k + 1) * D, -1))]
        unit += (np.linalg.det(np.array([P[0], P[1], P[2]])) + np.linalg.det(np.array([P[0], P[2], P[3]]))) / 6
    exact0 = nb * (re ** 3 - ri ** 3) * unit
    assert abs(L0.volumes().sum() - exact0) < 1e-12 * exact0
    # and the polyhedral shell is the spherical one (2 pi / 3)(re^3 - ri^3) sin(top) less its chord sags: a
    # pyramid over a flat rectangle inscribed in the unit sphere with angular half-widths u, v has the volume
    # of its spherical sector times 1 - (u^2 + v^2) + O(4th order); here u = a cos(phi) (area-weighted mean of
    # cos^2 = 1 - sin^2(top)/3) and v = D/2: deficit 1.74 %, within 10 % of it
    top = nc * D
    sphere = 2 * math.pi / 3 * (re ** 3 - ri ** 3) * math.sin(top)
    est = a ** 2 * (1 - math.sin(top) ** 2 / 3) + (D / 2) ** 2
    assert abs((1 - exact0 / sphere) - est) < 0.1 * est
    # the joints take 30 mm of the 0.27 m course pitch and of the 0.6 m block pitch: about 15 % of the shell
    assert 0.80 * exact0 < exact < 0.88 * exact0


def test_dome_no_overlap_and_joints(thesis_dome):
    L = thesis_dome
    C = L.corners(rigid=True)
    assert len(overlapping_pairs(C)) == 0
    L.check_no_overlap("dome")
    # a block pushed 1 cm (< the 3 cm joint) toward its neighbour still fits; 4 cm does not
    for shift, n_bad in ((0.01, 0), (0.04, 1)):
        C2 = C.copy()
        C2[5] += shift * (C[6].mean(0) - C[5].mean(0)) / np.linalg.norm(C[6].mean(0) - C[5].mean(0))
        bad = overlapping_pairs(C2)
        assert len(bad) == n_bad and (n_bad == 0 or tuple(bad[0]) == (5, 6))
    nb, nc = 22, 12
    R = facing_faces(L.corners(), reach=0.1)
    i, fi, j, fj = R[:, :4].astype(int).T
    head = (fi >= 2) & (fi != 3) & (fi != 5)  # front/back faces (meridian planes)
    assert np.all(fj[head] == np.where(fi[head] == 2, 4, 2))
    # head joints: exactly t between the 22 x 12 = 264 neighbour pairs of a course
    assert head.sum() == nb * nc and np.all(i[head] // nb == j[head] // nb)
    assert np.abs(R[head, 4:7] - T).max() < 1e-12
    # bed joints: each block faces 2 blocks of the course above (running bond), wedge t +- delta_k with
    # delta_k = re sin(phi) cos(phi) (1 - cos a) / cos a (phi = the bed's elevation); mean (centroid) t
    bed = fi < 2
    assert np.all((fi[bed] == 1) & (fj[bed] == 0)) and np.all(j[bed] // nb == i[bed] // nb + 1)
    assert bed.sum() == 2 * nb * (nc - 1) and len(R) == head.sum() + bed.sum()
    a = math.pi / nb
    D = 0.5 * math.pi * nc / (nc + 1) / nc
    phi = (i[bed] // nb + 1) * D
    delta = 2.48 * np.sin(phi) * np.cos(phi) * (1 - math.cos(a)) / math.cos(a)
    dev = np.maximum(np.abs(R[bed, 4] - T), np.abs(R[bed, 5] - T))
    assert np.all(dev <= delta) and np.all(dev >= 0.7 * delta)  # measured 0.72-0.91 of the bound
    assert np.abs(R[bed, 6] - T).max() < 0.05 * T
    # stacked courses: every bed joint exactly t
    Rs = facing_faces(dome(running_bond=False).corners(), reach=0.1)
    bs = Rs[:, 1] < 2
    assert bs.sum() == nb * (nc - 1) and np.abs(Rs[bs, 4:7] - T).max() < 1e-12


def test_dome_piers(thesis_dome):
    L = thesis_dome
    nb = 22
    carried = {0, 1, 2, 6, 7, 8, 11, 12, 13, 16, 17, 18}
    bottom = [b for b in L.blocks if b.course == 0]
    tops = []
    for p in L.rigid:
        assert p.group == "piers" and np.allclose(p.corners[4:, 2], -T / 2) and np.allclose(p.corners[:4, 2], -T / 2 - 0.5)
        tops.append(p.corners[4:, :2])
    gaps = []
    for b in bottom:
        foot = b.corners[:4]
        assert np.allclose(foot[:, 2], T / 2, atol=1e-15)  # a full joint above the piers' tops
        inside = [np.all([np.cross(top[(k + 1) % 4] - top[k], foot[m, :2] - top[k]) >= -1e-12
                          for k in range(4) for m in range(4)]) for top in tops]
        # a carried block stands entirely on one pier; the others are entirely off every pier (their plan
        # trapezoid lies outside the pier's bounding meridian planes, up to the joint)
        if b.index in carried:
            assert sum(inside) == 1
        else:
            assert not any(inside)
            gaps.append(b.index)
    # 22 blocks on 4 piers of 3: unsupported runs of 3, 2, 2, 3 blocks
    runs = np.split(np.array(gaps), np.flatnonzero(np.diff(gaps) > 1) + 1)
    assert sorted(len(r) for r in runs) == [2, 2, 3, 3] and len(gaps) == nb - 12
    assert np.allclose(L.volumes(rigid=True)[-4:], L.volumes(rigid=True)[-1])


# ----------------------------------------------------------------------------- wall
def _wall_volume(nc, nbk, l, h, w, t, opening, leaves):
    """Course by course: an even course has nbk bricks (material nbk l), an odd one nbk - 1 bricks and two
    halves (l - t)/2 (material nbk l - t). An opening [x0, x1] whose edges fall inside bricks removes from each
    course it crosses the band [x0 - t, x1 + t] less the head joints inside it."""
    x0, z0, x1, z1 = opening
    total = 0.0
    for c in range(nc):
        if c % 2 == 0:
            joints = [(k * (l + t) - t, k * (l + t)) for k in range(1, nbk)]
            mat = nbk * l
        else:
            joints = [((l - t) / 2 + k * (l + t), (l - t) / 2 + k * (l + t) + t) for k in range(nbk)]
            mat = nbk * l - t
        zc0, zc1 = c * (h + t), c * (h + t) + h
        if zc1 > z0 and zc0 < z1:
            band = (x0 - t, x1 + t)
            inside = sum(min(b, band[1]) - max(a, band[0]) for a, b in joints if b > band[0] and a < band[1])
            mat -= (band[1] - band[0]) - inside
        total += mat * h * w
    return leaves * total


@pytest.mark.parametrize("leaves,stagger,angle", [(1, False, 0.0), (2, False, 0.7), (2, True, -2.1)])
def test_wall_volume_overlap_joints(leaves, stagger, angle):
    l, h, w, t, nc, nbk = 0.21, 0.05, 0.1, 0.01, 6, 5
    op = (0.40, 0.06, 0.69, 0.2)  # courses 1-3; edges inside bricks of every course, pieces >= l/4
    origin = (1.0, -2.0, 0.5)
    L = running_bond_wall(nc, nbk, l, h, w, t, openings=[op], leaves=leaves, stagger_leaves=stagger,
                          origin=origin, angle=angle)
    V = L.volumes()
    exact = _wall_volume(nc, nbk, l, h, w, t, op, leaves)
    if stagger:  # leaf 1 has the other parity: its courses c hold the material of courses c + 1 of leaf 0
        exact = _wall_volume(nc, nbk, l, h, w, t, op, 1) + \
            _wall_volume(nc + 1, nbk, l, h, w, t, (op[0], op[1] + h + t, op[2], op[3] + h + t), 1) - \
            _wall_volume(1, nbk, l, h, w, t, (op[0], -1.0, op[2], -0.5), 1)
    assert abs(V.sum() - exact) < 1e-12 * exact
    # counts: 3 even courses of 5 bricks + 3 odd of 6; the opening removes the middle brick of course 2 and
    # leaves one piece of each brick it cuts
    if not stagger:
        assert len(L.blocks) == leaves * (3 * 5 + 3 * 6 - 1)
    else:
        assert len(L.blocks) == 32 + (3 * 6 + 3 * 5 - 2)  # leaf 1: courses 1, 3 even, each loses a brick
    R = rot_z(angle)
    for b in L.blocks:
        assert np.abs(b.corners - (L.prototypes[b.key] @ b.R.T + b.position)).max() < 1e-12
        assert np.allclose(b.R, R, atol=1e-15, rtol=0) and b.key == ("box",) + tuple(
            round(float(v), 12) for v in np.ptp(L.prototypes[b.key], axis=0))
    assert len(overlapping_pairs(L.corners())) == 0
    # every facing pair is a joint of exactly t (head, bed and collar joints)
    F = facing_faces(L.corners(), reach=0.5 * h)
    assert len(F) > 0 and np.abs(F[:, 4:7] - t).max() < 1e-12
    if leaves == 2:
        collar = F[[L.blocks[int(i)].leaf != L.blocks[int(j)].leaf for i, j in F[:, [0, 2]]]]
        # aligned leaves: the collar joint covers the whole face of a leaf (area = leaf volume / w); staggered:
        # less, the head joints of both leaves being at different places (minus 2 t h per course and joint)
        if not stagger:
            assert abs(collar[:, 7].sum() - (V.sum() / 2) / w) < 1e-10
        else:
            assert 0 < collar[:, 7].sum() < (V.sum() / 2) / w


def test_wall_counts_and_types():
    L = running_bond_wall(4, 3, 0.2, 0.1, 0.1, 0.01)
    assert len(L.blocks) == 2 * 3 + 2 * 4 and len(L.prototypes) == 2
    halves = [b for b in L.blocks if b.key[1] < 0.2]
    assert len(halves) == 4 and all(abs(b.key[1] - 0.095) < 1e-15 for b in halves)
    assert [b.index for b in L.blocks if b.course == 1] == [0, 1, 2, 3]
    Lt = running_bond_wall(4, 3, 0.2, 0.1, 0.1, 0.01, half_bricks=False)
    assert len(Lt.blocks) == 3 + 2 + 3 + 2 and len(Lt.prototypes) == 1
    # expanded-joint wall (t = 0): blocks touch, still no overlap, volume = envelope
    L0 = running_bond_wall(4, 3, 0.2, 0.1, 0.1, 0.0, leaves=2)
    assert abs(L0.volumes().sum() - 2 * 4 * 0.6 * 0.1 * 0.1) < 1e-15 and len(overlapping_pairs(L0.corners())) == 0


# ----------------------------------------------------------------------------- meshing compatibility
def test_prototype_meshes_to_the_block():
    """The voussoir prototype meshed by gmsh (2 x 2 x 2 hexahedra, as the thesis) and placed by R gives the
    block's volume and corners."""
    from fem_blocks.meshing import mesh_hexahedron
    L = dome(n_courses=3, blocks_per_course=8, top_elevation=0.9)
    b = L.blocks[9]
    m = mesh_hexahedron(L.prototypes[b.key], divisions=(2, 2, 2))
    vol = cell_volumes_3d(m.points, m.cells, m.cell_type).sum()
    assert abs(vol - hex_volume(b.corners[None])[0]) < 1e-12 * vol
    X = m.points @ b.R.T + b.position
    for c in b.corners:
        assert np.min(np.linalg.norm(X - c, axis=1)) < 1e-12


# ----------------------------------------------------------------------------- validation
@pytest.mark.parametrize("kw,field", [
    (dict(n_courses=0), "wall.courses"), (dict(n_courses=2.5), "wall.courses"),
    (dict(bricks_per_course=True), "wall.bricks_per_course"), (dict(brick_length=-0.2), "wall.brick_length"),
    (dict(brick_width=0.0), "wall.brick_width"), (dict(joint=0.15), "wall.joint"), (dict(leaves=3), "wall.leaves"),
    (dict(openings=[(0.1, 0.1, 0.2)]), "wall.openings[0]"), (dict(openings=[(0.5, 0.1, 0.9, 0.3)]),
                                                              "wall.openings[0]"),
    (dict(openings=[(0.3, 0.1, 0.2, 0.3)]), "wall.openings[0]"), (dict(origin=(0, 0)), "wall.origin"),
    (dict(angle=float("inf")), "wall.angle")])
def test_wall_validation(kw, field):
    args = dict(n_courses=3, bricks_per_course=3, brick_length=0.2, brick_height=0.1, brick_width=0.1, joint=0.01)
    args.update(kw)
    with pytest.raises(InputError, match=field.replace("[", r"\[").replace("]", r"\]")):
        running_bond_wall(**args)


@pytest.mark.parametrize("kw,field", [
    (dict(span=0), "dome.span"), (dict(thickness=-1), "dome.thickness"), (dict(n_courses=0), "dome.courses"),
    (dict(blocks_per_course=2), "dome.blocks_per_course"), (dict(blocks_per_course=7.5), "dome.blocks_per_course"),
    (dict(joint=-0.01), "dome.joint"), (dict(joint=0.4), "dome.joint"), (dict(top_elevation=math.pi / 2),
                                                                          "dome.top_elevation"),
    (dict(piers=-1), "dome.piers"), (dict(piers=4, pier_blocks=6), "dome.pier_blocks"),
    (dict(piers=4, pier_height=0), "dome.pier_height")])
def test_dome_validation(kw, field):
    with pytest.raises(InputError, match=field):
        dome(**kw)


def test_voussoir_symmetry_and_joint_offsets():
    """A voussoir with joints = the joint-free one with each joint plane moved t/2 inward: the head faces of
    the jointed block lie at distance t/2 from the meridian planes +-a, its bed faces at t/2 from the bed planes."""
    a, t = 0.3, 0.02
    C = dome_voussoir(1.0, 1.3, 0.2, 0.5, a, t)
    for s, idx in ((-1, [0, 1, 4, 5]), (1, [3, 2, 7, 6])):
        n = np.array([math.sin(a), -s * math.cos(a), 0.0])
        assert np.abs(C[idx] @ n - t / 2).max() < 1e-14
    for phi, s, idx in ((0.2, 1, [0, 1, 2, 3]), (0.5, -1, [4, 5, 6, 7])):
        n = s * np.array([-math.sin(phi), 0.0, math.cos(phi) * math.cos(a)])
        assert np.abs(C[idx] @ (n / np.linalg.norm(n)) - t / 2).max() < 1e-14
