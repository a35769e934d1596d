"""Output writers: VTU read back with meshio (bit-exact float64), PVD validity/resume, history CSV exact round trip
and resume, summary JSON, atomic writes, PNG plots, input validation."""
import base64
import datetime
import json
import os
import pathlib
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

from fem_blocks.errors import InputError
from fem_blocks.output import atomic
from fem_blocks.output.history import HistoryWriter, read_history
from fem_blocks.output.plots import plot_crack_pattern, plot_curve
from fem_blocks.output.pvd import PvdSeries
from fem_blocks.output.summary import write_summary
from fem_blocks.output.vtu import write_vtu


def _decode_arrays(path):
    """Independent decoder of our inline-binary VTU: name -> (numpy array, header byte count, payload bytes)."""
    root = ET.parse(path).getroot()
    assert root.get("header_type") == "UInt64" and root.get("byte_order") == "LittleEndian"
    dt = {"Float64": "<f8", "Int64": "<i8", "Int32": "<i4", "UInt8": "u1"}
    out = {}
    for da in root.iter("DataArray"):
        raw = base64.b64decode(da.text.strip())
        nbytes = int(np.frombuffer(raw[:8], "<u8")[0])
        out[da.get("Name")] = (np.frombuffer(raw[8:], dt[da.get("type")]), nbytes, len(raw) - 8)
    return root, out


def _mixed_grid():
    rng = np.random.default_rng(0)
    P = rng.random((7, 2))
    tri = np.array([[0, 1, 2], [2, 3, 0]])
    quad = np.array([[1, 4, 5, 2], [3, 2, 5, 6]])
    return rng, P, tri, quad


def test_vtu_mixed_triangle_quad_round_trip_bit_exact(tmp_path):
    rng, P, tri, quad = _mixed_grid()
    vel = rng.standard_normal((7, 2)) * 1e-7
    stress = rng.standard_normal((4, 3)) * 1e6  # (sxx, syy, sxy) per cell
    ids = np.array([3, -1, 2**40, 7], dtype=np.int64)
    f = tmp_path / "a.vtu"
    assert write_vtu(f, P, [("triangle", tri), ("quad", quad)],
                     point_data={"velocity": vel, "x": P[:, 0]}, cell_data={"stress": stress, "id": ids},
                     field_data={"TimeValue": 0.25}) == f
    m = meshio.read(f)
    assert np.array_equal(m.points[:, :2], P) and np.all(m.points[:, 2] == 0.0)
    assert m.point_data["velocity"].shape == (7, 3)  # padded to a 3-vector for ParaView
    assert np.array_equal(m.point_data["velocity"][:, :2], vel) and np.all(m.point_data["velocity"][:, 2] == 0)
    assert np.array_equal(m.point_data["x"], P[:, 0])
    assert [c.type for c in m.cells] == ["triangle", "quad"]
    assert np.array_equal(m.cells[0].data, tri) and np.array_equal(m.cells[1].data, quad)
    got = np.concatenate(m.cell_data["stress"])
    assert got.shape == (4, 3) and np.array_equal(got, stress)
    got_ids = np.concatenate(m.cell_data["id"]).ravel()
    assert got_ids.dtype == np.int64 and np.array_equal(got_ids, ids)
    assert np.array_equal(np.ravel(m.field_data["TimeValue"]), [0.25])
    # format conformance independent of meshio: byte-count headers, offsets, VTK type codes
    root, arr = _decode_arrays(f)
    for name, (a, nbytes, payload) in arr.items():
        assert nbytes == payload == a.nbytes, name
    assert np.array_equal(arr["offsets"][0], [3, 6, 10, 14])
    assert np.array_equal(arr["types"][0], [5, 5, 9, 9])
    piece = root.find("UnstructuredGrid/Piece")
    assert piece.get("NumberOfPoints") == "7" and piece.get("NumberOfCells") == "4"


def test_vtu_polygon_grid(tmp_path):
    # a unit square split into a triangle and two pentagons (ragged list)
    P = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0], [1, 0.5], [0.5, 0.5]], float)
    polys = [[0, 4, 6], np.array([4, 1, 5, 6, 6][:4]), [6, 5, 2, 3, 0]]
    damage = np.array([0.0, 0.5, 1.0])
    f = tmp_path / "p.vtu"
    write_vtu(f, P, [("polygon", polys)], cell_data={"damage": damage})
    m = meshio.read(f)
    assert all(c.type == "polygon" for c in m.cells)
    got = [list(row) for c in m.cells for row in c.data]
    assert sorted(got) == sorted([list(map(int, p)) for p in polys])
    by_cell = {tuple(row): d for c, dd in zip(m.cells, m.cell_data["damage"]) for row, d in zip(c.data, dd)}
    for p, d in zip(polys, damage):
        assert by_cell[tuple(int(i) for i in p)] == d
    _, arr = _decode_arrays(f)
    assert np.array_equal(arr["types"][0], [7, 7, 7]) and np.array_equal(arr["offsets"][0], [3, 7, 12])


def test_vtu_vertex_cloud_contact_points(tmp_path):
    P = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 1.0]])
    f = tmp_path / "c.vtu"
    status = np.array([0, 1, 2], dtype=np.int64)
    write_vtu(f, P, [("vertex", np.arange(3))],
              point_data={"r_N": np.array([1.0, 2.0, 3.0]), "status": status, "open": np.array([1, 0, 0], bool)},
              cell_data={"status": status})
    m = meshio.read(f)
    assert m.cells[0].type == "vertex" and np.array_equal(m.cells[0].data.ravel(), [0, 1, 2])
    assert np.array_equal(m.point_data["r_N"], [1.0, 2.0, 3.0])
    assert m.point_data["status"].dtype == np.int64 and np.array_equal(m.point_data["status"], status)
    assert np.array_equal(m.point_data["open"], [1, 0, 0])


def test_vtu_3d_tetra_hexahedron(tmp_path):
    P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1],
                  [0.5, 0.5, 2.0]], float)
    hexa = np.arange(8)[None]
    tet = np.array([[4, 5, 6, 8]])
    u = np.arange(27, dtype=float).reshape(9, 3)
    write_vtu(tmp_path / "h.vtu", P, [("hexahedron", hexa), ("tetra", tet)], point_data={"u": u})
    m = meshio.read(tmp_path / "h.vtu")
    assert [c.type for c in m.cells] == ["hexahedron", "tetra"]
    assert np.array_equal(m.points, P) and np.array_equal(m.point_data["u"], u)


def test_vtu_invalid_inputs_name_the_field(tmp_path):
    f = tmp_path / "x.vtu"
    P3 = np.zeros((3, 2))
    with pytest.raises(InputError, match=r"point_data\['velocity'\]: expected 3 rows"):
        write_vtu(f, P3, [("vertex", np.arange(3))], point_data={"velocity": np.zeros((4, 2))})
    with pytest.raises(InputError, match=r"cell_data\['stress'\]: expected 1 rows"):
        write_vtu(f, P3, [("triangle", [[0, 1, 2]])], cell_data={"stress": np.zeros((3, 3))})
    with pytest.raises(InputError, match=r"point_data\['name'\]: expected numeric"):
        write_vtu(f, P3, [("vertex", np.arange(3))], point_data={"name": np.array(["a", "b", "c"])})
    with pytest.raises(InputError, match="unknown cell type 'pyramid'"):
        write_vtu(f, P3, [("pyramid", np.arange(3))])
    with pytest.raises(InputError, match=r"cells\[0\] \('triangle'\).*does not exist"):
        write_vtu(f, P3, [("triangle", np.array([[0, 1, 3]]))])
    # 3 quads given as "triangle" have 12 = 4 x 3 indices: must not be silently reshaped
    with pytest.raises(InputError, match=r"cells\[1\] \('triangle'\): expected connectivity of shape \(m, 3\)"):
        write_vtu(f, np.zeros((8, 2)), [("vertex", [0]), ("triangle", np.zeros((3, 4), int))])
    with pytest.raises(InputError, match="at least 3 nodes"):
        write_vtu(f, P3, [("polygon", [[0, 1]])])
    with pytest.raises(InputError, match="points: expected an"):
        write_vtu(f, np.zeros((3, 4)), [])
    assert not f.exists()  # nothing written on bad input


def test_vtu_failed_write_keeps_previous_frame(tmp_path, monkeypatch):
    f = tmp_path / "a.vtu"
    write_vtu(f, np.zeros((1, 2)), [("vertex", [0])], point_data={"v": [1.0]})
    before = f.read_bytes()

    def boom(src, dst):
        raise OSError("no space left on device")
    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError):
        write_vtu(f, np.ones((1, 2)), [("vertex", [0])], point_data={"v": [2.0]})
    monkeypatch.undo()
    assert f.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["a.vtu"]
    assert meshio.read(f).point_data["v"][0] == 1.0


def _pvd_entries(path):
    return [(float(d.get("timestep")), d.get("file")) for d in ET.parse(path).getroot().iter("DataSet")]


def test_pvd_valid_after_each_add_and_resume_drops_later_frames(tmp_path):
    path = tmp_path / "s.pvd"
    s = PvdSeries(path)
    assert _pvd_entries(path) == []  # a valid empty series before the first frame
    times = [0.1 * k for k in range(5)]
    for k, t in enumerate(times):
        name = f"f{k}.vtu"
        write_vtu(tmp_path / name, np.zeros((1, 2)), [("vertex", [0])])
        s.add(t, name)
        assert _pvd_entries(path) == [(times[j], f"f{j}.vtu") for j in range(k + 1)]  # exact times
    # resume at t = 0.3: the frame stored at 0.1 * 3 = 0.30000000000000004 is the same instant (kept), 0.4 dropped
    r = PvdSeries.open_existing(path, keep_until_time=0.3)
    assert r.files == ["f0.vtu", "f1.vtu", "f2.vtu", "f3.vtu"] and r.times == times[:4]
    assert _pvd_entries(path) == [(times[j], f"f{j}.vtu") for j in range(4)]  # rewritten at once
    assert [(tmp_path / f"f{k}.vtu").exists() for k in range(5)] == [True, True, True, True, False]
    r = PvdSeries.open_existing(path, keep_until_time=0.25)
    assert r.files == ["f0.vtu", "f1.vtu", "f2.vtu"] and not (tmp_path / "f3.vtu").exists()
    r.add(times[3], "g3.vtu")
    assert [e[1] for e in _pvd_entries(path)] == ["f0.vtu", "f1.vtu", "f2.vtu", "g3.vtu"]
    # append=True continues without truncation; open_existing without a time keeps everything
    a = PvdSeries(path, append=True)
    a.add(0.5, "g4.vtu")
    assert len(PvdSeries.open_existing(path).entries) == 5
    # a fresh series (append=False) starts empty
    assert PvdSeries(path).entries == [] and _pvd_entries(path) == []


def test_pvd_resume_never_deletes_shared_or_outside_files(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "mesh.vtu").write_text("x")
    (tmp_path / "precious.vtu").write_text("x")
    s = PvdSeries(out / "s.pvd")
    s.add(0.0, "mesh.vtu")
    s.add(1.0, "mesh.vtu", part=1)
    s.add(2.0, "../precious.vtu")
    s.add(3.0, "a&b <1>.vtu")  # XML escaping
    assert _pvd_entries(out / "s.pvd")[-1] == (3.0, "a&b <1>.vtu")
    r = PvdSeries.open_existing(out / "s.pvd", keep_until_time=0.0)
    assert r.entries == [(0.0, 0, "mesh.vtu")]
    assert (out / "mesh.vtu").exists() and (tmp_path / "precious.vtu").exists()
    (out / "bad.pvd").write_text("<VTKFile type='Collection'><Collection><DataSet")
    with pytest.raises(InputError, match="bad.pvd: cannot read"):
        PvdSeries.open_existing(out / "bad.pvd", keep_until_time=1.0)
    with pytest.raises(InputError, match="time = nan"):
        r.add(float("nan"), "x.vtu")


def test_history_exact_17_digit_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    vals = np.concatenate([[0.1, 1 / 3, np.pi * 1e-17, -2.5e300, 5e-324, np.inf, -0.0],
                           rng.standard_normal(50) * 10.0 ** rng.integers(-300, 300, 50)])
    path = tmp_path / "h.csv"
    with HistoryWriter(path, ["step", "time", "x", "label"]) as h:
        for k, v in enumerate(vals):
            h.write({"step": np.int64(k), "time": v, "x": np.float64(v) * 2, "label": "a,b" if k == 0 else None})
    d = read_history(path)
    assert np.array_equal(d["step"], np.arange(len(vals)))
    assert np.array_equal(d["time"], vals) and np.array_equal(d["x"], vals * 2)  # bit-exact
    assert np.signbit(d["time"][6])
    lines = path.read_text().splitlines()
    assert lines[0] == "step,time,x,label" and lines[2].startswith("1,0.33333333333333331,")  # %.17g, int step
    assert lines[1].endswith('"a,b"')


def test_history_resume_truncates_and_checks_columns(tmp_path):
    path = tmp_path / "h.csv"
    cols = ["step", "time", "x"]
    with HistoryWriter(path, cols) as h:
        for k in range(6):
            h.write([k, 0.1 * k, k * k])
    with open(path, "a") as f:
        f.write("6,0.6000")  # a row torn by a crash
    h = HistoryWriter.resume(path, last_step=3)
    h.write({"step": 4, "time": 9.5, "x": 1.25})
    h.close()
    d = read_history(path)
    assert list(d["step"]) == [0, 1, 2, 3, 4] and d["time"][4] == 9.5 and d["x"][4] == 1.25
    assert d["time"][3] == 0.1 * 3
    with pytest.raises(InputError, match="columns differ"):
        HistoryWriter.resume(path, last_step=1, columns=["step", "t"])
    with pytest.raises(InputError, match="columns differ"):
        HistoryWriter(path, ["step", "t"], append=True)
    with pytest.raises(InputError, match="step_column 'it' not in the header"):
        HistoryWriter.resume(path, last_step=1, step_column="it")
    with pytest.raises(InputError, match="unknown history column"):
        HistoryWriter(tmp_path / "k.csv", ["a"]).write({"b": 1})
    with pytest.raises(InputError, match="expected 2 values"):
        HistoryWriter(tmp_path / "k.csv", ["a", "b"]).write([1.0])
    with pytest.raises(InputError, match="flush_every"):
        HistoryWriter(tmp_path / "k.csv", ["a"], flush_every=0)
    # append=True after a torn line: the torn row is dropped, the rest kept
    with open(path, "a") as f:
        f.write("5,0.5")
    with HistoryWriter(path, cols, append=True) as h:
        h.write([5, 0.5, 25])
    assert list(read_history(path)["step"]) == [0, 1, 2, 3, 4, 5]


def test_history_flushes_every_n_rows(tmp_path):
    path = tmp_path / "h.csv"
    h = HistoryWriter(path, ["step", "v"], flush_every=2)
    h.write([0, 1.5])
    h.write([1, 2.5])  # second row: flushed to disk while still open
    assert len(read_history(path)["step"]) == 2
    h.write([2, 3.5])
    h.close()
    d = read_history(path)
    assert list(d["v"]) == [1.5, 2.5, 3.5]


def test_summary_json_with_numpy_types(tmp_path):
    data = {"a": np.float64(1.5), "b": np.arange(3), "c": np.nan, "i": -np.inf, "m": np.eye(2, dtype=np.float32),
            "d": {"e": np.int64(4), "f": np.bool_(True), "p": pathlib.Path("x/y")}, "s": np.str_("ok")}
    d = write_summary(tmp_path / "s.json", data)
    got = json.loads((tmp_path / "s.json").read_text())
    assert got["a"] == 1.5 and got["b"] == [0, 1, 2] and got["c"] is None and got["i"] is None
    assert got["m"] == [[1.0, 0.0], [0.0, 1.0]] and got["s"] == "ok"
    assert got["d"] == {"e": 4, "f": True, "p": "x/y"}
    v = got["versions"]
    assert v["numpy"] == np.__version__ and v["fem_blocks"] == d["versions"]["fem_blocks"]
    assert {"python", "scipy", "numba", "dolfinx", "petsc4py", "gmsh"} <= set(v)
    ts = datetime.datetime.fromisoformat(got["timestamp"])
    assert ts.utcoffset() == datetime.timedelta(0)
    assert abs((datetime.datetime.now(datetime.timezone.utc) - ts).total_seconds()) < 3600
    with pytest.raises(InputError, match=r"summary\[d.obj\]"):
        write_summary(tmp_path / "t.json", {"d": {"obj": object()}})
    assert not (tmp_path / "t.json").exists()


def test_atomic_write_keeps_old_file_when_writer_raises_midway(tmp_path, monkeypatch):
    path = tmp_path / "keep.txt"
    atomic.atomic_write_text(path, "old")
    real_fdopen = os.fdopen

    class HalfWriter:
        def __init__(self, f):
            self.f = f

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

        def write(self, data):
            self.f.write(data[: len(data) // 2])
            self.f.flush()
            raise OSError("crash midway")

    monkeypatch.setattr(os, "fdopen", lambda fd, mode: HalfWriter(real_fdopen(fd, mode)))
    with pytest.raises(OSError, match="crash midway"):
        atomic.atomic_write_text(path, "new content that is long")
    monkeypatch.undo()
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]  # no temporary left behind

    def boom(fd):
        raise OSError("disk failure")
    monkeypatch.setattr(os, "fsync", boom)
    with pytest.raises(OSError, match="disk failure"):
        atomic.atomic_write_text(path, "new content")
    monkeypatch.undo()
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["keep.txt"]


def test_atomic_write_file_mode_follows_umask_not_mkstemp(tmp_path):
    old = os.umask(0o022)
    try:
        atomic.atomic_write_text(tmp_path / "n.txt", "x")
    finally:
        os.umask(old)
    assert (tmp_path / "n.txt").stat().st_mode & 0o777 == 0o644
    os.chmod(tmp_path / "n.txt", 0o640)
    atomic.atomic_write_text(tmp_path / "n.txt", "y")  # replacing keeps the file's mode
    assert (tmp_path / "n.txt").stat().st_mode & 0o777 == 0o640


def _png_size(path):
    b = pathlib.Path(path).read_bytes()
    assert b[:8] == b"\x89PNG\r\n\x1a\n"
    return int.from_bytes(b[16:20], "big"), int.from_bytes(b[20:24], "big"), len(b)


def test_plots_write_png_and_survive_empty_data(tmp_path):
    d = np.linspace(0, 2e-3, 50)
    f = 1e4 * d / (1 + (d / 5e-4) ** 2)
    assert plot_curve(tmp_path / "c.png", d, f, "u [m]", "F [N]", "curve") == tmp_path / "c.png"
    w, h, n = _png_size(tmp_path / "c.png")
    assert (w, h) == (768, 504) and n > 5000
    plot_curve(tmp_path / "e.png", [], [], "u", "F", "empty")
    assert _png_size(tmp_path / "e.png")[2] > 1000
    plot_curve(tmp_path / "nan.png", [0, 1], [np.nan, np.nan], "u", "F", "all NaN")
    polys = [np.array([[0, 0], [1, 0], [1, 0.5], [0, 0.5]]), np.array([[0, 0.5], [1, 0.5], [1, 1], [0, 1.0]])]
    seg = np.array([[[0, 0.5], [0.5, 0.5]], [[0.5, 0.5], [1, 0.5]]])
    out = plot_crack_pattern(tmp_path / "k.png", polys, seg, [0.2, 1.0], 50.0, "crack")
    w, h, n = _png_size(out)
    assert (w, h) == (975, 780) and n > 5000
    plot_crack_pattern(tmp_path / "k0.png", [], np.zeros((0, 2, 2)), [], 1.0, "empty")
    assert _png_size(tmp_path / "k0.png")[2] > 1000
    plot_crack_pattern(tmp_path / "k1.png", polys, [], [], 1.0, "blocks only")
    with pytest.raises(InputError, match="values: expected 2 values"):
        plot_crack_pattern(tmp_path / "z.png", polys, seg, [0.5], 1.0, "bad")
    out = plot_crack_pattern(tmp_path / "kw.png", polys, seg, [0.2, 1.0], 50.0, "crack", widths=[0.8, 5.0],
                             width_note="line width: joint opening + slip (thickest 1 mm)")
    assert _png_size(out)[:2] == (975, 780)
    with pytest.raises(InputError, match="widths: expected 2 line widths"):
        plot_crack_pattern(tmp_path / "z.png", polys, seg, [0.2, 1.0], 1.0, "bad", widths=[1.0])
    with pytest.raises(InputError, match="widths: expected finite line widths > 0"):
        plot_crack_pattern(tmp_path / "z.png", polys, seg, [0.2, 1.0], 1.0, "bad", widths=[1.0, 0.0])
    with pytest.raises(InputError, match="x and y must have the same length"):
        plot_curve(tmp_path / "z.png", [0, 1], [0], "u", "F", "bad")
    assert not (tmp_path / "z.png").exists()


def test_vtu_dtypes_and_empty_grid(tmp_path):
    P = np.array([[0.0, 0.0], [1.0, 0.0]])
    be = np.array([1.25, -3.5], dtype=">f8")  # big-endian input is written little-endian
    f32 = np.array([0.1, 0.2], dtype=np.float32)
    write_vtu(tmp_path / "d.vtu", P, [("line", [[0, 1]])],
              point_data={"be": be, "f32": f32, "i32": np.array([7, -8], np.int32), "u16": np.array([1, 2], "u2")})
    m = meshio.read(tmp_path / "d.vtu")
    assert np.array_equal(m.point_data["be"], [1.25, -3.5])
    assert m.point_data["f32"].dtype == np.float32 and np.array_equal(m.point_data["f32"], f32)
    assert m.point_data["i32"].dtype == np.int32 and np.array_equal(m.point_data["i32"], [7, -8])
    assert np.array_equal(m.point_data["u16"], [1, 2]) and m.cells[0].type == "line"
    # zero contacts: no point, one empty polygon cell (meshio 5.0 raises IndexError on a cell-less grid)
    write_vtu(tmp_path / "e.vtu", np.zeros((0, 2)), [("vertex", np.arange(0))], point_data={"r_N": np.zeros(0)},
              cell_data={"c": np.zeros(0)})
    root, arr = _decode_arrays(tmp_path / "e.vtu")
    piece = root.find("UnstructuredGrid/Piece")
    assert piece.get("NumberOfPoints") == "0" and piece.get("NumberOfCells") == "1"
    assert arr["Points"][1] == 0 and arr["r_N"][1] == 0 and set(arr) >= {"Points", "types", "r_N"}
    m = meshio.read(tmp_path / "e.vtu")
    assert len(m.points) == 0 and m.point_data["r_N"].shape == (0,)
    assert [(c.type, c.data.size) for c in m.cells] == [("polygon", 0)]
    g = _vtk_read(tmp_path / "e.vtu")
    assert (g.GetNumberOfPoints(), g.GetNumberOfCells()) == (0, 1) and g.GetPointData().HasArray("r_N")


def _vtk_read(path):
    """VTK's own XML reader (python3-vtk9, installed by scripts/setup.sh): fails the test on any reader error."""
    import vtk
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(str(path))
    obs = vtk.vtkFileOutputWindow()  # keep VTK's messages off the terminal; errors are read below
    obs.SetFileName("/dev/null")
    vtk.vtkOutputWindow.SetInstance(obs)
    r.Update()
    assert r.GetErrorCode() == 0, f"VTK could not read {path}"
    g = r.GetOutput()
    assert g is not None and g.GetNumberOfPoints() >= 0
    return g


def test_crack_width_is_opening_and_slip_and_sets_line_widths():
    """w = sqrt(<u_N>+^2 + u_T^2): a closed, sliding joint counts its slip, a closed stuck one nothing; the line
    width goes linearly from 0.8 pt (w = 0) to 5 pt (largest w)."""
    from fem_blocks.laws import NSTATE, S_UN, S_UT
    from fem_blocks.output.figures import crack_width, segment_widths
    st = np.zeros((4, NSTATE))
    st[:, S_UN] = [3e-4, -2e-5, 0.0, 6e-4]  # open, closed (compressed), touching, open
    st[:, S_UT] = [4e-4, 1e-3, 0.0, -8e-4]
    w = crack_width(st)
    np.testing.assert_allclose(w, [5e-4, 1e-3, 0.0, 1e-3], rtol=1e-14, atol=0)
    lw, wmax = segment_widths(w)
    assert wmax == 1e-3
    np.testing.assert_allclose(lw, [0.8 + 4.2 * 0.5, 5.0, 0.8, 5.0], rtol=1e-14)
    lw0, w0 = segment_widths(np.zeros(3))
    assert w0 == 0.0 and np.all(lw0 == 0.8)
