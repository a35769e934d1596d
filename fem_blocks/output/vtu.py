"""VTK XML UnstructuredGrid (.vtu) writer on plain numpy arrays (no dolfinx), binary and atomic.

Format: `<VTKFile type="UnstructuredGrid" version="1.0" header_type="UInt64">`, every DataArray
`format="binary"`: base64 of (UInt64 byte count of the payload) + (little-endian payload), inline.
Readable by ParaView and by `meshio.read`.

Cells are given as a list of blocks `(name, connectivity)`; VTK cell `k` is the k-th cell counted over the
blocks in the given order, and `offsets[k]` = sum of the node counts of cells 0..k (VTK XML 1.0 convention).
Names: vertex (k,) or (k,1), line (k,2), triangle (k,3), quad (k,4), tetra (k,4), hexahedron (k,8),
polygon (ragged list of index arrays, each of at least 3 nodes -> VTK_POLYGON). A grid with no cell (a contact
frame with no contact point) is written with one empty VTK_POLYGON (0 nodes), so that meshio 5 reads it too.

Data: point_data / cell_data map a name to an array of shape (n,) or (n, k); 2-vectors (n, 2) are padded with a
zero third component so ParaView shows them as vectors (glyphs, "Warp By Vector"); every other k is kept
(a symmetric 2D stress (sxx, syy, sxy) stays 3 components under its given name). field_data: name -> scalar or
array (whole-dataset values such as the time).
"""
from __future__ import annotations

import base64
from xml.sax.saxutils import quoteattr

import numpy as np

from ..errors import InputError
from .atomic import atomic_write_bytes

VTK_TYPES = {"vertex": 1, "line": 3, "triangle": 5, "polygon": 7, "quad": 9, "tetra": 10, "hexahedron": 12}
NODES = {"vertex": 1, "line": 2, "triangle": 3, "quad": 4, "tetra": 4, "hexahedron": 8}
_VTK_DTYPES = {np.dtype(k): v for k, v in [
    ("<f8", "Float64"), ("<f4", "Float32"), ("<i8", "Int64"), ("<i4", "Int32"), ("<i2", "Int16"), ("i1", "Int8"),
    ("<u8", "UInt64"), ("<u4", "UInt32"), ("<u2", "UInt16"), ("u1", "UInt8")]}


def _b64(arr: np.ndarray) -> str:
    """base64(UInt64 little-endian byte count + raw little-endian bytes) of a contiguous array."""
    raw = np.ascontiguousarray(arr).tobytes()
    return base64.b64encode(np.array(len(raw), dtype="<u8").tobytes() + raw).decode("ascii")


def _vtk_array(arr: np.ndarray) -> np.ndarray:
    """Cast to a little-endian dtype VTK knows: bool -> UInt8, float16/128 -> Float64."""
    if arr.dtype == bool:
        return arr.astype(np.uint8)
    if arr.dtype.kind == "f" and arr.dtype.itemsize not in (4, 8):
        return arr.astype(np.float64)
    return arr.astype(arr.dtype.newbyteorder("<"), copy=False)


def _data_array(name: str, arr: np.ndarray, extra: str = "") -> str:
    arr = _vtk_array(np.asarray(arr))
    comps = "" if arr.ndim == 1 else f' NumberOfComponents="{arr.shape[1]}"'
    return (f'<DataArray type="{_VTK_DTYPES[arr.dtype]}" Name={quoteattr(str(name))}{comps}{extra} '
            f'format="binary">{_b64(arr)}</DataArray>\n')


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


def _cells(cells, n: int):
    """Blocks -> (connectivity, offsets, types) flat VTK arrays, with validation naming the block."""
    conn, sizes, types = [], [], []
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
                conn.append(p)
                sizes.append(np.array([len(p)], dtype=np.int64))
                types.append(np.array([7], dtype=np.uint8))
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
        conn.append(a.astype(np.int64).ravel())
        sizes.append(np.full(len(a), k, dtype=np.int64))
        types.append(np.full(len(a), VTK_TYPES[name], dtype=np.uint8))
        if a.min() < 0 or a.max() >= n:
            raise InputError(f"{what}: node index out of range: expected 0 <= index < {n} (number of points), "
                             f"got [{a.min()}, {a.max()}]; the connectivity refers to a point that does not exist")
    connectivity = np.concatenate(conn) if conn else np.zeros(0, dtype=np.int64)
    if connectivity.size and (connectivity.min() < 0 or connectivity.max() >= n):
        raise InputError(f"cells (polygon): node index out of range: expected 0 <= index < {n}; "
                         "the connectivity refers to a point that does not exist")
    sizes = np.concatenate(sizes) if sizes else np.zeros(0, dtype=np.int64)
    types = np.concatenate(types) if types else np.zeros(0, dtype=np.uint8)
    return connectivity, np.cumsum(sizes, dtype=np.int64), types


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
    connectivity, offsets, types = _cells(cells, n)
    ncells = len(types)
    pd = {k: _prepare_field("point_data", k, v, n) for k, v in (point_data or {}).items()}
    cd = {k: _prepare_field("cell_data", k, v, ncells) for k, v in (cell_data or {}).items()}
    if ncells == 0:
        # A grid with no cell (e.g. a contact frame with no contact point) is valid VTK, but meshio 5 cannot
        # read it (IndexError on the empty `types`): write one empty polygon cell (0 nodes) instead, which VTK's
        # reader and meshio both read as a grid with no points; cell data get one zero row for it.
        offsets, types, ncells = np.zeros(1, dtype=np.int64), np.full(1, VTK_TYPES["polygon"], dtype=np.uint8), 1
        cd = {k: np.zeros((1,) + a.shape[1:], dtype=a.dtype) for k, a in cd.items()}
    fd = {}
    for k, v in (field_data or {}).items():
        if not isinstance(k, str) or not k:
            raise InputError(f"field_data: field names must be non-empty strings, got {k!r}")
        a = _numeric(f"field_data[{k!r}]", v)
        if a.ndim > 2:
            raise InputError(f"field_data[{k!r}]: expected a scalar, (m,) or (m, k) array, got shape {a.shape}")
        fd[k] = a.reshape(-1) if a.ndim == 0 else a
    out = ['<?xml version="1.0"?>\n<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" '
           'header_type="UInt64">\n<UnstructuredGrid>\n']
    if fd:
        out.append("<FieldData>\n")
        out += [_data_array(k, a, f' NumberOfTuples="{a.shape[0]}"') for k, a in fd.items()]
        out.append("</FieldData>\n")
    out += [f'<Piece NumberOfPoints="{n}" NumberOfCells="{ncells}">\n<Points>\n',
            _data_array("Points", P), "</Points>\n<Cells>\n",
            _data_array("connectivity", connectivity), _data_array("offsets", offsets),
            _data_array("types", types), "</Cells>\n"]
    if pd:
        out += ["<PointData>\n"] + [_data_array(k, a) for k, a in pd.items()] + ["</PointData>\n"]
    if cd:
        out += ["<CellData>\n"] + [_data_array(k, a) for k, a in cd.items()] + ["</CellData>\n"]
    out.append("</Piece>\n</UnstructuredGrid>\n</VTKFile>\n")
    atomic_write_bytes(path, "".join(out).encode("utf-8"))
    return path
