"""output/vtu.py through meshio: what the meshio path could get wrong that tests/test_output.py does not probe.

* polygons of alternating node counts (3, 4, 3, 5, 3) keep their order and their cell data, read back cell by
  cell with VTK's own reader (catches grouping polygons by node count over the whole list, which reorders cells);
* names with XML characters (&, <, ") stay valid XML (meshio 5 writes Name="..." unescaped);
* the atomic write around a writer that wants a file name (`atomic.atomic_write_with`): a writer failing midway
  leaves the previous file and no temporary (catches a rename before the write completes, or a lost clean-up).
"""
import os

import numpy as np
import pytest

from fem_blocks.output import atomic
from fem_blocks.output.vtu import write_vtu

from test_output import _vtk_read


def test_polygons_of_alternating_sizes_keep_order_and_data(tmp_path):
    P = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [2, 0], [2, 1], [3, 0.5], [0.5, 2]], float)
    polys = [[0, 1, 2], [1, 4, 5, 2], [2, 5, 7], [4, 6, 5, 7, 2], [0, 2, 3]]
    damage = np.array([0.1, 0.2, 0.3, 0.4, 0.5])
    f = tmp_path / "alt.vtu"
    write_vtu(f, P, [("polygon", polys)], cell_data={"damage": damage})
    g = _vtk_read(f)
    assert g.GetNumberOfCells() == 5
    arr = g.GetCellData().GetArray("damage")
    for k, poly in enumerate(polys):
        ids = g.GetCell(k).GetPointIds()
        assert [ids.GetId(j) for j in range(ids.GetNumberOfIds())] == poly
        assert g.GetCellType(k) == 7 and arr.GetValue(k) == damage[k]


def test_atomic_write_with_keeps_old_file_when_the_writer_fails(tmp_path):
    path = tmp_path / "frame.vtu"
    path.write_text("old")
    os.chmod(path, 0o640)

    def half(tmp):
        with open(tmp, "w") as fh:
            fh.write("new, but")
        raise OSError("disk full midway")
    with pytest.raises(OSError, match="disk full midway"):
        atomic.atomic_write_with(path, half)
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["frame.vtu"]

    def whole(tmp):
        with open(tmp, "w") as fh:
            fh.write("new")
    atomic.atomic_write_with(path, whole)
    assert path.read_text() == "new" and [p.name for p in tmp_path.iterdir()] == ["frame.vtu"]
    assert path.stat().st_mode & 0o777 == 0o640  # the replaced file's permissions are kept


def test_field_names_with_xml_characters_round_trip(tmp_path):
    """meshio 5 writes Name="..." as given: the names must be escaped for the file to stay valid XML."""
    import meshio
    name = 'a&b <1> "q"'
    f = tmp_path / "names.vtu"
    write_vtu(f, np.zeros((3, 2)), [("triangle", [[0, 1, 2]])], point_data={name: np.arange(3.0)},
              cell_data={name: np.array([7])}, field_data={name: 1.5})
    m = meshio.read(f)
    assert np.array_equal(m.point_data[name], [0.0, 1.0, 2.0]) and np.array_equal(m.cell_data[name][0], [7])
    assert np.array_equal(np.ravel(m.field_data[name]), [1.5])
    g = _vtk_read(f)
    assert g.GetPointData().GetArray(name).GetValue(2) == 2.0 and g.GetCellData().GetArray(name).GetValue(0) == 7
