"""3D blocks: BlockMesh3D meshing and validation, dolfinx K/M/stress in 3D, BlockType3D (shared factor and
W_bb), DeformableBody3D, RigidBody3D mass properties; against closed forms and conservation laws."""
import numpy as np
import pytest
import scipy.sparse.linalg as sla

from fem_blocks.bodies import (BlockType3D, Clamp3D, DeformableBody3D, Driver, Material, RigidBody3D, Traction,
                               box_inertia, rotation3d, solid_properties)
from fem_blocks.errors import InputError
from fem_blocks.fem_backend import (assemble_operators_3d, elasticity_matrix_3d, stress_operator_3d,
                                    von_mises)
from fem_blocks.meshing import (HEX_SIDES, BlockMesh3D, box_corners, load_msh3d,
                                mesh_box, mesh_hexahedron, validate3d)

E, NU, RHO = 12e9, 0.22, 1900.0
MAT = Material(E, NU, RHO)


# ----------------------------------------------------------------------------- geometry helpers
def voussoir_corners(r1=1.0, r2=1.4, a0=0.2, a1=0.5, d=0.3):
    """Arch voussoir with planar faces: the quadrilateral (r1, r2) x (a0, a1) of an annulus (chords), extruded
    along z by d; exact volume = d x shoelace area."""
    q = np.array([[r1 * np.cos(a0), r1 * np.sin(a0)], [r2 * np.cos(a0), r2 * np.sin(a0)],
                  [r2 * np.cos(a1), r2 * np.sin(a1)], [r1 * np.cos(a1), r1 * np.sin(a1)]])
    area = 0.5 * np.sum(q[:, 0] * np.roll(q[:, 1], -1) - np.roll(q[:, 0], -1) * q[:, 1])
    C = np.vstack([np.c_[q, np.zeros(4)], np.c_[q, np.full(4, d)]])
    return C, d * area


def warped_corners():
    """A hexahedral block with non-planar (ruled) faces: a unit cube with corner 6 moved."""
    C = box_corners(1.0, 0.8, 0.6)
    C[6] += [0.15, 0.1, 0.2]
    C[1] += [0.05, -0.05, 0.0]
    return C


def trilinear_volume(C):
    """Volume of the trilinear block: 2x2x2 Gauss of det J (exact)."""
    m = BlockMesh3D(np.asarray(C, float), np.arange(8, dtype=np.int64)[None], "hexahedron",
                    np.zeros((0, 4), np.int64), np.zeros(0, np.int64))
    return float(m.cell_volumes().sum())


def flux_volume(m):
    """(1/3) ∮ x . n dA over the boundary faces with n dA = x_,xi x x_,eta (right-hand rule), exact for
    triangles (1 point) and bilinear quadrangles (2x2 Gauss, integrand of degree 2 per direction). Equals the
    volume iff every face is ordered with its normal pointing out."""
    X = m.points[m.boundary_faces]
    if X.shape[1] == 3:
        n = 0.5 * np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0])
        return float(np.einsum("fi,fi->", X.mean(axis=1), n) / 3.0)
    g = 1 / np.sqrt(3.0)
    s = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float)
    tot = 0.0
    for xi, eta in ((-g, -g), (g, -g), (g, g), (-g, g)):
        N = 0.25 * (1 + s[:, 0] * xi) * (1 + s[:, 1] * eta)
        dxi = 0.25 * s[:, 0] * (1 + s[:, 1] * eta)
        deta = 0.25 * s[:, 1] * (1 + s[:, 0] * xi)
        x = np.einsum("a,fai->fi", N, X)
        n = np.cross(np.einsum("a,fai->fi", dxi, X), np.einsum("a,fai->fi", deta, X))
        tot += np.einsum("fi,fi->", x, n)
    return tot / 3.0


def face_normals(m):
    X = m.points[m.boundary_faces]
    if X.shape[1] == 3:
        n = np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0])
    else:
        n = np.cross(X[:, 2] - X[:, 0], X[:, 3] - X[:, 1])
    return n / np.linalg.norm(n, axis=1)[:, None]


# ----------------------------------------------------------------------------- meshing
@pytest.mark.parametrize("cell", ["hexahedron", "tetrahedron"])
def test_box_mesh_counts_orientation_and_tags(cell):
    lx, ly, lz, (n0, n1, n2) = 0.4, 0.3, 0.2, (4, 3, 2)
    m = mesh_box(lx, ly, lz, divisions=(n0, n1, n2), cell=cell)
    validate3d(m, "box")
    ncell = n0 * n1 * n2 * (1 if cell == "hexahedron" else 6)
    nface = 2 * (n0 * n1 + n1 * n2 + n0 * n2) * (1 if cell == "hexahedron" else 2)
    assert m.points.shape == ((n0 + 1) * (n1 + 1) * (n2 + 1), 3) and m.points.dtype == np.float64
    assert m.cells.shape == (ncell, 8 if cell == "hexahedron" else 4) and m.cells.dtype == np.int64
    assert m.boundary_faces.shape == (nface, 4 if cell == "hexahedron" else 3)
    assert m.boundary_nodes().size == (n0 + 1) * (n1 + 1) * (n2 + 1) - (n0 - 1) * (n1 - 1) * (n2 - 1)
    assert np.all(m.cell_volumes() > 0)
    assert m.volume() == pytest.approx(lx * ly * lz, rel=1e-12)
    assert flux_volume(m) == pytest.approx(lx * ly * lz, rel=1e-12)  # every face normal points out
    assert np.allclose(m.bbox(), (0, 0, 0, lx, ly, lz), rtol=0, atol=1e-15)
    assert m.tag_names == {nm: i for i, nm in enumerate(HEX_SIDES)}
    normal = {"bottom": (0, 0, -1), "top": (0, 0, 1), "front": (0, -1, 0), "right": (1, 0, 0),
              "back": (0, 1, 0), "left": (-1, 0, 0)}
    area = {"bottom": lx * ly, "top": lx * ly, "front": lx * lz, "back": lx * lz, "right": ly * lz, "left": ly * lz}
    n, A = face_normals(m), m.face_areas()
    for nm, tag in m.tag_names.items():
        sel = m.face_tags == tag
        assert np.allclose(n[sel], normal[nm], atol=1e-12), nm
        assert A[sel].sum() == pytest.approx(area[nm], rel=1e-12), nm
    assert np.all(m.face_tags >= 0)


def test_mesh_size_option_and_determinism_under_translation():
    """size -> n = round(longest parallel edge / size); the same block type meshed twice, or at another
    position, gives identical node counts and connectivity (points differ by the translation)."""
    C, _ = voussoir_corners()
    m1 = mesh_hexahedron(C, size=0.1)
    n = (round(0.4 / 0.1), round(np.linalg.norm(C[2] - C[1]) / 0.1), round(0.3 / 0.1))
    assert m1.cells.shape[0] == np.prod(n)
    off = np.array([12.3, -4.5, 7.1])
    for cell in ("hexahedron", "tetrahedron"):
        a = mesh_hexahedron(C, size=0.1, cell=cell)
        b = mesh_hexahedron(C, size=0.1, cell=cell)
        c = mesh_hexahedron(C + off, size=0.1, cell=cell)
        assert a.n_nodes == b.n_nodes == c.n_nodes
        assert np.array_equal(a.points, b.points) and np.array_equal(a.cells, b.cells)
        assert np.array_equal(a.cells, c.cells) and np.array_equal(a.boundary_faces, c.boundary_faces)
        assert np.allclose(c.points - off, a.points, rtol=0, atol=1e-12 * np.abs(c.points).max())  # gmsh round-off
        t = a.translated(*off)
        assert np.array_equal(t.cells, a.cells) and np.allclose(t.points, a.points + off, rtol=0, atol=0)


@pytest.mark.parametrize("cell, structured", [("hexahedron", True), ("tetrahedron", True), ("tetrahedron", False)])
def test_voussoir_block_volume_and_outward_faces(cell, structured):
    C, V = voussoir_corners()
    kw = dict(divisions=(3, 2, 2)) if structured else dict(size=0.08)
    m = mesh_hexahedron(C, cell=cell, structured=structured, **kw)
    validate3d(m, "voussoir")
    assert m.cell_type == cell
    assert m.volume() == pytest.approx(V, rel=1e-12)
    assert flux_volume(m) == pytest.approx(V, rel=1e-12)
    assert np.all(m.face_tags >= 0) and set(np.unique(m.face_tags)) == set(range(6))
    # corners of the block are nodes of the mesh
    d = np.linalg.norm(m.points[:, None, :] - C[None], axis=2).min(axis=0)
    assert np.all(d < 1e-13)


def test_dome_voussoir_block():
    """Voussoir of a spherical dome (radii 5 and 5.5, elevations 0.3-0.45, azimuths 0.1-0.35): its 8 corners
    span planar faces (symmetric trapezoids), so the hexahedral, Kuhn-tetrahedral and unstructured meshes all
    have the polyhedron's volume (1e-12)."""
    def sph(r, t, p):
        return [r * np.cos(t) * np.cos(p), r * np.cos(t) * np.sin(p), r * np.sin(t)]
    C = np.array([sph(r, t, p) for t in (0.3, 0.45) for r, p in ((5, 0.1), (5.5, 0.1), (5.5, 0.35), (5, 0.35))])
    V = trilinear_volume(C)
    for cell, structured in (("hexahedron", True), ("tetrahedron", True), ("tetrahedron", False)):
        m = mesh_hexahedron(C, size=0.12, cell=cell, structured=structured)
        assert m.volume() == pytest.approx(V, rel=1e-12) and flux_volume(m) == pytest.approx(V, rel=1e-12)
        top = m.face_tags == m.tag_names["top"]
        assert np.all(face_normals(m)[top] @ [0, 0, 1] > 0.5)  # the upper bed joint faces up


def test_warped_block_is_the_trilinear_block():
    """Non-planar faces: the hexahedral mesh is the trilinear image of a grid, so its volume is the trilinear
    block's volume exactly, and so is the flux integral over the ruled faces."""
    C = warped_corners()
    V = trilinear_volume(C)
    m = mesh_hexahedron(C, divisions=(3, 3, 2))
    assert m.volume() == pytest.approx(V, rel=1e-12)
    assert flux_volume(m) == pytest.approx(V, rel=1e-12)
    t = mesh_hexahedron(C, divisions=(3, 3, 2), cell="tetrahedron")
    assert np.allclose(t.points, m.points, rtol=0, atol=0) and t.cells.shape[0] == 6 * m.cells.shape[0]
    assert flux_volume(t) == pytest.approx(t.volume(), rel=1e-12)


def test_hexahedron_corner_errors():
    C = box_corners(1, 1, 1)
    with pytest.raises(InputError, match="inverted .*counter-clockwise"):
        mesh_hexahedron(C[[0, 3, 2, 1, 4, 7, 6, 5]], divisions=1)
    flat = C.copy()
    flat[4:, 2] = 0.0
    with pytest.raises(InputError, match="folded or flat"):
        mesh_hexahedron(flat, divisions=1)
    folded = C.copy()
    folded[6] = [-0.5, -0.5, -1.0]
    with pytest.raises(InputError, match="folded or flat"):
        mesh_hexahedron(folded, divisions=1)
    with pytest.raises(InputError, match="corners: expected 8"):
        mesh_hexahedron(C[:7], divisions=1)
    with pytest.raises(InputError, match="exactly one of mesh_size or divisions"):
        mesh_hexahedron(C)
    with pytest.raises(InputError, match="divisions"):
        mesh_hexahedron(C, divisions=(2, 0, 1))
    with pytest.raises(InputError, match="unstructured meshes are tetrahedral"):
        mesh_hexahedron(C, size=0.5, structured=False)
    with pytest.raises(InputError, match=r"box\.ly"):
        mesh_box(1, -1, 1, divisions=1)


# ----------------------------------------------------------------------------- .msh reading and validation
def _msh3(nodes, elements, physical=((2, 1, "base"), (3, 2, "block"))):
    """ASCII MSH 2.2 text; elements are (type, physical tag, node ids...)."""
    lines = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$PhysicalNames", str(len(physical))]
    lines += [f'{d} {t} "{n}"' for d, t, n in physical]
    lines += ["$EndPhysicalNames", "$Nodes", str(len(nodes))]
    lines += [f"{i} {x} {y} {z}" for i, (x, y, z) in nodes.items()]
    lines += ["$EndNodes", "$Elements", str(len(elements))]
    lines += [f"{k + 1} {e[0]} 2 {e[1]} {e[1]} " + " ".join(map(str, e[2:])) for k, e in enumerate(elements)]
    lines += ["$EndElements", ""]
    return "\n".join(lines)


# two unit cubes along x: bottom nodes 1..6 (z=0), top nodes 7..12 (z=1); node 13 unused
NODES3 = {i + 1: (x, y, z) for i, (z, y, x) in enumerate((z, y, x) for z in (0, 1) for y in (0, 1)
                                                         for x in (0, 1, 2))}
NODES3[13] = (9.0, 9.0, 9.0)
HEX_A = (1, 2, 5, 4, 7, 8, 11, 10)
HEX_B = (2, 3, 6, 5, 8, 9, 12, 11)
BASE = [(3, 1, 1, 4, 5, 2), (3, 1, 2, 5, 6, 3)]  # bottom quadrangles, physical surface 1 "base"


def test_load_msh3d_hexahedra_tags_unused_node(tmp_path):
    p = tmp_path / "two.msh"
    p.write_text(_msh3(NODES3, BASE + [(5, 2, *HEX_A), (5, 2, *HEX_B)]))
    m = load_msh3d(str(p))
    assert m.cell_type == "hexahedron" and m.cells.shape == (2, 8) and m.n_nodes == 12
    assert np.allclose(m.points, [NODES3[i] for i in range(1, 13)])
    assert m.tag_names == {"base": 1, "untagged": -1}
    base = m.boundary_faces[m.face_tags == 1]
    assert len(base) == 2 and np.allclose(face_normals(m)[m.face_tags == 1], [0, 0, -1])
    assert m.boundary_faces.shape == (10, 4) and m.volume() == pytest.approx(2.0, rel=1e-14)
    assert flux_volume(m) == pytest.approx(2.0, rel=1e-14)


def test_load_msh3d_negative_input_is_reoriented(tmp_path):
    mirror = [0, 3, 2, 1, 4, 7, 6, 5]
    p = tmp_path / "neg.msh"
    p.write_text(_msh3(NODES3, [(5, 2, *np.array(HEX_A)[mirror]), (5, 2, *np.array(HEX_B)[mirror])]))
    m = load_msh3d(str(p))
    assert np.all(m.cell_volumes() > 0) and flux_volume(m) == pytest.approx(2.0, rel=1e-14)
    tets = [(4, 2, 1, 2, 4, 7), (4, 2, 2, 4, 7, 8)]
    p.write_text(_msh3(NODES3, [(t[0], t[1], t[2], t[4], t[3], t[5]) for t in tets]))  # all negative
    assert load_msh3d(str(p)).cell_volumes().min() > 0


@pytest.mark.parametrize("elements, match", [
    ([(5, 2, *HEX_A), (5, 2, *np.array(HEX_B)[[0, 3, 2, 1, 4, 7, 6, 5]])], r"element 2 \(gmsh tag\) is inverted"),
    ([(11, 2, 1, 2, 4, 7, 13, 13, 13, 13, 13, 13)], r"10-node tetrahedron \(gmsh type 11\)"),
    ([(6, 2, 1, 2, 4, 7, 8, 10)], r"6-node prism \(gmsh type 6\)"),
    ([(5, 2, *HEX_A), (4, 2, 2, 3, 5, 8)], r"mixed element types 4-node tetrahedron .*8-node hexahedron"),
    (BASE, "no 3D element"),
    ([(4, 2, 1, 2, 4, 7), (4, 2, 1, 2, 4, 8)], r"elements 1 \(gmsh tag\) and 2 \(gmsh tag\) overlap"),
])
def test_load_msh3d_rejects(tmp_path, elements, match):
    p = tmp_path / "bad.msh"
    p.write_text(_msh3(NODES3, elements))
    with pytest.raises(InputError, match=match) as e:
        load_msh3d(str(p))
    assert str(p) in str(e.value)


def test_load_msh3d_duplicate_nodes_named(tmp_path):
    nodes = dict(NODES3)
    nodes[14] = nodes[2]  # cube B uses a copy of node 2
    p = tmp_path / "dup.msh"
    p.write_text(_msh3(nodes, [(5, 2, *HEX_A), (5, 2, 14, 3, 6, 5, 8, 9, 12, 11)]))
    with pytest.raises(InputError, match=r"nodes 2 \(gmsh tag\) and 14 \(gmsh tag\) are duplicates"):
        load_msh3d(str(p))


def cubes(origins):
    """Unit hexahedra at integer origins, shared nodes merged."""
    pts, cells, index = [], [], {}
    for o in origins:
        c = []
        for dx, dy, dz in box_corners(1, 1, 1).astype(int):
            k = (o[0] + dx, o[1] + dy, o[2] + dz)
            if k not in index:
                index[k] = len(pts)
                pts.append(k)
            c.append(index[k])
        cells.append(c)
    return np.array(pts, float), np.array(cells, np.int64)


def expect3(mesh, *words):
    with pytest.raises(InputError) as e:
        validate3d(mesh, "blk.msh")
    for w in words:
        assert w in str(e.value), str(e.value)


def test_validate3d_errors():
    P, C = cubes([(0, 0, 0), (1, 0, 0)])
    validate3d(BlockMesh3D.from_cells(P, C), "ok")
    # inverted hexahedron (mirrored node order)
    bad = C.copy()
    bad[1] = bad[1, [0, 3, 2, 1, 4, 7, 6, 5]]
    m = BlockMesh3D(P, bad, "hexahedron", np.zeros((10, 4), np.int64), np.zeros(10, np.int64))
    expect3(m, "element 1 is inverted")
    # degenerate tetrahedron (flat)
    Pt = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.3, 0.0]])
    expect3(BlockMesh3D(Pt, np.array([[0, 1, 2, 3]]), "tetrahedron", np.zeros((4, 3), np.int64),
                        np.zeros(4, np.int64)), "element 0 is degenerate")
    # hexahedron with a folded corner: positive at the centre, negative at corner 6
    Pf = box_corners(1, 1, 1)
    Pf[6] = [0.3, 0.3, 0.3]
    expect3(BlockMesh3D(Pf, np.arange(8, dtype=np.int64)[None], "hexahedron", np.zeros((6, 4), np.int64),
                        np.zeros(6, np.int64)), "element 0 is inverted", "corner 6")
    # repeated node, unused node, out-of-range index, NaN, dtype
    rep = C.copy()
    rep[0, 1] = rep[0, 0]
    expect3(BlockMesh3D(P, rep, "hexahedron", np.zeros((10, 4), np.int64), np.zeros(10, np.int64)),
            "element 0 repeats node")
    expect3(BlockMesh3D(np.vstack([P, [[5, 5, 5]]]), C, "hexahedron", np.zeros((10, 4), np.int64),
                        np.zeros(10, np.int64)), "node 12 is not used")
    expect3(BlockMesh3D(P, C + 1, "hexahedron", np.zeros((10, 4), np.int64), np.zeros(10, np.int64)),
            "refers to a node that does not exist")
    Pn = P.copy()
    Pn[3, 1] = np.nan
    expect3(BlockMesh3D(Pn, C, "hexahedron", np.zeros((10, 4), np.int64), np.zeros(10, np.int64)),
            "node 3 has a non-finite")
    expect3(BlockMesh3D(P, C.astype(np.int32), "hexahedron", np.zeros((10, 4), np.int64), np.zeros(10, np.int64)),
            "cells: expected an int64")
    expect3(BlockMesh3D(P, C, "prism", np.zeros((10, 4), np.int64), np.zeros(10, np.int64)), "cell_type")
    # duplicate nodes: cube 1 on its own copy of the shared face
    P2 = np.vstack([P, P[C[1, [0, 3, 4, 7]]]])
    C2 = C.copy()
    C2[1, [0, 3, 4, 7]] = np.arange(len(P), len(P) + 4)
    expect3(BlockMesh3D(P2, C2, "hexahedron", np.zeros((12, 4), np.int64), np.zeros(12, np.int64)),
            "are duplicates")
    # disconnected, touching along an edge only, touching at a vertex only
    Pd, Cd = cubes([(0, 0, 0), (3, 0, 0)])
    expect3(BlockMesh3D.from_cells(Pd, Cd), "2 pieces not connected through faces")
    Pe, Ce = cubes([(0, 0, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (1, 1, 0)])  # (0,0,0) and (1,1,0) share an edge
    expect3(BlockMesh3D.from_cells(Pe, Ce), "non-manifold boundary at the edge between nodes")
    Pv, Cv = cubes([(0, 0, 0), (0, -1, 0), (1, -1, 0), (2, -1, 0), (2, 0, 0), (2, 1, 0), (2, 1, 1), (1, 1, 1)])
    mv = BlockMesh3D.from_cells(Pv, Cv)
    expect3(mv, "non-manifold boundary at node")
    # three hexahedra on one face (non-manifold face), boundary faces not matching the cells
    P3 = np.vstack([P, P[C[1, [1, 2, 5, 6]]] - [0.5, 0, 0]])  # a third cell on the face x = 1
    C3 = np.vstack([C, [C[1, 0], 12, 13, C[1, 3], C[1, 4], 14, 15, C[1, 7]]])
    with pytest.raises(InputError, match="non-manifold mesh: the face with nodes"):
        validate3d(BlockMesh3D(P3, C3, "hexahedron", np.zeros((0, 4), np.int64), np.zeros(0, np.int64)), "x")
    good = BlockMesh3D.from_cells(P, C)
    flipped = BlockMesh3D(P, C, "hexahedron", good.boundary_faces[:, ::-1].copy(), good.face_tags)
    expect3(flipped, "normal pointing out")


# ----------------------------------------------------------------------------- FE operators
def jittered(m, amp, seed=1):
    """Interior nodes moved randomly (cells stay valid): a distorted mesh for the patch test."""
    rng = np.random.default_rng(seed)
    P = m.points.copy()
    inner = np.setdiff1d(np.arange(m.n_nodes), m.boundary_nodes())
    P[inner] += rng.uniform(-amp, amp, size=(inner.size, 3))
    out = BlockMesh3D(P, m.cells, m.cell_type, m.boundary_faces, m.face_tags, dict(m.tag_names), "jittered")
    validate3d(out, "jittered")
    return out


def meshes():
    return {
        "tet": mesh_box(0.5, 0.3, 0.25, divisions=(3, 3, 3), cell="tetrahedron"),
        "hex": mesh_box(0.5, 0.3, 0.25, divisions=(3, 3, 3)),
        "distorted-hex": jittered(mesh_hexahedron(warped_corners(), divisions=(3, 3, 3)), 0.04),
        "voussoir-tet": mesh_hexahedron(voussoir_corners()[0], size=0.12, cell="tetrahedron", structured=False),
    }


@pytest.fixture(scope="module")
def ops():
    return {k: (m, assemble_operators_3d(m, E, NU, RHO)) for k, m in meshes().items()}


def rigid_modes(X):
    n = len(X)
    modes = []
    for c in range(3):
        u = np.zeros((n, 3))
        u[:, c] = 1.0
        modes.append(u.ravel())
    for w in np.eye(3):
        modes.append(np.cross(w, X - X.mean(axis=0)).ravel())
    return modes


@pytest.mark.parametrize("case", ["tet", "hex", "distorted-hex", "voussoir-tet"])
def test_mass_totals_rigid_modes_symmetry(ops, case):
    m, o = ops[case]
    V = m.volume()
    n = m.n_nodes
    for M in (o.M_consistent, o.M_lumped):
        assert M.shape == (3 * n, 3 * n)
        for c in range(3):  # total mass per direction: e_c^T M e_c = rho V
            e = np.zeros((n, 3))
            e[:, c] = 1.0
            assert e.ravel() @ (M @ e.ravel()) == pytest.approx(RHO * V, rel=1e-12)
    ML = o.M_lumped
    assert ML.nnz == 3 * n and np.all(ML.tocoo().row == ML.tocoo().col)  # diagonal
    assert np.allclose(ML.diagonal(), np.asarray(o.M_consistent.sum(axis=1)).ravel(), rtol=1e-12)  # = row sums
    assert np.all(ML.diagonal() > 0)
    K = o.K
    assert abs(K - K.T).max() <= 1e-14 * abs(K).max()
    nK = sla.eigsh(K, k=1, which="LM", return_eigenvectors=False)[0]  # ||K||_2
    for u in rigid_modes(m.points):
        assert np.linalg.norm(K @ u) <= 1e-10 * nK * np.linalg.norm(u)
    # exactly 6 zero modes: K + (rigid projector) is positive definite
    R = np.array(rigid_modes(m.points)).T
    lam = np.linalg.eigvalsh(K.toarray() + nK * R @ np.linalg.pinv(R))
    assert lam.min() > 1e-8 * nK


def linear_field(X, seed=0):
    """u = A x + b with a random (non-symmetric) A: uniform strain eps = sym(A)."""
    rng = np.random.default_rng(seed)
    A = rng.uniform(-1e-3, 1e-3, (3, 3))
    b = rng.uniform(-1e-3, 1e-3, 3)
    return (X @ A.T + b).ravel(), 0.5 * (A + A.T)


def voigt(eps):
    return np.array([eps[0, 0], eps[1, 1], eps[2, 2], 2 * eps[1, 2], 2 * eps[0, 2], 2 * eps[0, 1]])


@pytest.mark.parametrize("case", ["tet", "hex", "distorted-hex", "voussoir-tet"])
def test_patch_test(ops, case):
    """Boundary nodes follow u = A x + b: the FE solution reproduces it at the interior nodes and every cell
    has the Hooke stress D eps (1e-10)."""
    m, o = ops[case]
    u_ex, eps = linear_field(m.points, seed=3)
    bn = m.boundary_nodes()
    b = np.zeros(3 * m.n_nodes, bool)
    b[(3 * bn[:, None] + np.arange(3)).ravel()] = True
    assert (~b).sum() > 0
    K = o.K.tocsr()
    u = u_ex.copy()
    u[~b] = sla.spsolve(K[~b][:, ~b].tocsc(), -K[~b][:, b] @ u_ex[b])
    assert np.abs(u - u_ex).max() <= 1e-10 * np.abs(u_ex).max()
    s = (stress_operator_3d(m, E, NU) @ u).reshape(-1, 6)
    s_ex = elasticity_matrix_3d(E, NU) @ voigt(eps)
    assert np.abs(s - s_ex).max() <= 1e-10 * np.abs(s_ex).max()


def test_hooke_closed_forms_and_von_mises():
    lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
    D = elasticity_matrix_3d(E, NU)
    s = D @ np.array([1e-4, 0, 0, 0, 0, 0])  # uniaxial strain
    assert np.allclose(s, [(lam + 2 * mu) * 1e-4, lam * 1e-4, lam * 1e-4, 0, 0, 0], rtol=1e-14)
    s = D @ np.array([0, 0, 0, 2e-4, 0, 0])  # engineering shear
    assert s[3] == pytest.approx(mu * 2e-4, rel=1e-14)
    # uniaxial stress: eps = (1, -nu, -nu) sigma / E
    sig = 3e6
    assert np.allclose(D @ np.array([1, -NU, -NU, 0, 0, 0]) * sig / E, [sig, 0, 0, 0, 0, 0], atol=1e-9 * sig)
    assert von_mises(np.array([sig, 0, 0, 0, 0, 0]))[0] == pytest.approx(sig, rel=1e-14)
    assert von_mises(np.array([0, 0, 0, 0, 0, sig]))[0] == pytest.approx(np.sqrt(3) * sig, rel=1e-14)
    assert von_mises(np.array([sig, sig, sig, 0, 0, 0]))[0] == pytest.approx(0.0, abs=1e-9)


def test_operator_input_errors():
    m = mesh_box(1, 1, 1, divisions=1)
    with pytest.raises(InputError, match="nu"):
        assemble_operators_3d(m, E, 0.5, RHO)
    with pytest.raises(InputError, match="rho"):
        assemble_operators_3d(m, E, NU, 0.0)
    from fem_blocks.meshing import mesh_rectangle
    with pytest.raises(InputError, match="expected a 3D mesh"):
        stress_operator_3d(mesh_rectangle(1, 1, 0.5), E, NU)
    with pytest.raises(InputError, match="expected a 3D mesh"):
        BlockType3D(mesh_rectangle(1, 1, 0.5), MAT)


# ----------------------------------------------------------------------------- static closed forms
def static_solve(body, f):
    bt = body.type
    free = ~body.clamped
    u = np.zeros(bt.ndof)
    u[free] = sla.spsolve(bt.K.tocsr()[free][:, free].tocsc(), f[free])
    return u.reshape(-1, 3)


@pytest.mark.parametrize("cell", ["hexahedron", "tetrahedron"])
def test_bar_under_axial_traction_exact(cell):
    """Bar [0,L]x[0,b]x[0,h], traction sigma on x = L, symmetry planes x = 0 (ux), y = 0 (uy), z = 0 (uz):
    uniform uniaxial stress, u = sigma/E (x, -nu y, -nu z), reproduced exactly by P1 and Q1 (1e-10)."""
    L, b, h, sig = 1.2, 0.3, 0.2, 2e6
    bt = BlockType3D(mesh_box(L, b, h, divisions=(6, 2, 2), cell=cell), MAT)
    body = DeformableBody3D(bt, clamps=[Clamp3D(tag="left", components="x"), Clamp3D(tag="front", components="y"),
                                        Clamp3D(tag="bottom", components="z")],
                            tractions=[Traction("right", (sig, 0.0, 0.0))])
    f = body.external_load(0.0, np.zeros(3))
    assert f.reshape(-1, 3).sum(axis=0) == pytest.approx([sig * b * h, 0, 0], rel=1e-13, abs=1e-9)
    U = static_solve(body, f)
    X = bt.mesh.points
    U_ex = sig / E * np.c_[X[:, 0], -NU * X[:, 1], -NU * X[:, 2]]
    assert np.abs(U - U_ex).max() <= 1e-10 * np.abs(U_ex).max()
    s = (bt.stress_operator @ U.ravel()).reshape(-1, 6)
    assert np.abs(s - [sig, 0, 0, 0, 0, 0]).max() <= 1e-10 * sig


def test_hanging_bar_under_self_weight_nodal_exact():
    """Q1 bar under gravity g along +x, ux = 0 at x = 0, nu = 0: u_x(x) = rho g (L x - x²/2)/E; on a structured
    hexahedral mesh every x-line is a 1D linear-element problem, whose nodal values are exact (1e-10)."""
    L, g = 2.0, 9.81
    mat = Material(E, 0.0, RHO)
    bt = BlockType3D(mesh_box(L, 0.2, 0.1, divisions=(8, 2, 1)), mat, mass="consistent")
    body = DeformableBody3D(bt, clamps=[Clamp3D(tag="left", components="x"), Clamp3D(tag="front", components="y"),
                                        Clamp3D(tag="bottom", components="z")])
    f = body.external_load(0.0, np.array([g, 0.0, 0.0]))
    assert f.reshape(-1, 3).sum(axis=0)[0] == pytest.approx(RHO * bt.mesh.volume() * g, rel=1e-12)
    U = static_solve(body, f)
    x = bt.mesh.points[:, 0]
    ux = RHO * g * (L * x - 0.5 * x * x) / E
    assert np.abs(U[:, 0] - ux).max() <= 1e-10 * ux.max()
    assert np.abs(U[:, 1:]).max() <= 1e-10 * ux.max()


def test_cantilever_tip_deflection_vs_timoshenko():
    """Clamped at x = 0, shear traction P/A on x = L (L = 2, square 0.2 section): mean tip deflection vs
    Timoshenko P L³/(3EI) + P L/(k G A) (Cowper k = 10(1+nu)/(12+11nu)). Q1 hexahedra 40x4x4: within 4 %
    (measured 3.3 %, shear locking of full integration); the error drops by > 3 from 20x2x2 (measured 11.2 %)."""
    L, b, h, P = 2.0, 0.2, 0.2, 1e4
    I, A, G = b * h ** 3 / 12, b * h, E / (2 * (1 + NU))
    k = 10 * (1 + NU) / (12 + 11 * NU)
    d_ex = P * L ** 3 / (3 * E * I) + P * L / (k * G * A)
    err = []
    for div in ((20, 2, 2), (40, 4, 4)):
        bt = BlockType3D(mesh_box(L, b, h, divisions=div), MAT)
        body = DeformableBody3D(bt, clamps=[Clamp3D(tag="left")], tractions=[Traction("right", (0, 0, -P / A))])
        U = static_solve(body, body.external_load(0.0, np.zeros(3)))
        tip = np.isclose(bt.mesh.points[:, 0], L)
        err.append(abs(-U[tip, 2].mean() / d_ex - 1))
        assert abs(U[tip, 1].mean()) < 1e-9 * d_ex  # no out-of-plane bending (anticlastic: antisymmetric in y)
    assert err[1] < 0.04 and err[0] / err[1] > 3


# ----------------------------------------------------------------------------- BlockType3D prototype
def test_wbb_spd_shared_and_translation_invariant():
    m = mesh_hexahedron(voussoir_corners()[0], divisions=(3, 2, 2))
    bt = BlockType3D(m, MAT)
    h, th = 1e-3, 0.5
    none = np.zeros(bt.ndof, bool)
    W = bt.step_operator(h, th, none).W_bb
    nb = bt.boundary_nodes.size
    assert W.shape == (3 * nb, 3 * nb) and nb == m.boundary_nodes().size
    assert np.array_equal(bt.boundary_dofs, (3 * bt.boundary_nodes[:, None] + np.arange(3)).ravel())
    assert np.abs(W - W.T).max() <= 1e-14 * np.abs(W).max()
    assert np.linalg.eigvalsh(W).min() > 0
    # W_bb = B Mhat^-1 B^T against a dense inverse
    Mhat = (bt.M + (h * th) ** 2 * bt.K).toarray()
    Wd = np.linalg.inv(Mhat)[np.ix_(bt.boundary_dofs, bt.boundary_dofs)]
    assert np.abs(W - Wd).max() <= 1e-10 * np.abs(Wd).max()
    # two instances share the type's operator; a type built on a translated copy has the same W_bb
    a = DeformableBody3D(bt, position=(0, 0, 0))
    b = DeformableBody3D(bt, position=(3.0, -1.0, 2.5))
    assert bt.step_operator(h, th, a.clamped) is bt.step_operator(h, th, b.clamped)
    assert np.allclose(b.reference_points - a.reference_points, [3.0, -1.0, 2.5], rtol=0, atol=1e-15)
    bt2 = BlockType3D(m.translated(3.0, -1.0, 2.5), MAT)
    W2 = bt2.step_operator(h, th, none).W_bb
    assert np.abs(W2 - W).max() <= 1e-12 * np.abs(W).max()
    # rotated instance: a type meshed in the rotated position has W' = diag(R) W diag(R)^T
    R = rotation3d([1.0, 2.0, 0.5], 0.7)
    bt3 = BlockType3D(m.transformed(R, (1.0, 2.0, 3.0)), MAT)
    W3 = bt3.step_operator(h, th, none).W_bb
    Rb = np.kron(np.eye(nb), R)
    assert np.abs(W3 - Rb @ W @ Rb.T).max() <= 1e-9 * np.abs(W).max()
    c = DeformableBody3D(bt, position=(1.0, 2.0, 3.0), R=R)
    assert np.allclose(c.reference_points, bt3.mesh.points, rtol=0, atol=1e-14)


def test_clamped_step_operator_and_loads():
    bt = BlockType3D(mesh_box(0.4, 0.2, 0.2, divisions=(2, 1, 1), cell="tetrahedron"), MAT, mass="consistent")
    body = DeformableBody3D(bt, clamps=[Clamp3D(box=(-1, 0.0, -1, 1, -1, 1))])
    nodes = np.flatnonzero(np.isclose(bt.mesh.points[:, 0], 0.0))
    assert np.array_equal(np.flatnonzero(body.clamped), (3 * nodes[:, None] + np.arange(3)).ravel())
    op = bt.step_operator(1e-3, 1.0, body.clamped)
    W = op.W_bb
    cl = np.isin(bt.boundary_dofs, np.flatnonzero(body.clamped))
    assert np.all(W[cl] == 0) and np.all(W[:, cl] == 0)
    assert np.linalg.eigvalsh(W[np.ix_(~cl, ~cl)]).min() > 0
    # gravity: total weight; traction on a tag: total force = t x area, rotated instance loads in its frame
    g = np.array([0.0, 0.0, -9.81])
    assert bt.gravity_load(g).reshape(-1, 3).sum(axis=0) == pytest.approx(RHO * 0.016 * g, rel=1e-12)
    R = rotation3d([0, 0, 1], np.pi / 2)
    rb = DeformableBody3D(bt, R=R, tractions=[Traction("top", (1e3, 2e3, 3e3), 2.0)])
    F = rb.external_load(0.0, g).reshape(-1, 3) @ R.T  # back to the global frame
    assert F.sum(axis=0) == pytest.approx(RHO * 0.016 * g + 2.0 * 0.08 * np.array([1e3, 2e3, 3e3]), rel=1e-12)
    # single components on a rotated block: global y = type x for a 90° rotation about z
    m = DeformableBody3D(bt, R=R, clamps=[Clamp3D(tag="left", components="y")])
    left = np.unique(bt.mesh.boundary_faces[bt.mesh.face_tags == 5])
    assert np.array_equal(np.flatnonzero(m.clamped), 3 * left)
    with pytest.raises(InputError, match="rotation maps axes to axes"):
        DeformableBody3D(bt, R=rotation3d([0, 0, 1], 0.3), clamps=[Clamp3D(tag="left", components="x")])
    with pytest.raises(InputError, match="selects no node"):
        DeformableBody3D(bt, clamps=[Clamp3D(box=(5, 6, 5, 6, 5, 6))])
    with pytest.raises(InputError, match="subset of 'xyz'"):
        DeformableBody3D(bt, clamps=[Clamp3D(tag="left", components="xw")])
    with pytest.raises(InputError, match="rotation"):
        DeformableBody3D(bt, R=np.diag([1.0, 1.0, -1.0]))


# ----------------------------------------------------------------------------- RigidBody3D
def test_rigid_box_inertia_closed_form():
    lx, ly, lz, rho = 0.6, 0.4, 0.25, 2100.0
    m = rho * lx * ly * lz
    I_ex = m / 12 * np.diag([ly ** 2 + lz ** 2, lx ** 2 + lz ** 2, lx ** 2 + ly ** 2])
    a = RigidBody3D.box(lx, ly, lz, origin=(1, 2, 3), rho=rho)
    b = RigidBody3D(box_corners(lx, ly, lz, (1, 2, 3)), rho=rho)  # trilinear quadrature
    c = RigidBody3D(mesh_box(lx, ly, lz, divisions=(2, 2, 1), cell="tetrahedron"), rho=rho)  # tetrahedra
    for body in (a, b, c):
        assert body.mass == pytest.approx(m, rel=1e-12)
        assert np.abs(body.inertia0 - I_ex).max() <= 1e-12 * I_ex.max()
    assert np.allclose(a.center0, [1 + lx / 2, 2 + ly / 2, 3 + lz / 2], rtol=1e-14)
    assert np.allclose(box_inertia(m, lx, ly, lz), I_ex, rtol=1e-15)


def test_rigid_parallelepiped_and_voussoir_inertia():
    """Parallelepiped x = c + A xi, xi in [-1/2, 1/2]^3: S = V A A^T / 12 (closed form); a planar-faced
    voussoir: trilinear quadrature = tetrahedral mesh (both exact)."""
    A = np.array([[0.5, 0.1, 0.05], [0.0, 0.3, 0.08], [0.02, 0.0, 0.2]])
    xi = box_corners(1, 1, 1) - 0.5
    C = xi @ A.T + [0.3, -0.2, 1.0]
    rho = 2500.0
    body = RigidBody3D(C, rho=rho)
    V = np.linalg.det(A)
    S = V * A @ A.T / 12
    I_ex = rho * (np.trace(S) * np.eye(3) - S)
    assert body.mass == pytest.approx(rho * V, rel=1e-12)
    assert np.abs(body.inertia0 - I_ex).max() <= 1e-12 * np.abs(I_ex).max()
    assert np.allclose(body.center0, [0.3, -0.2, 1.0], rtol=0, atol=1e-14)
    Cv, Vv = voussoir_corners()
    q = RigidBody3D(Cv, rho=rho)
    t = RigidBody3D(mesh_hexahedron(Cv, size=0.15, cell="tetrahedron", structured=False), rho=rho)
    assert q.mass == pytest.approx(rho * Vv, rel=1e-12) and t.mass == pytest.approx(rho * Vv, rel=1e-12)
    assert np.allclose(q.center0, t.center0, rtol=0, atol=1e-13)
    assert np.abs(q.inertia0 - t.inertia0).max() <= 1e-12 * np.abs(q.inertia0).max()
    Vs, c, S = solid_properties(mesh_hexahedron(Cv, divisions=(2, 2, 2)))
    assert Vs == pytest.approx(Vv, rel=1e-12) and np.allclose(c, q.center0, rtol=0, atol=1e-13)


def test_rigid_drivers_forces_and_W():
    body = RigidBody3D.box(1.0, 0.5, 0.2, rho=2000.0, drivers={"z": Driver("velocity", 0.1), "rx": ("velocity", 0)},
                           forces={"x": 5.0})
    assert np.array_equal(body.driven, [False, False, True, True, False, False])
    phi = np.array([0.1, 0.2, -0.3])
    body.rotate(phi)
    Rt = rotation3d(phi)
    assert np.allclose(Rt, rotation3d(phi / np.linalg.norm(phi), np.linalg.norm(phi)), rtol=0, atol=1e-15)
    assert np.allclose(Rt @ Rt.T, np.eye(3), atol=1e-15) and np.allclose(Rt @ phi, phi, atol=1e-15)
    assert np.allclose(rotation3d([0, 0, 2.0], np.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    assert np.allclose(body.orientation, Rt) and np.allclose(body.q[3:], phi)
    I = body.inertia
    assert np.allclose(I, Rt @ body.inertia0 @ Rt.T) and np.allclose(np.linalg.eigvalsh(I),
                                                                     np.linalg.eigvalsh(body.inertia0))
    W = body.W
    free = ~body.driven
    assert np.all(W[body.driven] == 0) and np.all(W[:, body.driven] == 0)
    assert np.allclose(W[np.ix_(free, free)] @ body.mass_matrix[np.ix_(free, free)], np.eye(4), atol=1e-12)
    f = body.applied_force(0.0, np.array([0, 0, -9.81]))
    assert np.allclose(f, [5.0, 0, -9.81 * body.mass, 0, 0, 0])
    assert np.allclose(body.current_points() - body.center, body.points_rel @ Rt.T)
    body.set_driver("z", None)
    assert not body.driven[2]
    with pytest.raises(InputError, match="driven dof cannot also carry a force"):
        RigidBody3D.box(1, 1, 1, rho=1.0, drivers={"x": ("velocity", 0)}, forces={"x": 1.0})
    with pytest.raises(InputError, match="give rho"):
        RigidBody3D.box(1, 1, 1)
    fixed = RigidBody3D.box(1, 1, 1, drivers={k: ("velocity", 0.0) for k in ("x", "y", "z", "rx", "ry", "rz")})
    assert fixed.mass == 0.0 and np.all(fixed.W == 0)
    with pytest.raises(InputError, match="triangle inequality"):
        RigidBody3D.box(1, 1, 1, mass=1.0, inertia=(1.0, 1.0, 3.0))
    with pytest.raises(InputError, match="dof 'w'"):
        RigidBody3D.box(1, 1, 1, rho=1.0, forces={"w": 1.0})


def test_load_geo3d_tetrahedra_and_hexahedra(tmp_path):
    p = tmp_path / "box.geo"
    p.write_text('SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 1, 0.5, 0.3};\n'
                 'Physical Surface("xmin") = {1};\nPhysical Volume("block") = {1};\n')
    from fem_blocks.meshing import load_geo3d
    m = load_geo3d(str(p), size=0.2)
    assert m.cell_type == "tetrahedron" and m.volume() == pytest.approx(0.15, rel=1e-12)
    assert flux_volume(m) == pytest.approx(0.15, rel=1e-12)
    xmin = m.face_tags == m.tag_names["xmin"]
    assert np.allclose(face_normals(m)[xmin], [-1, 0, 0]) and m.face_areas()[xmin].sum() == pytest.approx(0.15)
    assert m.tag_names["untagged"] == -1 and np.count_nonzero(m.face_tags == -1) == len(xmin) - xmin.sum()
    h = tmp_path / "hex.geo"
    h.write_text('SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 1, 0.5, 0.3};\n'
                 'Transfinite Curve {:} = 3;\nTransfinite Surface {:};\nRecombine Surface {:};\n'
                 'Transfinite Volume {1};\nRecombine Volume {1};\nPhysical Volume("block") = {1};\n')
    m = load_geo3d(str(h), cell="hexahedron")
    assert m.cells.shape == (8, 8) and m.volume() == pytest.approx(0.15, rel=1e-12)
    with pytest.raises(InputError, match="produces hexahedron elements"):
        load_geo3d(str(h), cell="tetrahedron")


# ----------------------------------------------------------------------------- numpy reference assembly
def shuffled3(m, seed):
    """Same geometry, random node numbering and cell order (cell node order kept: orientation unchanged)."""
    rng = np.random.default_rng(seed)
    perm = rng.permutation(m.n_nodes)  # new index of old node i
    P = np.empty_like(m.points)
    P[perm] = m.points
    C = perm[m.cells][rng.permutation(len(m.cells))]
    return BlockMesh3D.from_cells(P, C, m.cell_type, "shuffled")


def reference_operators_3d(m, E, nu, rho):
    """Element-by-element numpy assembly, dofs 3*node + c: tetrahedra exact (constant B, consistent mass
    rho V/20 (1 + delta_ab)); hexahedra K with 2x2x2 Gauss, M with 3x3x3 Gauss."""
    from fem_blocks.fem_backend import elasticity_matrix_3d
    from fem_blocks.meshing import gauss_hex, hex_shape_functions, hex_shape_gradients
    D = elasticity_matrix_3d(E, nu)
    n = m.n_nodes
    K = np.zeros((3 * n, 3 * n))
    M = np.zeros((3 * n, 3 * n))
    Xk, Wk = gauss_hex(2)
    Xm, Wm = gauss_hex(3)
    for cell in m.cells:
        X = m.points[cell]
        nv = len(cell)
        dofs = (3 * cell[:, None] + np.arange(3)).ravel()
        if nv == 4:
            dN = np.array([[-1.0, -1, -1], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
            J = X.T @ dN
            V = np.linalg.det(J) / 6
            pts = [(dN, V)]
            me = rho * V / 20 * (np.ones((4, 4)) + np.eye(4))
        else:
            pts = []
            for dNq, w in zip(hex_shape_gradients(Xk), Wk):
                pts.append((dNq, w * np.linalg.det(X.T @ dNq)))
            me = np.zeros((8, 8))
            for Nq, dNq, w in zip(hex_shape_functions(Xm), hex_shape_gradients(Xm), Wm):
                me += rho * w * np.linalg.det(X.T @ dNq) * np.outer(Nq, Nq)
        ke = np.zeros((3 * nv, 3 * nv))
        for dN, w in pts:
            G = dN @ np.linalg.inv(X.T @ dN)
            B = np.zeros((6, 3 * nv))
            for i in range(3):
                B[i, i::3] = G[:, i]
            B[3, 1::3], B[3, 2::3] = G[:, 2], G[:, 1]
            B[4, 0::3], B[4, 2::3] = G[:, 2], G[:, 0]
            B[5, 0::3], B[5, 1::3] = G[:, 1], G[:, 0]
            ke += w * B.T @ D @ B
        K[np.ix_(dofs, dofs)] += ke
        M[np.ix_(dofs, dofs)] += np.kron(me, np.eye(3))
    return K, M


@pytest.mark.parametrize("kind", ["tet", "distorted-hex"])
def test_matches_numpy_assembly_in_node_order(kind):
    """dolfinx K, M on a randomly renumbered mesh equal an element-by-element numpy assembly in the BlockMesh3D
    node order (1e-12): checks the dof permutation, the hexahedron vertex reordering and the quadratures."""
    if kind == "tet":
        base = mesh_hexahedron(warped_corners(), divisions=(2, 2, 1), cell="tetrahedron")
    else:
        base = jittered(mesh_hexahedron(warped_corners(), divisions=(3, 2, 2)), 0.04, seed=4)
    m = shuffled3(base, 7)
    o = assemble_operators_3d(m, E, NU, RHO)
    K, M = reference_operators_3d(m, E, NU, RHO)
    assert np.abs(o.K.toarray() - K).max() <= 1e-12 * np.abs(K).max()
    assert np.abs(o.M_consistent.toarray() - M).max() <= 1e-12 * np.abs(M).max()
    assert np.allclose(o.M_lumped.diagonal(), M.sum(axis=1), rtol=1e-12)
