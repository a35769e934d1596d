"""3D outputs: bodies (hexahedra, tetrahedra, rigid polyhedra) and contact points written as .vtu/.pvd, read
back with meshio and compared with independently computed fields (1e-12); off-screen PNG of a 3D model."""
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

from fem_blocks.bodies import BlockType3D, DeformableBody3D, Material, RigidBody3D, rotation3d
from fem_blocks.builders3d import dome
from fem_blocks.contact.detection_3d import ContactSet
from fem_blocks.errors import InputError
from fem_blocks.laws import BRITTLE, COULOMB, DUGDALE, ELASTIC, FREMOND, MIXED, NSTATE, S_BETA, S_DISS, S_UN, S_UP, S_UT
from fem_blocks.meshing import mesh_box, mesh_hexahedron
from fem_blocks.contact.result import ContactResult
from fem_blocks.output.contacts import ContactsWriter
from fem_blocks.output.figures import write_blocks_3d
from fem_blocks.output.paraview import BodiesWriter3D
from fem_blocks.output.plots import plot_polygons_3d


@pytest.fixture(scope="module")
def model():
    rng = np.random.default_rng(3)
    mat = Material(E=1e10, nu=0.2, rho=2000.0)
    L = dome(n_courses=2, blocks_per_course=6, top_elevation=0.8, joint=0.02)
    hexa = BlockType3D(mesh_hexahedron(L.prototypes[L.blocks[0].key], divisions=(2, 1, 2)), mat)
    tet = BlockType3D(mesh_box(0.4, 0.2, 0.1, divisions=(2, 1, 1), cell="tetrahedron"), mat)
    bodies = [DeformableBody3D(hexa, b.position, b.R) for b in L.blocks[:3]]
    bodies += [DeformableBody3D(tet, (3.0, 0.0, 0.0), rotation3d([0.3, -0.2, 0.9])),
               DeformableBody3D(tet, (3.0, 1.0, 0.0))]
    bodies.insert(2, RigidBody3D.box(1.0, 0.5, 0.3, origin=(0.0, 0.0, -0.5), rho=2400.0))
    bodies.append(RigidBody3D(L.blocks[4].corners, rho=2400.0))
    for b in bodies:
        b.q[:] = 1e-4 * rng.standard_normal(b.q.shape)
        b.u[:] = 1e-2 * rng.standard_normal(b.u.shape)
    for b in bodies:
        if b.kind == 1:
            b.rotate(1e-3 * rng.standard_normal(3))
    return bodies


def _sym(s):
    """Voigt (sxx, syy, szz, syz, sxz, sxy) -> 3x3."""
    return np.array([[s[0], s[5], s[4]], [s[5], s[1], s[3]], [s[4], s[3], s[2]]])


def test_bodies_vtu_round_trip(model, tmp_path):
    w = BodiesWriter3D(model, str(tmp_path / "pv"))
    names = [w.write(0.0), None]
    for b in model:
        b.q *= 2.0
    names[1] = w.write(0.5)
    root = ET.parse(tmp_path / "pv" / "blocks.pvd").getroot()
    ds = root.findall(".//DataSet")
    assert [(float(d.get("timestep")), d.get("file")) for d in ds] == [(0.0, names[0]), (0.5, names[1])]
    m = meshio.read(tmp_path / "pv" / names[1])
    # independent expectations, body by body in the writer's point order
    X, D, V, cells, sig, vm, ids = [], [], [], {}, {}, {}, {}
    off = 0
    for i, b in enumerate(model):
        if b.kind == 0:
            P = b.type.mesh.points
            X.append(P @ b.R.T + b.position)
            D.append(b.q.reshape(-1, 3) @ b.R.T)
            V.append(b.u.reshape(-1, 3) @ b.R.T)
            name = {"hexahedron": "hexahedron", "tetrahedron": "tetra"}[b.type.mesh.cell_type]
            s_type = (b.type.stress_operator @ b.q).reshape(-1, 6)
            S = []
            for s in s_type:
                T = b.R @ _sym(s) @ b.R.T
                S.append([T[0, 0], T[1, 1], T[2, 2], T[1, 2], T[0, 2], T[0, 1]])
            S = np.array(S)
            ev = np.linalg.eigvalsh(np.array([_sym(s) for s in S]))  # von Mises from principal stresses
            vmi = np.sqrt(0.5 * ((ev[:, 0] - ev[:, 1]) ** 2 + (ev[:, 1] - ev[:, 2]) ** 2 + (ev[:, 2] - ev[:, 0]) ** 2))
            cells.setdefault(name, []).append(b.type.mesh.cells + off)
            sig.setdefault(name, []).append(S)
            vm.setdefault(name, []).append(vmi)
            ids.setdefault(name, []).append(np.full(len(S), i))
        else:
            ref = b.center0 + b.points_rel
            cur = b.center0 + b.q[:3] + b.points_rel @ b.orientation.T
            X.append(ref)
            D.append(cur - ref)
            V.append(b.u[:3] + np.cross(b.u[3:], cur - (b.center0 + b.q[:3])))
            cells.setdefault("quad", []).append(b.boundary_faces + off)
            sig.setdefault("quad", []).append(np.zeros((6, 6)))
            vm.setdefault("quad", []).append(np.zeros(6))
            ids.setdefault("quad", []).append(np.full(6, i))
        off += len(X[-1])
    X, D, V = np.concatenate(X), np.concatenate(D), np.concatenate(V)
    assert np.abs(m.points - X).max() < 1e-12
    assert np.abs(m.point_data["displacement"] - D).max() < 1e-12 * max(1.0, np.abs(D).max())
    assert np.abs(m.point_data["velocity"] - V).max() < 1e-12
    order = [c.type for c in m.cells]
    assert order == ["hexahedron", "tetra", "quad"]
    for k, c in enumerate(m.cells):
        assert np.array_equal(c.data, np.concatenate(cells[c.type]))
        smax = np.abs(np.concatenate(sig["hexahedron"])).max()
        assert np.abs(m.cell_data["stress"][k] - np.concatenate(sig[c.type])).max() < 1e-12 * smax
        assert np.abs(m.cell_data["von_mises"][k] - np.concatenate(vm[c.type])).max() < 1e-9 * smax
        assert np.array_equal(m.cell_data["body_id"][k].ravel(), np.concatenate(ids[c.type]))
        assert np.array_equal(m.cell_data["body_kind"][k].ravel(), (c.type == "quad") * np.ones(len(c.data)))
    # the stress is not trivially zero, and a rotated type really is rotated (stress differs from the type frame)
    assert smax > 1e3
    # resume: keep frame 0 only, then continue
    w2 = BodiesWriter3D(model, str(tmp_path / "pv"), append=True, keep_until_time=0.1)
    assert w2.frame == 1 and not (tmp_path / "pv" / names[1]).exists()


def _contact_set(rng, nc):
    n = rng.standard_normal((nc, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t = np.cross(n, [0.3, 0.5, 0.8])
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    s = np.cross(n, t)
    i4 = rng.integers(0, 9, (nc, 4))
    w4 = rng.random((nc, 4))
    return ContactSet(rng.integers(0, 5, nc), rng.integers(0, 5, nc), i4, w4, i4, w4, rng.random((nc, 3)), n, t, s,
                        1e-3 * rng.standard_normal(nc), np.full(nc, 0.03), rng.random(nc), rng.integers(0, 3, nc),
                        rng.integers(0, 9, nc), rng.integers(0, 9, nc), rng.random((nc, 2)), np.arange(nc))


def test_contacts3d_vtu_round_trip(tmp_path):
    rng = np.random.default_rng(7)
    nc = 40
    cs = _contact_set(rng, nc)
    r = rng.standard_normal((nc, 3)) * 1e3
    law = rng.integers(0, 5, nc)
    law[:5] = MIXED
    state = rng.random((nc, NSTATE))
    status = rng.integers(0, 3, nc)
    w = ContactsWriter(str(tmp_path), 3)
    f = w.write(1.5, ContactResult(3, {}, cs=cs, r=r, law=law, state=state, status=status))
    m = meshio.read(tmp_path / f)
    pd = m.point_data
    assert np.abs(m.points - cs.point).max() < 1e-15
    F = np.array([r[k, 0] * cs.n[k] + r[k, 1] * cs.t[k] + r[k, 2] * cs.s[k] for k in range(nc)])
    assert np.abs(pd["reaction"] - F).max() < 1e-12 * np.abs(F).max()
    # the local frame is orthonormal, so |reaction| = |r|
    assert np.allclose(np.linalg.norm(pd["reaction"], axis=1), np.linalg.norm(r, axis=1), rtol=1e-12, atol=0)
    assert np.array_equal(pd["r_local"], r) and np.array_equal(pd["r_N"], r[:, 0])
    assert np.abs(pd["r_T"] - np.sqrt(r[:, 1] ** 2 + r[:, 2] ** 2)).max() < 1e-12 * np.abs(r).max()
    for k, v in (("normal", cs.n), ("t", cs.t), ("s", cs.s), ("gap", cs.gap - cs.g0), ("area", cs.area)):
        assert np.array_equal(pd[k], v), k
    assert np.array_equal(pd["status"], status) and np.array_equal(pd["interface"], cs.interface)
    # damage per law as docs/laws.md defines it, contact by contact: 0 for dry (coulomb) and elastic joints, 1 - β
    # (adhesion intensity) for brittle, Dugdale and Frémond–Cangémi joints, the damage variable D for mixed-mode
    by_law = {COULOMB: lambda st: 0.0, ELASTIC: lambda st: 0.0, BRITTLE: lambda st: 1.0 - st[S_BETA],
              DUGDALE: lambda st: 1.0 - st[S_BETA], FREMOND: lambda st: 1.0 - st[S_BETA], MIXED: lambda st: st[S_BETA]}
    dmg = np.array([by_law[int(law[k])](state[k]) for k in range(nc)])
    assert np.array_equal(pd["damage"], dmg) and np.array_equal(pd["law"], law)
    for k, c in (("opening", S_UN), ("slip", S_UT), ("dissipated", S_DISS), ("crushing", S_UP)):
        assert np.array_equal(pd[k], state[:, c]), k
    assert len(m.cells) == 1 and m.cells[0].type == "vertex" and np.array_equal(m.cells[0].data.ravel(), np.arange(nc))
    # an empty contact set still gives a valid frame (meshio 5.0 cannot read an empty grid: parse the XML)
    f0 = w.write(2.0, ContactResult(3, {}, cs=cs.subset(np.zeros(0, dtype=int)), r=np.zeros((0, 3))))
    piece = ET.parse(tmp_path / f0).getroot().find("UnstructuredGrid/Piece")
    assert piece.get("NumberOfPoints") == "0" and w.series.times == [1.5, 2.0]


def test_png_of_3d_model(tmp_path):
    """The thesis dome on its piers as rigid bodies, the lowest course moved down: a PNG of exactly the
    requested size, not blank (coloured, many colours, the colourbar's extreme colours present)."""
    import matplotlib.image as mpimg
    L = dome(piers=4)
    bodies = [RigidBody3D(b.corners, rho=2500.0) for b in L.blocks] + [RigidBody3D(r.corners, rho=2500.0)
                                                                      for r in L.rigid]
    for i, b in enumerate(bodies[:22]):
        b.q[2] = -1e-3 * (1 + i % 3)
    f = write_blocks_3d(str(tmp_path / "dome.png"), bodies, title="dome", size=(900, 700), amplification=30,
                        backend="matplotlib")
    img = mpimg.imread(f)
    assert img.shape[:2] == (700, 900)
    rgb = img[..., :3]
    nonwhite = np.any(rgb < 0.97, axis=-1).mean()
    assert nonwhite > 0.15
    colours = np.unique((rgb * 255).astype(np.uint8).reshape(-1, 3), axis=0)
    assert len(colours) > 200
    # viridis extremes (dark purple 0.267, 0.005, 0.329 / yellow 0.993, 0.906, 0.144) in the colourbar
    assert np.any(np.all(np.abs(rgb - [0.267, 0.005, 0.329]) < 0.03, axis=-1))
    assert np.any(np.all(np.abs(rgb - [0.993, 0.906, 0.144]) < 0.03, axis=-1))
    # per-body values (e.g. damage) and validation
    f2 = write_blocks_3d(str(tmp_path / "dmg.png"), bodies, body_values=np.linspace(0, 1, len(bodies)),
                         value_label="damage", size=(400, 300), backend="matplotlib")
    assert mpimg.imread(f2).shape[:2] == (300, 400)
    with pytest.raises(InputError, match="body_values"):
        write_blocks_3d(str(tmp_path / "x.png"), bodies, body_values=[0.0, 1.0])
    with pytest.raises(InputError, match="size"):
        plot_polygons_3d(str(tmp_path / "x.png"), [np.eye(3)], size=(10, 5))
    with pytest.raises(InputError, match=r"polygons\[0\]"):
        plot_polygons_3d(str(tmp_path / "x.png"), [np.zeros((2, 3))])


def test_png_3d_pyvista_backend(tmp_path):
    """The optional pyvista/VTK renderer (`make pyvista`): exact size, not blank, the dome's faces coloured with
    viridis (its two extremes present), the lowered blocks darker; skipped when pyvista is not installed."""
    pytest.importorskip("pyvista")
    import matplotlib.image as mpimg
    from fem_blocks.builders3d import dome
    L = dome(piers=4)
    bodies = [RigidBody3D(b.corners, rho=2500.0) for b in L.blocks]
    for i, b in enumerate(bodies[:22]):
        b.q[2] = -1e-3 * (1 + i % 3)
    f = write_blocks_3d(str(tmp_path / "dome_vtk.png"), bodies, title="dome", size=(640, 480), amplification=30,
                        backend="pyvista")
    rgb = mpimg.imread(f)[..., :3]
    assert rgb.shape[:2] == (480, 640)
    assert np.any(rgb < 0.97, axis=-1).mean() > 0.10
    assert np.any(np.all(np.abs(rgb - [0.267, 0.005, 0.329]) < 0.08, axis=-1))
    assert np.any(np.all(np.abs(rgb - [0.993, 0.906, 0.144]) < 0.08, axis=-1))
    with pytest.raises(InputError, match="backend"):
        write_blocks_3d(str(tmp_path / "x.png"), bodies, backend="vtk")
