"""3D geometry builders: plain numpy geometry, no meshing (no gmsh, no dolfinx).

Every block is a hexahedron given by its 8 corners in the gmsh order (meshing.check_hex_corners: 0-3 the
bottom face counter-clockwise seen from the top face 4-7, corner 4+i above corner i; the face sides are
meshing.HEX_SIDES: bottom, top, front, right, back, left). Blocks that are identical up to a rigid motion share
one *prototype* (block type, meshed once): block b has

    corners_b = prototype[key_b] @ R_b.T + position_b        (x = R X + c, as DeformableBody3D)

so `BlockType3D(mesh_hexahedron(prototype[key]))` placed with `DeformableBody3D(type, position, R)` reproduces
the block exactly. Rigid parts (dome piers) are 8-corner hexahedra for `RigidBody3D`.

Builders:
* `running_bond_wall`: bricks l x w x h (x along the wall, y through it, z up), courses offset by half a brick,
  half bricks at the ends (or toothed ends), rectangular openings through the wall (blocks cut as in the 2D
  builder), one or two leaves separated by a collar joint, the whole wall rotated about z and translated;
* `dome`: spherical dome of the thesis §7.2.1.c / §7.2.2.a (see its docstring for the geometry choices).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .builders import Block, cut_opening
from .builders import running_bond as running_bond_2d
from .errors import InputError, check_range
from .meshing import HEX_FACES, box_corners, cell_volumes_3d, check_hex_corners

ROUND = 12  # decimals used to identify equal block types


def rot_z(angle: float) -> np.ndarray:
    """Rotation by `angle` [rad] about the vertical axis z."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass
class Block3D:
    corners: np.ndarray   # (8, 3) global corners, gmsh hexahedron order
    key: tuple            # block type key (Layout3D.prototypes[key])
    R: np.ndarray         # (3, 3) type frame -> global
    position: np.ndarray  # (3,)   corners = prototype @ R.T + position
    course: int
    index: int            # rank in the course (wall: along x from the left end; dome: azimuthal)
    leaf: int = 0
    group: str = "bricks"


@dataclass
class RigidPart3D:
    name: str
    corners: np.ndarray  # (8, 3), gmsh hexahedron order
    group: str


@dataclass
class Layout3D:
    blocks: list
    prototypes: dict          # key -> (8, 3) corners in the type frame
    rigid: list = field(default_factory=list)
    joint: float = 0.0        # nominal joint thickness (g0 of the interfaces)

    def block_types(self) -> list:
        """Distinct block type keys, in first-appearance order."""
        return list(self.prototypes)

    def corners(self, rigid: bool = False) -> np.ndarray:
        """(nb, 8, 3) corners of the blocks (then of the rigid parts when rigid=True)."""
        C = [b.corners for b in self.blocks] + ([r.corners for r in self.rigid] if rigid else [])
        return np.array(C, dtype=float).reshape(-1, 8, 3)

    def volumes(self, rigid: bool = False) -> np.ndarray:
        """Exact volume of each trilinear hexahedron (2x2x2 Gauss on det J)."""
        C = self.corners(rigid)
        return cell_volumes_3d(C.reshape(-1, 3), np.arange(8 * len(C)).reshape(-1, 8), "hexahedron")

    def check_no_overlap(self, source: str = "layout", rigid: bool = True):
        """Raise InputError if two blocks (and rigid parts) overlap by more than 1e-9 x block size
        (separating-axis test on every pair whose bounding boxes meet; exact for planar-faced blocks)."""
        if not self.blocks:
            raise InputError(f"{source}: the layout has no block")
        C = self.corners(rigid)
        bad = overlapping_pairs(C)
        if len(bad):
            i, j = bad[0]
            raise InputError(f"{source}: blocks {i} and {j} overlap ({len(bad)} overlapping pair(s))")


# ----------------------------------------------------------------------------- geometry helpers
_HEX_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4],
                       [0, 4], [1, 5], [2, 6], [3, 7]])


def candidate_pairs(C: np.ndarray, pad: float = 0.0) -> np.ndarray:
    """Pairs (i < j) of hexahedra whose axis-aligned boxes, enlarged by `pad`, intersect (sweep on x)."""
    lo, hi = C.min(axis=1) - pad, C.max(axis=1) + pad
    order = np.argsort(lo[:, 0], kind="stable")
    pairs = []
    for a, i in enumerate(order):
        for j in order[a + 1:]:
            if lo[j, 0] > hi[i, 0]:
                break
            if np.all(lo[j] <= hi[i]) and np.all(lo[i] <= hi[j]):
                pairs.append((min(i, j), max(i, j)))
    return np.array(sorted(pairs), dtype=np.int64).reshape(-1, 2)


def face_normals(C: np.ndarray) -> np.ndarray:
    """(nb, 6, 3) unit outward normals of the hexahedra faces (cross product of the face diagonals)."""
    F = C[:, HEX_FACES]  # (nb, 6, 4, 3)
    n = np.cross(F[:, :, 2] - F[:, :, 0], F[:, :, 3] - F[:, :, 1])
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def overlapping_pairs(C: np.ndarray, rel_tol: float = 1e-9) -> np.ndarray:
    """Pairs of convex hexahedra (nb, 8, 3) that overlap: no separating axis among the 6 + 6 face normals and
    the 12 x 12 cross products of edge directions (separating-axis theorem; a pair that only touches, with
    interval overlap <= rel_tol x size on some axis, is not overlapping)."""
    P = candidate_pairs(C)
    if len(P) == 0:
        return P
    A, B = C[P[:, 0]], C[P[:, 1]]
    nA, nB = face_normals(A), face_normals(B)
    eA = A[:, _HEX_EDGES[:, 1]] - A[:, _HEX_EDGES[:, 0]]
    eB = B[:, _HEX_EDGES[:, 1]] - B[:, _HEX_EDGES[:, 0]]
    X = np.cross(eA[:, :, None, :], eB[:, None, :, :]).reshape(len(P), -1, 3)
    nx = np.linalg.norm(X, axis=-1, keepdims=True)
    scale = np.linalg.norm(eA, axis=-1).max(axis=1)[:, None, None] * np.linalg.norm(eB, axis=-1).max(axis=1)[:, None, None]
    X = np.where(nx > 1e-9 * scale, X / np.maximum(nx, 1e-300), 0.0)  # parallel edges: no axis
    axes = np.concatenate([nA, nB, X], axis=1)  # (np, 156, 3)
    pa = np.einsum("pki,pai->pak", A, axes)
    pb = np.einsum("pki,pai->pak", B, axes)
    ov = np.minimum(pa.max(-1), pb.max(-1)) - np.maximum(pa.min(-1), pb.min(-1))
    size = np.ptp(np.concatenate([A, B], axis=1), axis=1).max(axis=1)
    ov = np.where(np.linalg.norm(axes, axis=-1) > 0, ov, np.inf)
    sep = np.any(ov <= rel_tol * size[:, None], axis=1)
    return P[~sep]


def _prototype(protos: dict, key: tuple, corners: np.ndarray, name: str) -> None:
    if key not in protos:
        protos[key] = check_hex_corners(corners, name)


# ----------------------------------------------------------------------------- running-bond wall
def running_bond_wall(n_courses: int, bricks_per_course: int, brick_length: float, brick_height: float,
                      brick_width: float, joint: float = 0.0, half_bricks: bool = True, openings=(),
                      leaves: int = 1, stagger_leaves: bool = False, origin=(0.0, 0.0, 0.0),
                      angle: float = 0.0, name: str = "wall") -> Layout3D:
    """Running-bond wall of bricks length l (x) x width w (y) x height h (z) with joints t between them.

    Course c (from 0 at the bottom) lies at z = c (h + t); even courses hold `bricks_per_course` full bricks,
    odd ones are offset by half a brick with half bricks (l - t)/2 at both ends (`half_bricks`, else the course
    has one brick less and the ends are toothed). Openings (x0, z0, x1, z1) [m, wall frame] go through all
    leaves: every block whose interior meets the opening is cut to its parts on each side of the opening,
    a joint t away from it; parts shorter than l/4 are dropped (builders.cut_opening). Leaf k occupies
    y in [k (w + t), k (w + t) + w] (collar joint t between leaves); with `stagger_leaves` the second leaf's
    courses swap parity (its head joints fall mid-brick of the first leaf). The wall frame is then rotated by
    `angle` about z and translated by `origin`: every block has R = rot_z(angle), position = origin + R p0
    where p0 is its lower-left-front corner; block types are keyed ("box", l, w, h)."""
    n_courses = _integer(f"{name}.courses", n_courses, 1)
    bricks_per_course = _integer(f"{name}.bricks_per_course", bricks_per_course, 1)
    if isinstance(leaves, bool) or leaves not in (1, 2):
        raise InputError(f"{name}.leaves = {leaves!r}: expected 1 or 2")
    for k, v in (("brick_length", brick_length), ("brick_height", brick_height), ("brick_width", brick_width)):
        check_range(f"{name}.{k}", v, 0.0, lo_open=True, expected=f"{k} > 0 [m]")
    check_range(f"{name}.joint", joint, 0.0, hi=0.5 * brick_length, hi_open=True,
                expected="0 <= joint < brick_length / 2 [m]")
    check_range(f"{name}.angle", angle, expected="a finite angle [rad]")
    if not math.isfinite(float(angle)):
        raise InputError(f"{name}.angle = {angle!r}: expected a finite angle [rad]")
    o = np.asarray(origin, dtype=float)
    if o.shape != (3,) or not np.all(np.isfinite(o)):
        raise InputError(f"{name}.origin = {origin!r}: expected 3 finite coordinates [m]")
    l, h, w, t = float(brick_length), float(brick_height), float(brick_width), float(joint)
    ops = []
    for i, op in enumerate(openings):
        if len(op) != 4:
            raise InputError(f"{name}.openings[{i}] = {op!r}: expected [x0, z0, x1, z1]")
        ops.append(tuple(float(v) for v in op))
    # the 2D builder (x, z) gives the courses and the cuts; an extra course of the other parity for leaf 1
    layouts = [running_bond_2d(n_courses, bricks_per_course, l, h, t, half_bricks=half_bricks, openings=ops,
                               name=name)]
    if leaves == 2:
        if stagger_leaves:
            shifted = running_bond_2d(n_courses + 1, bricks_per_course, l, h, t, half_bricks=half_bricks,
                                      name=name)
            # drop course 0 and move every course one down: course c of leaf 1 has the parity of course c + 1
            moved = [Block(b.length, b.height, b.x, b.y - (h + t), b.course - 1, b.group)
                     for b in shifted if b.course > 0]
            for i, op in enumerate(ops):
                moved = cut_opening(moved, op, l, t, False, f"{name}.openings[{i}]")
            layouts.append(moved)
        else:
            layouts.append(layouts[0])
    R = rot_z(float(angle))
    protos: dict = {}
    blocks = []
    for leaf, blocks2d in enumerate(layouts):
        y0 = leaf * (w + t)
        rank: dict = {}
        for b in sorted(blocks2d, key=lambda b: (b.course, b.x)):
            key = ("box", round(b.length, ROUND), round(w, ROUND), round(h, ROUND))
            _prototype(protos, key, box_corners(b.length, w, b.height), f"{name}.block")
            p0 = o + R @ np.array([b.x, y0, b.y])
            k = rank.get(b.course, 0)
            rank[b.course] = k + 1
            blocks.append(Block3D(protos[key] @ R.T + p0, key, R.copy(), p0, b.course, k, leaf))
    return Layout3D(blocks, protos, [], t)


def _integer(name, v, lo=None):
    """int(v) if v is an integer-valued number >= lo, else InputError naming the field."""
    try:
        ok = not isinstance(v, bool) and float(v).is_integer()
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok or (lo is not None and int(v) < lo):
        raise InputError(f"{name} = {v!r}: expected an integer" + ("" if lo is None else f" >= {lo}"))
    return int(v)


# ----------------------------------------------------------------------------- dome
def _plane_corner(planes) -> np.ndarray:
    """Intersection point of 3 planes (n_i . x = d_i)."""
    N = np.array([p[0] for p in planes])
    d = np.array([p[1] for p in planes])
    return np.linalg.solve(N, d)


def dome_voussoir(r_in: float, r_out: float, phi0: float, phi1: float, alpha: float, joint: float) -> np.ndarray:
    """8 corners of a dome voussoir centred on the azimuth 0 (x axis), spanning azimuths [-alpha, alpha] and
    elevations [phi0, phi1] of the shell r_in <= |x| <= r_out, each joint face moved by joint/2 into the block.

    Faces (all planar): intrados / extrados = the planes through the 4 points of the spheres r_in / r_out at
    (phi0|phi1, -alpha|alpha) (isosceles trapezoids); bed faces = the planes through the centre containing the
    generatrices of the cones of elevation phi0 / phi1 at azimuths -alpha and alpha, normal
    (sin phi, 0, -cos phi cos alpha) / |.|; head faces = the meridian planes of azimuth -alpha / alpha. Bed and head
    planes are then offset by joint/2 toward the block, so that two neighbours sharing a nominal plane are
    joint apart. Corners = intersections of the 3 planes (intrados|extrados, bed, head)."""
    ca = math.cos(alpha)

    def chord(r):  # plane through (r cos(phi) cos(a), +-r cos(phi) sin(a), r sin(phi)), phi = phi0, phi1
        p0 = np.array([r * math.cos(phi0) * ca, r * math.sin(phi0)])
        p1 = np.array([r * math.cos(phi1) * ca, r * math.sin(phi1)])
        d = p1 - p0
        n = np.array([d[1], 0.0, -d[0]])  # normal of the chord in the (x, z) section (the plane contains y)
        n /= np.linalg.norm(n)
        return n, float(n @ np.array([p0[0], 0.0, p0[1]]))

    def bed(phi, sign):  # sign +1: lower bed (block above the plane), -1: upper bed
        n = sign * np.array([-math.sin(phi), 0.0, math.cos(phi) * ca])
        n /= np.linalg.norm(n)
        return n, 0.5 * joint  # interior: n . x >= joint/2

    def head(sign):  # sign -1: face at azimuth -alpha, +1: at +alpha; interior: n . x >= joint/2
        n = np.array([math.sin(alpha), -sign * math.cos(alpha), 0.0])
        return n, 0.5 * joint

    C = np.empty((8, 3))
    for k, (phi_s, r_s, y_s) in enumerate([(0, 0, -1), (0, 1, -1), (0, 1, 1), (0, 0, 1),
                                           (1, 0, -1), (1, 1, -1), (1, 1, 1), (1, 0, 1)]):
        C[k] = _plane_corner([chord(r_out if r_s else r_in), bed(phi1 if phi_s else phi0, -1 if phi_s else 1),
                              head(y_s)])
    return C


def dome(span: float = 4.0, thickness: float = 0.48, n_courses: int = 12, blocks_per_course: int = 22,
         joint: float = 0.03, top_elevation: float | None = None, running_bond: bool = True, piers: int = 0,
         pier_blocks: int = 3, pier_height: float = 0.5, name: str = "dome") -> Layout3D:
    """Spherical dome of hexahedral voussoirs (thesis §7.2.1.c; on 4 piers as in §7.2.2.a with piers=4).

    Geometry (thesis: 264 blocks in 12 courses of 22, span 4 m, constant shell thickness 0.48 m, joints 30 mm,
    bed-course blocks about 54 x 24 x 48 cm, regular "plein-sur-joints" bond, i.e. running bond):
    centre at the origin, intrados radius r_i = span/2 (the 22 bed-course blocks are then 2 pi r_i / 22 - t =
    0.541 m long at the intrados, the thesis' 54 cm), extrados r_e = r_i + thickness; course k spans the
    elevations [k D, (k+1) D], D = top_elevation / n_courses, and holds `blocks_per_course` voussoirs of pitch
    2 alpha = 2 pi / blocks_per_course, centred at azimuths 2 alpha j (+ alpha on odd courses when running_bond).
    The thesis gives no top angle and a closed crown is impossible with 22 hexahedra per course, so the default
    `top_elevation` = (pi/2) n/(n+1) leaves an oculus one course high (half-angle 6.9 deg for n = 12): course
    height 0.24 m at the mid-surface, bed-course block 0.0693 m^3 (173 kg at 2500 kg/m^3; the thesis: "about
    170 kg"). Every voussoir is `dome_voussoir` (planar faces, all joint faces moved by t/2 into the block,
    the springing course standing on z = t/2), so the blocks of a course are one prototype (key
    ("voussoir", k, ...)) rotated by R = rot_z(azimuth) (position 0).

    Head joints are exactly t. Bed faces are planar chords of the bed cones, so between two staggered courses
    the bed joint is a thin wedge of mean thickness t, t +- delta with delta <= r_e sin(phi) cos(phi)
    (1 - cos alpha)/cos alpha (<= 1.15 cm for the thesis dome); with running_bond=False it is exactly t.

    Piers (piers > 0; the thesis' §7.2.2.a dome stands on "4 socles" and the bed-course blocks between them
    fall without cohesion, a pyramid of 6 blocks coming loose): rigid hexahedra under the bed course, pier p
    carrying the `pier_blocks` consecutive bed-course blocks starting at j = round(p * n / piers); its top is
    z = -t/2 (a full joint under the blocks), its height `pier_height`, its plan the trapezoid between the
    meridian planes bounding its blocks, from the intrados chord to the extrados tangent (covering the blocks'
    footprint). With 22 blocks and 4 piers of 3 blocks, the gaps hold 3, 2, 2 and 3 unsupported blocks.
    """
    for k, v in (("span", span), ("thickness", thickness)):
        check_range(f"{name}.{k}", v, 0.0, lo_open=True, expected=f"{k} > 0 [m]")
    nc = _integer(f"{name}.courses", n_courses, 1)
    nb = _integer(f"{name}.blocks_per_course", blocks_per_course, 3)
    check_range(f"{name}.joint", joint, 0.0, expected="joint >= 0 [m]")
    top = 0.5 * math.pi * nc / (nc + 1) if top_elevation is None else check_range(
        f"{name}.top_elevation", top_elevation, 0.0, 0.5 * math.pi, lo_open=True, hi_open=True,
        expected="0 < top_elevation < pi/2 [rad] (a closed crown is not made of hexahedra)")
    np_ = _integer(f"{name}.piers", piers, 0)
    if np_ > nb:
        raise InputError(f"{name}.piers = {piers!r}: expected 0 <= piers <= blocks_per_course = {nb}")
    if np_:
        pb = _integer(f"{name}.pier_blocks", pier_blocks, 1)
        starts = [int(round(p * nb / np_)) for p in range(np_)]
        room = min((starts[(p + 1) % np_] - starts[p]) % nb or nb for p in range(np_))
        pb_max = min(room, (nb - 1) // 2)  # a pier spans less than half the circle
        if pb > pb_max:
            raise InputError(f"{name}.pier_blocks = {pier_blocks!r}: expected 1 <= pier_blocks <= {pb_max} "
                             f"(piers must not share blocks and must span less than half the circle)")
        check_range(f"{name}.pier_height", pier_height, 0.0, lo_open=True, expected="pier_height > 0 [m]")
    ri = 0.5 * float(span)
    re = ri + float(thickness)
    t = float(joint)
    alpha = math.pi / nb
    D = top / nc
    protos: dict = {}
    blocks = []
    for k in range(nc):
        key = ("voussoir", k, round(ri, ROUND), round(re, ROUND), round(k * D, ROUND), round((k + 1) * D, ROUND),
               nb, round(t, ROUND))
        C = dome_voussoir(ri, re, k * D, (k + 1) * D, alpha, t)
        try:  # the joints must leave a block (head and bed faces apart, positive orientation)
            check_hex_corners(C, f"{name}.course[{k}]")
        except InputError:
            raise InputError(f"{name}.joint = {joint!r}: the joints leave no proper block in course {k} (blocks too "
                             f"small for the joint; expected a smaller joint, fewer blocks or fewer courses)") from None
        _prototype(protos, key, C, f"{name}.course[{k}]")
        shift = alpha if (running_bond and k % 2) else 0.0
        for j in range(nb):
            R = rot_z(shift + 2 * alpha * j)
            blocks.append(Block3D(protos[key] @ R.T, key, R, np.zeros(3), k, j, 0, "dome"))
    rigid = []
    if np_:
        for p, j0 in enumerate(starts):
            a0, a1 = 2 * alpha * j0 - alpha, 2 * alpha * (j0 + pb - 1) + alpha  # meridian planes bounding its blocks
            am, ha = 0.5 * (a0 + a1), 0.5 * (a1 - a0)
            x_in, x_out = ri * math.cos(ha), re  # intrados chord, extrados tangent (local frame, mid-azimuth)
            plan = np.array([[x_in, -x_in * math.tan(ha)], [x_out, -x_out * math.tan(ha)],
                             [x_out, x_out * math.tan(ha)], [x_in, x_in * math.tan(ha)]])
            z1 = -0.5 * t
            z0 = z1 - float(pier_height)
            C = np.vstack([np.column_stack([plan, np.full(4, z0)]), np.column_stack([plan, np.full(4, z1)])])
            C = C @ rot_z(am).T
            rigid.append(RigidPart3D(f"pier{p}", check_hex_corners(C, f"{name}.pier{p}"), "piers"))
    return Layout3D(blocks, protos, rigid, t)
