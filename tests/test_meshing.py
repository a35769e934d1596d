"""meshing: gmsh -> BlockMesh arrays (counts, boundary, orientation, tags), .geo/.msh loading, validation."""
import os

import numpy as np
import pytest

from fem_blocks.errors import InputError
from fem_blocks.meshing import BlockMesh, load_geo, load_msh, mesh_polygon, mesh_rectangle, validate

from _paths import ROOT  # noqa: E402


def edge_lengths(m, edges=None):
    e = m.boundary_edges if edges is None else edges
    return np.linalg.norm(m.points[e[:, 1]] - m.points[e[:, 0]], axis=1)


def boundary_signed_area(m):
    """Green: A = 1/2 sum (x_a y_b - x_b y_a) over oriented boundary edges (body on the left -> +area)."""
    a, b = m.points[m.boundary_edges[:, 0]], m.points[m.boundary_edges[:, 1]]
    return 0.5 * np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1])


def check_body_on_left(m):
    """Every boundary edge has the rest of its (unique) cell on its left."""
    C = m.cells
    for a, b in m.boundary_edges:
        rows = np.flatnonzero(np.any(C == a, axis=1) & np.any(C == b, axis=1))
        assert rows.size == 1
        others = [v for v in C[rows[0]] if v not in (a, b)]
        d = m.points[b] - m.points[a]
        for v in others:
            r = m.points[v] - m.points[a]
            assert d[0] * r[1] - d[1] * r[0] > 0


def check_arrays(m):
    assert m.points.dtype == np.float64 and m.points.ndim == 2 and m.points.shape[1] == 2
    assert m.cells.dtype == np.int64 and m.boundary_edges.dtype == np.int64 and m.edge_tags.dtype == np.int64
    assert np.all(m.cell_areas() > 0)  # counter-clockwise cells
    validate(m, "test")


@pytest.mark.parametrize("cell", ["quad", "triangle"])
@pytest.mark.parametrize("lx, ly, size, nx, ny", [(0.25, 0.06, 0.01, 25, 6), (0.25, 0.06, 0.02, 12, 3),
                                                  (0.3, 0.1, 1.0, 1, 1)])
def test_rectangle_counts_boundary_tags(cell, lx, ly, size, nx, ny):
    m = mesh_rectangle(lx, ly, size, cell=cell)
    check_arrays(m)
    assert m.cell_type == cell
    assert m.cells.shape == ((nx * ny, 4) if cell == "quad" else (2 * nx * ny, 3))
    assert m.n_nodes == (nx + 1) * (ny + 1)
    assert len(m.boundary_edges) == 2 * (nx + ny)
    assert len(m.boundary_nodes()) == 2 * (nx + ny)
    assert edge_lengths(m).sum() == pytest.approx(2 * (lx + ly), rel=1e-12)
    assert m.area() == pytest.approx(lx * ly, rel=1e-12)
    assert boundary_signed_area(m) == pytest.approx(lx * ly, rel=1e-12)  # CCW outer loop
    check_body_on_left(m)
    assert np.allclose(m.bbox(), (0, 0, lx, ly), rtol=0, atol=1e-14)
    assert set(m.tag_names) == {"bottom", "right", "top", "left"} and 0 not in m.edge_tags
    tol = 1e-12
    for name, coord, value, length in (("bottom", 1, 0.0, lx), ("top", 1, ly, lx),
                                       ("left", 0, 0.0, ly), ("right", 0, lx, ly)):
        e = m.boundary_edges[m.edge_tags == m.tag_names[name]]
        assert len(e) == (nx if length == lx else ny)
        assert np.all(np.abs(m.points[e, coord] - value) < tol)
        assert edge_lengths(m, e).sum() == pytest.approx(length, rel=1e-12)


def test_boundary_nodes_sorted_unique_and_translation():
    m = mesh_rectangle(0.4, 0.2, 0.05, "triangle")
    bn = m.boundary_nodes()
    assert bn.dtype == np.int64 and np.all(np.diff(bn) > 0)
    assert np.array_equal(bn, np.unique(m.boundary_edges))
    t = m.translated(12.3, -4.5)
    assert np.array_equal(t.cells, m.cells) and np.array_equal(t.boundary_edges, m.boundary_edges)
    assert np.allclose(t.points - m.points, [12.3, -4.5], rtol=0, atol=1e-14)
    assert t.area() == pytest.approx(m.area(), rel=1e-12)
    assert np.allclose(t.bbox(), (12.3, -4.5, 12.7, -4.3), rtol=0, atol=1e-13)
    assert np.allclose(m.points[:, 0].min(), 0.0, atol=1e-15)  # translated() does not modify the original


def test_repeated_calls_are_deterministic_and_leave_no_model():
    import gmsh
    ref = mesh_rectangle(0.25, 0.06, 0.01, "quad")
    for _ in range(10):
        m = mesh_rectangle(0.25, 0.06, 0.01, "quad")
        assert np.array_equal(m.points, ref.points) and np.array_equal(m.cells, ref.cells)
        assert np.array_equal(m.boundary_edges, ref.boundary_edges)
        p = mesh_polygon([[0, 0], [1, 0], [0.5, 0.8]], 0.2)
    assert gmsh.model.getEntities() == []  # model cleared after use
    q = mesh_polygon([[0, 0], [1, 0], [0.5, 0.8]], 0.2)
    assert np.array_equal(p.points, q.points) and np.array_equal(p.cells, q.cells)


def test_gmsh_finalized_elsewhere_is_reinitialised():
    import gmsh
    mesh_rectangle(1, 1, 0.5)
    gmsh.finalize()
    m = mesh_rectangle(1, 1, 0.5)
    assert m.cells.shape == (4, 4)


@pytest.mark.parametrize("cell", ["triangle", "quad"])
@pytest.mark.parametrize("reverse", [False, True])
def test_polygon_orientation_and_sides(cell, reverse):
    V = np.array([[0.0, 0.0], [1.0, 0.0], [1.2, 0.8], [0.5, 1.3], [0.1, 1.0]])
    area = 0.5 * np.sum(V[:, 0] * np.roll(V[:, 1], -1) - np.roll(V[:, 0], -1) * V[:, 1])
    m = mesh_polygon(V[::-1] if reverse else V, 0.15, cell=cell)
    check_arrays(m)
    assert m.cell_type == cell
    assert m.area() == pytest.approx(area, rel=1e-12)
    assert boundary_signed_area(m) == pytest.approx(area, rel=1e-12)
    check_body_on_left(m)
    W = V[::-1] if reverse else V  # input order; the CCW polygon is V (side i from vertex i to i+1)
    if reverse:
        W = W[::-1]
    assert set(m.tag_names) == {f"side{i}" for i in range(5)}
    for i in range(5):
        a, b = W[i], W[(i + 1) % 5]
        e = m.boundary_edges[m.edge_tags == m.tag_names[f"side{i}"]]
        assert edge_lengths(m, e).sum() == pytest.approx(np.linalg.norm(b - a), rel=1e-12)
        d = (b - a) / np.linalg.norm(b - a)
        for k in range(2):  # on the side's line, and oriented like it
            r = m.points[e[:, k]] - a
            assert np.all(np.abs(r[:, 0] * d[1] - r[:, 1] * d[0]) < 1e-12)
        assert np.all((m.points[e[:, 1]] - m.points[e[:, 0]]) @ d > 0)


def test_polygon_rejects_bad_input():
    with pytest.raises(InputError, match="sides 0 and 2 cross"):
        mesh_polygon([[0, 0], [2, 2], [2, 0], [0, 1]], 0.2)  # bow tie
    with pytest.raises(InputError, match="zero area"):
        mesh_polygon([[0, 0], [1, 0], [2, 0]], 0.2)
    with pytest.raises(InputError, match="mesh_size"):
        mesh_polygon([[0, 0], [1, 0], [0, 1]], -1.0)
    with pytest.raises(InputError, match="cell"):
        mesh_rectangle(1, 1, 0.5, cell="hex")
    with pytest.raises(InputError, match="lx"):
        mesh_rectangle(0.0, 1, 0.5)


# ----------------------------------------------------------------------------- .geo / .msh
def test_brick_geo_structured_quads():
    m = load_geo(os.path.join(ROOT, "meshes", "brick.geo"))
    check_arrays(m)
    assert m.cell_type == "quad" and m.cells.shape == (25 * 6, 4) and m.n_nodes == 26 * 7
    assert m.area() == pytest.approx(0.015, rel=1e-12)
    for name, length in (("bottom", 0.25), ("right", 0.06), ("top", 0.25), ("left", 0.06)):
        e = m.boundary_edges[m.edge_tags == m.tag_names[name]]
        assert edge_lengths(m, e).sum() == pytest.approx(length, rel=1e-12)
    assert "untagged" not in m.tag_names


def test_voussoir_geo_size_and_quads():
    path = os.path.join(ROOT, "meshes", "voussoir.geo")
    coarse = load_geo(path)
    fine = load_geo(path, size=0.02)
    quads = load_geo(path, size=0.03, cell="quad")
    assert coarse.cell_type == "triangle" and fine.cells.shape[0] > 2 * coarse.cells.shape[0]
    assert quads.cell_type == "quad"
    for m in (coarse, fine, quads):
        check_arrays(m)
        check_body_on_left(m)
        assert set(m.tag_names) == {"joint_lower", "extrados", "joint_upper", "intrados"}
        e = m.boundary_edges[m.edge_tags == m.tag_names["joint_upper"]]
        assert edge_lengths(m, e).sum() == pytest.approx(0.3, rel=1e-12)


HOLED_GEO = """
lc = 0.1;
Point(1) = {0, 0, 0, lc}; Point(2) = {1, 0, 0, lc}; Point(3) = {1, 1, 0, lc}; Point(4) = {0, 1, 0, lc};
Point(5) = {0.3, 0.3, 0, lc}; Point(6) = {0.6, 0.3, 0, lc}; Point(7) = {0.6, 0.6, 0, lc}; Point(8) = {0.3, 0.6, 0, lc};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 4}; Line(4) = {4, 1};
Line(5) = {5, 6}; Line(6) = {6, 7}; Line(7) = {7, 8}; Line(8) = {8, 5};
Curve Loop(1) = {1, 2, 3, 4}; Curve Loop(2) = {5, 6, 7, 8};
Plane Surface(1) = {1, 2};
Physical Curve("hole") = {5, 6, 7, 8};
Physical Curve("base") = {1};
Physical Surface("s") = {1};
"""


def test_geo_with_hole_orientation_and_untagged(tmp_path):
    p = tmp_path / "holed.geo"
    p.write_text(HOLED_GEO)
    m = load_geo(str(p))
    check_arrays(m)
    assert m.area() == pytest.approx(1 - 0.09, rel=1e-12)
    assert boundary_signed_area(m) == pytest.approx(1 - 0.09, rel=1e-12)  # outer CCW, hole CW
    check_body_on_left(m)
    assert m.tag_names == {"hole": m.tag_names["hole"], "base": m.tag_names["base"], "untagged": 0}
    hole = m.boundary_edges[m.edge_tags == m.tag_names["hole"]]
    assert edge_lengths(m, hole).sum() == pytest.approx(1.2, rel=1e-12)
    a, b = m.points[hole[:, 0]], m.points[hole[:, 1]]
    assert 0.5 * np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]) == pytest.approx(-0.09, rel=1e-12)  # hole CW
    assert edge_lengths(m, m.boundary_edges[m.edge_tags == 0]).sum() == pytest.approx(3.0, rel=1e-12)


def test_geo_options_do_not_leak(tmp_path):
    """A .geo that asks for second-order elements is rejected, and the next mesh is linear again."""
    p = tmp_path / "order2.geo"
    p.write_text(HOLED_GEO + "Mesh.ElementOrder = 2;\n")
    with pytest.raises(InputError, match=r"order2\.geo.*6-node triangle"):
        load_geo(str(p))
    m = mesh_rectangle(1, 1, 0.5, "triangle")
    assert m.cells.shape == (8, 3) and m.n_nodes == 9


def _msh(nodes, elements, physical=((1, 1, "bottom"), (2, 2, "block"))):
    """ASCII MSH 2.2 text; elements are (type, physical tag, node ids...)."""
    lines = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$PhysicalNames", str(len(physical))]
    lines += [f'{d} {t} "{n}"' for d, t, n in physical]
    lines += ["$EndPhysicalNames", "$Nodes", str(len(nodes))]
    lines += [f"{i} {x} {y} 0" for i, (x, y) in nodes.items()]
    lines += ["$EndNodes", "$Elements", str(len(elements))]
    lines += [f"{k + 1} {e[0]} 2 {e[1]} {e[1]} " + " ".join(map(str, e[2:])) for k, e in enumerate(elements)]
    lines += ["$EndElements", ""]
    return "\n".join(lines)


NODES = {1: (0, 0), 2: (1, 0), 3: (2, 0), 4: (0, 1), 5: (1, 1), 6: (2, 1), 7: (5, 5)}  # node 7 unused


def test_load_msh_quads_tags_and_unused_node_removed(tmp_path):
    p = tmp_path / "two.msh"
    p.write_text(_msh(NODES, [(1, 1, 1, 2), (1, 1, 2, 3), (3, 2, 1, 2, 5, 4), (3, 2, 2, 3, 6, 5)]))
    m = load_msh(str(p))
    check_arrays(m)
    assert m.cell_type == "quad" and m.cells.shape == (2, 4) and m.n_nodes == 6
    assert np.allclose(m.points, [NODES[i] for i in range(1, 7)])  # gmsh node order, unused node dropped
    assert m.tag_names == {"bottom": 1, "untagged": 0}
    bottom = m.boundary_edges[m.edge_tags == 1]
    assert np.array_equal(np.sort(bottom, axis=0), [[0, 1], [1, 2]])
    assert len(m.boundary_edges) == 6 and m.area() == pytest.approx(2.0, rel=1e-14)


def test_load_msh_clockwise_input_is_reoriented(tmp_path):
    p = tmp_path / "cw.msh"
    p.write_text(_msh(NODES, [(2, 2, 1, 4, 5), (2, 2, 1, 5, 2)]))
    m = load_msh(str(p))
    check_arrays(m)
    assert m.area() == pytest.approx(1.0, rel=1e-14)


@pytest.mark.parametrize("elements, match", [
    ([(9, 2, 1, 3, 6, 2, 5, 4)], r"6-node triangle \(gmsh type 9\)"),
    ([(2, 2, 1, 2, 5), (3, 2, 2, 3, 6, 5)], r"mixed element types 3-node triangle .*4-node quadrangle"),
    ([(1, 1, 1, 2)], "no 2D element"),
])
def test_load_msh_rejects_unsupported_elements(tmp_path, elements, match):
    p = tmp_path / "bad.msh"
    p.write_text(_msh(NODES, elements))
    with pytest.raises(InputError, match=match) as e:
        load_msh(str(p))
    assert str(p) in str(e.value)


def test_missing_or_unreadable_files(tmp_path):
    for f in (load_msh, load_geo):
        with pytest.raises(InputError, match="nope.msh: .*not found"):
            f(str(tmp_path / "nope.msh"))
    p = tmp_path / "garbage.msh"
    p.write_text("$MeshFormat\nthis is not a mesh\n")
    with pytest.raises(InputError, match="garbage.msh"):
        load_msh(str(p))


# ----------------------------------------------------------------------------- validate()
def tri_strip():
    """4 CCW triangles over [0,2]x[0,1]: nodes 0..5."""
    P = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1]], dtype=float)
    C = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]], dtype=np.int64)
    return P, C


def quad_strip():
    P = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1]], dtype=float)
    C = np.array([[0, 1, 4, 3], [1, 2, 5, 4]], dtype=np.int64)
    return P, C


def _raw(P, C, cell_type=None):
    """BlockMesh without validation (boundary computed as for a valid mesh when possible)."""
    cell_type = cell_type or ("triangle" if C.shape[1] == 3 else "quad")
    try:
        return BlockMesh.from_cells(P, C, cell_type, "raw")
    except InputError:
        return BlockMesh(P, C, cell_type, np.zeros((0, 2), np.int64), np.zeros(0, np.int64), {}, "raw")


def test_validate_accepts_good_meshes():
    for P, C in (tri_strip(), quad_strip()):
        validate(BlockMesh.from_cells(P, C), "ok")


def expect(mesh, *words):
    with pytest.raises(InputError) as e:
        validate(mesh, "blk.msh")
    msg = str(e.value)
    assert msg.startswith("blk.msh:"), msg
    for w in words:
        assert w in msg, msg
    return msg


def test_validate_inverted_and_degenerate_elements():
    P, C = tri_strip()
    C2 = C.copy()
    C2[2] = C2[2, ::-1]
    expect(_raw(P, C2), "element 2", "inverted")
    P3 = P.copy()
    P3[5] = [2.0, 1e-14]  # element 2 = (1, 2, 5) almost flat
    expect(_raw(P3, C), "element 2", "degenerate")
    Pq, Cq = quad_strip()
    Cq2 = Cq.copy()
    Cq2[1] = Cq2[1, ::-1]
    expect(_raw(Pq, Cq2), "element 1", "inverted")


def test_validate_nonconvex_quad():
    P, C = quad_strip()
    P = P.copy()
    P[5] = [1.2, 0.4]  # quad 1 = (1, 2, 5, 4): reflex angle at node 5, positive area
    m = _raw(P, C)
    assert m.cell_areas()[1] > 0
    expect(m, "quadrangle 1", "not convex")


def test_validate_duplicate_and_unused_nodes():
    P, C = tri_strip()
    P2 = np.vstack([P, [[1.0, 1.0 + 1e-14]]])  # node 6 coincides with node 4
    C2 = C.copy()
    C2[1] = [0, 6, 3]  # element 1 uses the duplicate
    expect(_raw(P2, C2), "nodes 4 and 6", "duplicate")
    P3 = np.vstack([P, [[5.0, 5.0]]])
    expect(_raw(P3, C), "node 6", "not used")


def test_validate_non_manifold():
    P, C = tri_strip()
    P2 = np.vstack([P, [[0.2, 0.6]]])  # a third triangle on edge (0, 4): (0, 4, 6) overlaps element 1
    C2 = np.vstack([C, [[0, 4, 6]]])
    m = BlockMesh(P2, C2, "triangle", np.zeros((0, 2), np.int64), np.zeros(0, np.int64), {}, "raw")
    expect(m, "edge between nodes 0 and 4", "non-manifold", "3 elements")
    # bow tie: two triangles touching at node 2 only
    P = np.array([[0, 0], [1, 0], [1, 1], [2, 1], [2, 2]], dtype=float)
    C = np.array([[0, 1, 2], [2, 3, 4]], dtype=np.int64)
    expect(_raw(P, C), "node 2", "non-manifold boundary")


def test_validate_disconnected():
    P = np.array([[0, 0], [1, 0], [0, 1], [3, 0], [4, 0], [3, 1]], dtype=float)
    C = np.array([[0, 1, 2], [3, 4, 5]], dtype=np.int64)
    expect(_raw(P, C), "element 1", "disconnected")


def test_validate_nan_shapes_dtypes():
    P, C = tri_strip()
    P2 = P.copy()
    P2[3, 1] = np.nan
    expect(_raw(P2, C), "node 3", "non-finite")
    good = BlockMesh.from_cells(P, C)
    for kw, word in ((dict(points=P.astype(np.float32)), "points"), (dict(points=np.c_[P, P[:, :1]]), "points"),
                     (dict(cells=C.astype(float)), "cells"), (dict(cells=C[:, :2]), "cells"),
                     (dict(cells=C, cell_type="quad"), "cells"), (dict(cell_type="hex"), "cell_type"),
                     (dict(edge_tags=good.edge_tags[:-1]), "edge_tags"),
                     (dict(boundary_edges=good.boundary_edges[:, ::-1].copy()), "boundary_edges")):
        args = dict(points=P, cells=C, cell_type="triangle", boundary_edges=good.boundary_edges,
                    edge_tags=good.edge_tags)
        args.update(kw)
        expect(BlockMesh(**args), word)
    C3 = C.copy()
    C3[0, 2] = 17
    expect(BlockMesh(P, C3, "triangle", good.boundary_edges, good.edge_tags), "element 0", "does not exist")


def test_gmsh_ids_named_in_messages(tmp_path):
    """Errors in a .msh name gmsh's own element tags."""
    p = tmp_path / "flat.msh"
    nodes = dict(NODES)
    nodes[6] = (3, 0)  # quad 2-3-6-5 becomes non-convex (node 6 on the line through 2, 3)
    p.write_text(_msh(nodes, [(1, 1, 1, 2), (3, 2, 1, 2, 5, 4), (3, 2, 2, 3, 6, 5)]))
    with pytest.raises(InputError, match=r"flat\.msh: quadrangle 3 \(gmsh tag\) is not convex"):
        load_msh(str(p))


def test_geo_cell_request_must_match(tmp_path):
    with pytest.raises(InputError, match=r"brick\.geo: the file produces quad elements .*'triangle'"):
        load_geo(os.path.join(ROOT, "meshes", "brick.geo"), cell="triangle")
    with pytest.raises(InputError, match="cell = 'hex'"):
        load_geo(os.path.join(ROOT, "meshes", "brick.geo"), cell="hex")


def test_msh_non_manifold_edge_names_gmsh_node_tags(tmp_path):
    nodes = {11: (0, 0), 12: (1, 0), 13: (0.5, 1), 14: (0.5, -1), 15: (0.5, 0.5)}
    p = tmp_path / "fan.msh"
    p.write_text(_msh(nodes, [(2, 2, 11, 12, 13), (2, 2, 12, 11, 14), (2, 2, 11, 12, 15)]))
    with pytest.raises(InputError, match=r"fan\.msh: non-manifold mesh: edge between nodes 11 \(gmsh tag\) and "
                                         r"12 \(gmsh tag\) is shared by 3 elements"):
        load_msh(str(p))
