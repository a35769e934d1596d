"""Output writers: VTU/PVD read back with meshio, history CSV exact round trip, resume, atomicity."""
import json
import os

import meshio
import numpy as np
import pytest

from fem_blocks.errors import InputError
from fem_blocks.output import atomic
from fem_blocks.output.history import HistoryWriter, read_history
from fem_blocks.output.pvd import PvdSeries
from fem_blocks.output.summary import write_summary
from fem_blocks.output.vtu import write_vtu


def test_vtu_mixed_cells_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    P = rng.random((7, 2))
    tri = np.array([[0, 1, 2], [2, 3, 0]])
    quad = np.array([[1, 4, 5, 2]])
    poly = [np.array([3, 5, 6]), np.array([0, 2, 5, 6, 4])]
    vel = rng.random((7, 2))
    stress = rng.random((5, 3))
    ids = np.arange(5, dtype=np.int64)
    f = tmp_path / "a.vtu"
    write_vtu(f, P, [("triangle", tri), ("quad", quad), ("polygon", poly)],
              point_data={"velocity": vel, "scalar": P[:, 0]}, cell_data={"stress": stress, "id": ids})
    m = meshio.read(f)
    assert np.array_equal(m.points[:, :2], P) and np.all(m.points[:, 2] == 0)
    assert np.array_equal(m.point_data["velocity"][:, :2], vel)
    assert np.array_equal(m.point_data["scalar"], P[:, 0])
    types = [c.type for c in m.cells]
    assert types[:2] == ["triangle", "quad"]
    assert np.array_equal(m.cells[0].data, tri) and np.array_equal(m.cells[1].data, quad)
    got = np.concatenate([np.asarray(a).reshape(len(a), -1) for a in m.cell_data["stress"]])
    assert np.array_equal(got, stress)
    assert np.array_equal(np.concatenate(m.cell_data["id"]).ravel(), ids)


def test_vtu_vertex_cloud(tmp_path):
    P = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 1.0]])
    f = tmp_path / "c.vtu"
    write_vtu(f, P, [("vertex", np.arange(3))], point_data={"r_N": np.array([1.0, 2.0, 3.0])},
              cell_data={"status": np.array([0, 1, 2])})
    m = meshio.read(f)
    assert m.cells[0].type == "vertex" and len(m.cells[0].data) == 3
    assert np.array_equal(m.point_data["r_N"], [1.0, 2.0, 3.0])


def test_vtu_bad_field_named(tmp_path):
    with pytest.raises(InputError, match=r"point_data\['velocity'\]: expected 3 rows"):
        write_vtu(tmp_path / "x.vtu", np.zeros((3, 2)), [("vertex", np.arange(3))],
                  point_data={"velocity": np.zeros((4, 2))})
    with pytest.raises(InputError, match="unknown cell type 'pyramid'"):
        write_vtu(tmp_path / "x.vtu", np.zeros((3, 2)), [("pyramid", np.arange(3))])
    with pytest.raises(InputError, match="does not exist"):
        write_vtu(tmp_path / "x.vtu", np.zeros((3, 2)), [("triangle", np.array([[0, 1, 3]]))])


def test_pvd_series_valid_after_each_add_and_resume(tmp_path):
    import xml.etree.ElementTree as ET
    path = tmp_path / "s.pvd"
    s = PvdSeries(path)
    for k in range(4):
        name = f"f{k}.vtu"
        write_vtu(tmp_path / name, np.zeros((1, 2)), [("vertex", [0])])
        s.add(0.1 * k, name)
        ds = list(ET.parse(path).getroot().iter("DataSet"))  # valid XML after each frame
        assert len(ds) == k + 1 and ds[-1].get("file") == name
    r = PvdSeries.open_existing(path, keep_until_time=0.1)
    assert [e[2] for e in r.entries] == ["f0.vtu", "f1.vtu"]
    assert not (tmp_path / "f3.vtu").exists() and (tmp_path / "f1.vtu").exists()
    r.add(0.2, "g2.vtu")
    assert [d.get("file") for d in ET.parse(path).getroot().iter("DataSet")] == ["f0.vtu", "f1.vtu", "g2.vtu"]


def test_history_exact_round_trip_and_resume(tmp_path):
    path = tmp_path / "h.csv"
    vals = [0.1, 1 / 3, np.pi * 1e-17, -2.5e300]
    with HistoryWriter(path, ["step", "time", "x"]) as h:
        for k, v in enumerate(vals):
            h.write({"step": k, "time": v, "x": np.float64(v) * 2})
    d = read_history(path)
    assert list(d["step"]) == [0, 1, 2, 3]
    assert np.array_equal(d["time"], vals) and np.array_equal(d["x"], np.array(vals) * 2)
    h = HistoryWriter.resume(path, ["step", "time", "x"], last_step=1)
    h.write([2, 9.0, 9.0])
    h.close()
    d = read_history(path)
    assert list(d["step"]) == [0, 1, 2] and d["time"][2] == 9.0
    with pytest.raises(InputError, match="columns differ"):
        HistoryWriter.resume(path, ["step", "t"], last_step=1)
    with pytest.raises(InputError, match="unknown history column"):
        HistoryWriter(tmp_path / "k.csv", ["a"]).write({"b": 1})


def test_summary_numpy_types(tmp_path):
    d = write_summary(tmp_path / "s.json", {"a": np.float64(1.5), "b": np.arange(3), "c": np.nan,
                                            "d": {"e": np.int64(4), "f": np.bool_(True)}})
    got = json.loads((tmp_path / "s.json").read_text())
    assert got["a"] == 1.5 and got["b"] == [0, 1, 2] and got["c"] is None and got["d"] == {"e": 4, "f": True}
    assert "versions" in got and got["versions"]["fem_blocks"] == d["versions"]["fem_blocks"]


def test_atomic_write_keeps_old_file_on_failure(tmp_path, monkeypatch):
    path = tmp_path / "keep.txt"
    atomic.atomic_write_text(path, "old")

    def boom(fd):
        raise OSError("disk failure")
    monkeypatch.setattr(os, "fsync", boom)
    with pytest.raises(OSError):
        atomic.atomic_write_text(path, "new content")
    monkeypatch.undo()
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]  # no temporary left behind
