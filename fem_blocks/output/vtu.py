"""VTK XML UnstructuredGrid (.vtu) files on plain numpy arrays (no dolfinx), written by meshio, atomically.

meshio (`meshio.vtu` writer) writes the file: `<VTKFile type="UnstructuredGrid" version="0.1"
header_type="UInt64">`, every DataArray `format="binary"` inline (base64 of a UInt64 byte count followed by the
little-endian payload; uncompressed: see COMPRESSION).
This module validates the input (InputError naming the field or block), shapes it for ParaView and hands it to
meshio; the file appears by an atomic rename (`atomic.atomic_write_with`). Readable by ParaView/VTK and by
`meshio.read`.

Cells are given as a list of blocks `(name, connectivity)`; VTK cell `k` is the k-th cell counted over the
blocks in the given order. Names: vertex (k,) or (k,1), line (k,2), triangle (k,3), quad (k,4), tetra (k,4),
hexahedron (k,8), polygon (ragged list of index arrays, each of at least 3 nodes -> VTK_POLYGON; consecutive
polygons with the same node count form one meshio block, so the order is kept). A grid with no cell (a contact
frame with no contact point) is written with one empty VTK_POLYGON (0 nodes), so that meshio 5 reads it too.

Data: point_data / cell_data map a name to an array of shape (n,) or (n, k); 2-vectors (n, 2) are padded with a
zero third component so ParaView shows them as vectors (glyphs, "Warp By Vector"); every other k is kept
(a symmetric 2D stress (sxx, syy, sxy) stays 3 components under its given name). field_data: name -> scalar or
array (whole-dataset values such as the time); meshio 5 reads `<FieldData>` but does not write it, so this module
adds that element to meshio's file, encoded as meshio encodes the other arrays.

Parallel pieces (`write_pvtu`): a `.pvtu` file (`<VTKFile type="PUnstructuredGrid">`) names the `.vtu` pieces of
one grid (`<Piece Source="...">`, paths relative to the .pvtu) and declares their arrays (`<PPoints>`,
`<PPointData>`, `<PCellData>`: name, VTK type and number of components of each, as `array_info` computes them from
the arrays handed to write_vtu). The grid is the union of the pieces, in the listed order; each piece numbers
its points from 0.
"""
from __future__ import annotations

import base64
import zlib
from xml.sax.saxutils import escape, quoteattr

import meshio
import numpy as np

from ..errors import InputError
from .atomic import atomic_write_with

# None: uncompressed binary. "zlib" makes smaller files, but meshio 5.0 cannot read a zlib-compressed empty array
# back (the contact frame with no point): docs/benchmarks.md "VTU writer".
COMPRESSION = None
HEADER_TYPE = "UInt64"
VTK_TYPES = {"vertex": 1, "line": 3, "triangle": 5, "polygon": 7, "quad": 9, "tetra": 10, "hexahedron": 12}
NODES = {"vertex": 1, "line": 2, "triangle": 3, "quad": 4, "tetra": 4, "hexahedron": 8}
_VTK_DTYPES = {np.dtype(k): v for k, v in [
    ("<f8", "Float64"), ("<f4", "Float32"), ("<i8", "Int64"), ("<i4", "Int32"), ("<i2", "Int16"), ("i1", "Int8"),
    ("<u8", "UInt64"), ("<u4", "UInt32"), ("<u2", "UInt16"), ("u1", "UInt8")]}


def _vtk_array(arr: np.ndarray) -> np.ndarray:
    """Cast to a little-endian dtype VTK knows: bool -> UInt8, float16/128 -> Float64."""
    if arr.dtype == bool:
        return arr.astype(np.uint8)
    if arr.dtype.kind == "f" and arr.dtype.itemsize not in (4, 8):
        return arr.astype(np.float64)
    return arr.astype(arr.dtype.newbyteorder("<"), copy=False)


def _b64(arr: np.ndarray) -> str:
    """A binary DataArray's text as meshio writes it: base64(UInt64 byte count + payload), or with zlib the
    base64 block header (count, block size, last block size, compressed sizes) followed by base64(blocks)."""
    raw = np.ascontiguousarray(arr).tobytes()
    if not COMPRESSION:
        return base64.b64encode(np.array(len(raw), dtype="<u8").tobytes() + raw).decode("ascii")
    bs = 32768
    blocks = [zlib.compress(raw[i:i + bs]) for i in range(0, len(raw), bs)]
    head = np.array([len(blocks), bs, len(raw) - (len(blocks) - 1) * bs if blocks else 0]
                    + [len(b) for b in blocks], dtype="<u8")
    return base64.b64encode(head.tobytes()).decode("ascii") + base64.b64encode(b"".join(blocks)).decode("ascii")


def _field_data_xml(fd: dict) -> str:
    out = ["<FieldData>\n"]
    for k, a in fd.items():
        a = _vtk_array(a)
        comps = "" if a.ndim == 1 else f' NumberOfComponents="{a.shape[1]}"'
        out.append(f'<DataArray type="{_VTK_DTYPES[a.dtype]}" Name={quoteattr(k)}{comps} '
                   f'NumberOfTuples="{a.shape[0]}" format="binary">\n{_b64(a)}\n</DataArray>\n')
    return "".join(out) + "</FieldData>\n"


def _xml_name(name: str) -> str:
    return escape(name, {'"': "&quot;"})


def _numeric(what: str, a) -> np.ndarray:
    try:
        a = np.asarray(a)
    except Exception as e:  # ragged nested lists etc.
        raise InputError(f"{what}: expected a numeric array ({e})") from None
    if a.dtype.kind not in "biuf":
        raise InputError(f"{what}: expected numeric values (float or int), got dtype {a.dtype}")
    return a


def _prepare_field(kind: str, name, arr, n: int) -> np.ndarray:
    what = f"{kind}[{name!r}]"
    if not isinstance(name, str) or not name:
        raise InputError(f"{kind}: field names must be non-empty strings, got {name!r}")
    a = _numeric(what, arr)
    if a.ndim not in (1, 2) or a.shape[0] != n:
        raise InputError(f"{what}: expected {n} rows, shape ({n},) or ({n}, k), got shape {a.shape}")
    if a.ndim == 2 and a.shape[1] == 0:
        raise InputError(f"{what}: expected at least one component, got shape {a.shape}")
    if a.ndim == 2 and a.shape[1] == 1:
        a = a[:, 0]
    if a.ndim == 2 and a.shape[1] == 2:  # 2D vector -> 3 components (z = 0)
        a = np.column_stack([a, np.zeros(n, dtype=a.dtype)])
    return a


def _cells(cells, n: int) -> list:
    """Blocks -> meshio blocks [(name, (m, k) int64 array)] in the given order, with validation naming the
    block; a ragged polygon list becomes one block per run of polygons with the same node count."""
    out = []
    if isinstance(cells, (str, bytes)) or not hasattr(cells, "__iter__"):
        raise InputError("cells: expected a list of (cell_type_name, connectivity) blocks")
    for i, blk in enumerate(cells):
        try:
            name, c = blk
        except (TypeError, ValueError):
            raise InputError(f"cells[{i}]: expected a (cell_type_name, connectivity) pair") from None
        what = f"cells[{i}] ({name!r})"
        if name not in VTK_TYPES:
            raise InputError(f"{what}: unknown cell type {name!r}; expected one of {sorted(VTK_TYPES)}")
        if name == "polygon":
            for j, poly in enumerate(c):
                p = _numeric(f"{what}[{j}]", poly)
                if p.dtype.kind == "f" and not np.array_equal(p, np.round(p)):
                    raise InputError(f"{what}[{j}]: expected integer node indices")
                p = p.astype(np.int64).ravel()
                if len(p) < 3:
                    raise InputError(f"{what}[{j}]: expected a polygon of at least 3 nodes, got {len(p)}")
                if p.min() < 0 or p.max() >= n:
                    raise InputError(f"cells (polygon): node index out of range: expected 0 <= index < {n}; "
                                     "the connectivity refers to a point that does not exist")
                if out and out[-1][0] == "polygon" and len(out[-1][1][0]) == len(p):  # same node count: same block
                    out[-1][1].append(p)
                else:
                    out.append(("polygon", [p]))
            continue
        a = _numeric(what, c)
        if a.dtype.kind == "f" and not np.array_equal(a, np.round(a)):
            raise InputError(f"{what}: expected integer node indices")
        k = NODES[name]
        if a.size == 0:
            continue
        if name == "vertex" and a.ndim == 1:
            a = a[:, None]
        if a.ndim != 2 or a.shape[1] != k:
            raise InputError(f"{what}: expected connectivity of shape (m, {k}), got shape {a.shape}")
        if a.min() < 0 or a.max() >= n:
            raise InputError(f"{what}: node index out of range: expected 0 <= index < {n} (number of points), "
                             f"got [{a.min()}, {a.max()}]; the connectivity refers to a point that does not exist")
        out.append((name, a.astype(np.int64)))
    return [(name, np.array(c, dtype=np.int64) if isinstance(c, list) else c) for name, c in out]


def write_vtu(path, points, cells, point_data=None, cell_data=None, field_data=None) -> str:
    """Write an unstructured grid atomically and return `path`.

    points (n, 2) or (n, 3) float (2D padded with z = 0); cells: list of (name, connectivity) blocks;
    point_data / cell_data: name -> (n,) or (n, k) array with one row per point / per cell;
    field_data: name -> scalar or array. Raises InputError naming the offending field or block."""
    P = _numeric("points", points).astype(np.float64)
    if P.ndim != 2 or P.shape[1] not in (2, 3):
        raise InputError(f"points: expected an (n, 2) or (n, 3) array, got shape {P.shape}")
    if P.shape[1] == 2:
        P = np.column_stack([P, np.zeros(len(P))])
    n = len(P)
    blocks = _cells(cells, n)
    ncells = sum(len(c) for _, c in blocks)
    pd = {k: _vtk_array(_prepare_field("point_data", k, v, n)) for k, v in (point_data or {}).items()}
    cd = {k: _vtk_array(_prepare_field("cell_data", k, v, ncells)) for k, v in (cell_data or {}).items()}
    if ncells == 0:
        # A grid with no cell (e.g. a contact frame with no contact point) is valid VTK, but meshio 5 cannot
        # read it (IndexError on the empty `types`): write one empty polygon cell (0 nodes) instead, which VTK's
        # reader and meshio both read as a grid with no points; cell data get one zero row for it.
        blocks = [("polygon", np.zeros((1, 0), dtype=np.int64))]
        cd = {k: np.zeros((1,) + a.shape[1:], dtype=a.dtype) for k, a in cd.items()}
    fd = {}
    for k, v in (field_data or {}).items():
        if not isinstance(k, str) or not k:
            raise InputError(f"field_data: field names must be non-empty strings, got {k!r}")
        a = _numeric(f"field_data[{k!r}]", v)
        if a.ndim > 2:
            raise InputError(f"field_data[{k!r}]: expected a scalar, (m,) or (m, k) array, got shape {a.shape}")
        fd[k] = a.reshape(-1) if a.ndim == 0 else a
    bounds = np.cumsum([0] + [len(c) for _, c in blocks])
    # meshio 5 writes Name="..." without escaping: escape the names here (XML readers give back the original)
    mesh = meshio.Mesh(P, blocks, point_data={_xml_name(k): a for k, a in pd.items()},
                       cell_data={_xml_name(k): [a[b0:b1] for b0, b1 in zip(bounds[:-1], bounds[1:])]
                                  for k, a in cd.items()})

    def write_to(tmp):
        meshio.vtu.write(tmp, mesh, binary=True, compression=COMPRESSION, header_type=HEADER_TYPE)
        if fd:  # meshio 5 does not write field data: insert <FieldData> as the grid's first child
            with open(tmp, encoding="utf-8") as f:
                text = f.read()
            tag = "<UnstructuredGrid>\n"
            i = text.index(tag) + len(tag)
            with open(tmp, "w", encoding="utf-8") as f:
                f.write(text[:i] + _field_data_xml(fd) + text[i:])
    atomic_write_with(path, write_to)
    return path


def array_info(point_data=None, cell_data=None) -> dict:
    """The arrays that `write_vtu(path, points, cells, point_data, cell_data)` writes, as a .pvtu declares them:
    {"points": [("Points", "Float64", 3)], "point": [(name, VTK type, components)], "cell": [...]}, in the
    given order (2-vectors padded to 3 components, bool -> UInt8, as write_vtu does; scalars: 1 component)."""
    def info(kind, data):
        out = []
        for k, v in (data or {}).items():
            a = _numeric(f"{kind}[{k!r}]", v)
            a = _vtk_array(_prepare_field(kind, k, a, a.shape[0] if a.ndim else -1))
            out.append((k, _VTK_DTYPES[a.dtype], 1 if a.ndim == 1 else int(a.shape[1])))
        return out
    return {"points": [("Points", "Float64", 3)], "point": info("point_data", point_data),
            "cell": info("cell_data", cell_data)}


def write_pvtu(path, sources, arrays: dict) -> str:
    """Write the parallel grid `path` (.pvtu) of the pieces `sources` (.vtu paths relative to the .pvtu's
    directory, in order) with the arrays `arrays` (array_info of any piece: every piece has the same arrays);
    atomically. Returns `path`."""
    def pdata(items, with_name=True):
        return "".join(f'<PDataArray type="{t}"' + (f" Name={quoteattr(k)}" if with_name else "")
                       + (f' NumberOfComponents="{c}"' if c != 1 or not with_name else "") + "/>\n"
                       for k, t, c in items)
    if not sources:
        raise InputError(f"{path}: a parallel grid needs at least one piece")
    text = ('<?xml version="1.0"?>\n'
            '<VTKFile type="PUnstructuredGrid" version="0.1" byte_order="LittleEndian" '
            f'header_type="{HEADER_TYPE}">\n<PUnstructuredGrid GhostLevel="0">\n'
            f'<PPoints>\n{pdata(arrays["points"], False)}</PPoints>\n'
            f'<PPointData>\n{pdata(arrays["point"])}</PPointData>\n'
            f'<PCellData>\n{pdata(arrays["cell"])}</PCellData>\n'
            + "".join(f"<Piece Source={quoteattr(str(s).replace(chr(92), '/'))}/>\n" for s in sources)
            + "</PUnstructuredGrid>\n</VTKFile>\n")
    from .atomic import atomic_write_text
    atomic_write_text(path, text)
    return path
