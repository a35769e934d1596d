"""VTK XML UnstructuredGrid (.vtu) writer on plain arrays: binary (base64, UInt64 headers), atomic.

Readable by ParaView and by meshio. Cells are given as blocks `(name, connectivity)` with names
vertex, line, triangle, quad, polygon (ragged list of index arrays), tetra, hexahedron.
2-vectors are padded to 3 components so ParaView shows them as vectors.
"""
from __future__ import annotations

import base64

import numpy as np

from ..errors import InputError
from .atomic import atomic_write_bytes

VTK_TYPES = {"vertex": 1, "line": 3, "triangle": 5, "polygon": 7, "quad": 9, "tetra": 10, "hexahedron": 12}
NODES = {"vertex": 1, "line": 2, "triangle": 3, "quad": 4, "tetra": 4, "hexahedron": 8}
VTK_DTYPES = {np.dtype("float64"): "Float64", np.dtype("float32"): "Float32", np.dtype("int64"): "Int64",
              np.dtype("int32"): "Int32", np.dtype("uint8"): "UInt8"}


def _b64(arr: np.ndarray) -> str:
    raw = np.ascontiguousarray(arr).tobytes()
    return base64.b64encode(np.uint64(len(raw)).tobytes() + raw).decode("ascii")


def _data_array(name: str, arr: np.ndarray) -> str:
    arr = np.asarray(arr)
    if arr.dtype == bool:
        arr = arr.astype(np.uint8)
    if arr.dtype.kind in "iu" and arr.dtype not in VTK_DTYPES:
        arr = arr.astype(np.int64)
    if arr.dtype.kind == "f" and arr.dtype not in VTK_DTYPES:
        arr = arr.astype(np.float64)
    comps = "" if arr.ndim == 1 else f' NumberOfComponents="{arr.shape[1]}"'
    return (f'<DataArray type="{VTK_DTYPES[arr.dtype]}" Name="{name}"{comps} '
            f'format="binary">{_b64(arr)}</DataArray>\n')


def _prepare_field(kind: str, name: str, arr, n: int) -> np.ndarray:
    a = np.asarray(arr)
    if a.ndim not in (1, 2) or a.shape[0] != n:
        raise InputError(f"{kind}[{name!r}]: expected {n} rows, got shape {a.shape}")
    if a.dtype.kind not in "biuf":
        raise InputError(f"{kind}[{name!r}]: expected numeric values, got dtype {a.dtype}")
    if a.ndim == 2 and a.shape[1] == 2:  # 2D vector -> 3 components
        a = np.column_stack([a, np.zeros(n, dtype=a.dtype)])
    return a


def write_vtu(path: str, points, cells, point_data=None, cell_data=None) -> None:
    """Write an unstructured grid. `cells`: list of (name, connectivity); point_data/cell_data: name -> array
    with one row per point / per cell (cells counted over the blocks in the given order)."""
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] not in (2, 3):
        raise InputError(f"points: expected an (n, 2) or (n, 3) array, got shape {P.shape}")
    if P.shape[1] == 2:
        P = np.column_stack([P, np.zeros(len(P))])
    n = len(P)
    conn, offsets, types = [], [], []
    off = 0
    for name, c in cells:
        if name not in VTK_TYPES:
            raise InputError(f"cells: unknown cell type {name!r}; expected one of {sorted(VTK_TYPES)}")
        if name == "polygon":
            for poly in c:
                poly = np.asarray(poly, dtype=np.int64).ravel()
                conn.append(poly)
                off += len(poly)
                offsets.append(off)
                types.append(7)
            continue
        c = np.asarray(c, dtype=np.int64)
        if c.size == 0:
            continue
        c = c.reshape(-1, NODES[name])
        conn.append(c.ravel())
        offsets.extend(off + NODES[name] * np.arange(1, len(c) + 1))
        off += c.size
        types.extend([VTK_TYPES[name]] * len(c))
    connectivity = np.concatenate(conn) if conn else np.zeros(0, dtype=np.int64)
    if connectivity.size and (connectivity.min() < 0 or connectivity.max() >= n):
        raise InputError("cells: connectivity refers to a point that does not exist")
    offsets = np.asarray(offsets, dtype=np.int64)
    types = np.asarray(types, dtype=np.uint8)
    ncells = len(types)
    out = ['<?xml version="1.0"?>\n<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" '
           'header_type="UInt64">\n<UnstructuredGrid>\n'
           f'<Piece NumberOfPoints="{n}" NumberOfCells="{ncells}">\n<Points>\n',
           _data_array("Points", P), "</Points>\n<Cells>\n",
           _data_array("connectivity", connectivity), _data_array("offsets", offsets),
           _data_array("types", types), "</Cells>\n"]
    if point_data:
        out.append("<PointData>\n")
        for k, v in point_data.items():
            out.append(_data_array(k, _prepare_field("point_data", k, v, n)))
        out.append("</PointData>\n")
    if cell_data:
        out.append("<CellData>\n")
        for k, v in cell_data.items():
            out.append(_data_array(k, _prepare_field("cell_data", k, v, ncells)))
        out.append("</CellData>\n")
    out.append("</Piece>\n</UnstructuredGrid>\n</VTKFile>\n")
    atomic_write_bytes(path, "".join(out).encode("ascii"))
