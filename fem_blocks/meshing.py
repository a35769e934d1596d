"""Block meshes with gmsh, returned as plain arrays (`BlockMesh`), and mesh validation.

A block type is meshed once (gmsh is not translation-stable: the same rectangle meshed at two
offsets can give different node counts), then instanced by translation and rotation.

`BlockMesh`: points (n,2), cells (nc,3|4) counter-clockwise, cell_type "triangle"|"quad",
boundary_edges (ne,2) oriented with the body on the left (outer loop CCW, holes CW), edge_tags
(ne,) and tag_names {name: id} from gmsh physical curves ("untagged" = 0 for the rest).

`BlockMesh3D` (3D blocks: a box, a hexahedral block given by its 8 corners, a .msh/.geo file): points (n,3),
cells (nc,4|8) positively oriented, cell_type "tetrahedron"|"hexahedron", boundary_faces (nf,3|4) with outward
right-hand-rule normals, face_tags (nf,) (side 0..5 of a generated block, physical surface tag of a file, -1
untagged), tag_names; see docs/architecture.md.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError
from .geometry import HEX_XI, box_corners, check_hex_corners, hex_shape_gradients  # noqa: F401 (re-exported)

GMSH_LINEAR = {2: "triangle", 3: "quad"}
GMSH_NAMES = {1: "2-node line", 2: "3-node triangle", 3: "4-node quadrangle", 4: "4-node tetrahedron",
              5: "8-node hexahedron", 8: "3-node line", 9: "6-node triangle", 10: "9-node quadrangle",
              15: "point", 16: "8-node quadrangle", 20: "9-node incomplete triangle", 21: "10-node triangle"}


class _MeshArrays:
    """What BlockMesh and BlockMesh3D share: `points` (n, gdim) and a boundary connectivity array named by
    `_boundary` (2D edges, 3D faces)."""

    _boundary = ""

    @property
    def n_nodes(self) -> int:
        return int(self.points.shape[0])

    def boundary_nodes(self) -> np.ndarray:
        """Sorted unique node indices on the boundary (int64)."""
        return np.unique(np.asarray(getattr(self, self._boundary), dtype=np.int64))

    def bbox(self):
        """(xmin, ymin[, zmin], xmax, ymax[, zmax])."""
        return (*self.points.min(axis=0), *self.points.max(axis=0))


@dataclass(eq=False)
class BlockMesh(_MeshArrays):
    """2D block mesh as plain arrays (see the module docstring). `node_ids`/`cell_ids` (optional) are the
    gmsh node/element tags, used only to name nodes and elements in error messages."""

    points: np.ndarray
    cells: np.ndarray
    cell_type: str
    boundary_edges: np.ndarray
    edge_tags: np.ndarray
    tag_names: dict = field(default_factory=dict)
    source: str = "mesh"
    node_ids: np.ndarray | None = field(default=None, repr=False)
    cell_ids: np.ndarray | None = field(default=None, repr=False)

    gdim = 2
    _boundary = "boundary_edges"

    @classmethod
    def from_cells(cls, points, cells, cell_type: str | None = None, source: str = "mesh") -> "BlockMesh":
        """BlockMesh of given arrays: boundary edges from the cells, all untagged (tag 0)."""
        P = np.asarray(points, dtype=np.float64)
        C = np.asarray(cells, dtype=np.int64)
        if cell_type is None:
            cell_type = "triangle" if C.ndim == 2 and C.shape[1] == 3 else "quad"
        be, _ = boundary_from_cells(C, source)
        return cls(P, C, cell_type, be.astype(np.int64), np.zeros(len(be), dtype=np.int64), {"untagged": 0}, source)

    def translated(self, dx: float, dy: float) -> "BlockMesh":
        """Same mesh (same node order and connectivity) moved by (dx, dy)."""
        return BlockMesh(self.points + np.array([dx, dy], dtype=np.float64), self.cells, self.cell_type,
                         self.boundary_edges, self.edge_tags, dict(self.tag_names), self.source,
                         self.node_ids, self.cell_ids)

    def cell_areas(self) -> np.ndarray:
        """Signed area of each cell (shoelace), positive for counter-clockwise cells."""
        return _signed_areas(self.points, self.cells)

    def area(self) -> float:
        return float(self.cell_areas().sum())


def _signed_areas(points, cells) -> np.ndarray:
    """Shoelace formula per cell (positive when counter-clockwise)."""
    x = points[cells, 0]
    y = points[cells, 1]
    return 0.5 * np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)


def boundary_from_cells(cells: np.ndarray, source: str = "mesh", node_name=str):
    """Edges used by exactly one cell, oriented as in that (CCW) cell, and that cell's index; InputError on an
    edge shared by more than 2 cells (nodes named by `node_name(index)`)."""
    nv = cells.shape[1]
    e = np.stack([cells, np.roll(cells, -1, axis=1)], axis=2).reshape(-1, 2)
    key = np.sort(e, axis=1)
    uniq, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    if np.any(cnt > 2):
        a, b = uniq[np.flatnonzero(cnt > 2)[0]]
        raise InputError(f"{source}: non-manifold mesh: edge between nodes {node_name(a)} and {node_name(b)} is "
                         f"shared by "
                         f"{cnt.max()} elements (expected at most 2)")
    once = cnt[inv] == 1
    return e[once], np.flatnonzero(once) // nv


# ----------------------------------------------------------------------------- gmsh helpers
_GMSH_READY = False
# options a .geo file or a previous call may change; restored to the gmsh defaults before every use
_GMSH_OPTIONS = ("Mesh.ElementOrder", "Mesh.SecondOrderIncomplete", "Mesh.MeshSizeMin", "Mesh.MeshSizeMax",
                 "Mesh.MeshSizeFactor", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature",
                 "Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromParametricPoints", "Mesh.RecombineAll",
                 "Mesh.RecombinationAlgorithm", "Mesh.SubdivisionAlgorithm", "Mesh.Algorithm", "Mesh.Smoothing",
                 "Mesh.SaveAll", "Geometry.Tolerance")
_GMSH_DEFAULTS: dict = {}


def _import_gmsh():
    """Import gmsh without letting it replace Python's SIGINT handler (gmsh.py sets SIG_DFL on import)."""
    import signal
    old = signal.getsignal(signal.SIGINT)
    import gmsh
    if signal.getsignal(signal.SIGINT) is not old and old is not None:
        signal.signal(signal.SIGINT, old)
    return gmsh


def _finalize_gmsh():
    global _GMSH_READY
    if _GMSH_READY:
        import signal
        old = signal.getsignal(signal.SIGINT)
        try:
            _import_gmsh().finalize()
        except Exception:
            pass
        if old is not None:
            signal.signal(signal.SIGINT, old)
        _GMSH_READY = False


class _Gmsh:
    """Context manager around one gmsh use: gmsh initialised once per process (finalised at exit, re-initialised
    if someone else finalised it or after a gmsh error), quiet, default meshing options, a fresh model, cleared
    on exit."""

    def __enter__(self):
        global _GMSH_READY
        gmsh = self.gmsh = _import_gmsh()
        if _GMSH_READY:
            try:
                gmsh.clear()
            except Exception:  # finalised behind our back
                _GMSH_READY = False
        if not _GMSH_READY:
            import atexit
            import signal
            old = signal.getsignal(signal.SIGINT)
            gmsh.initialize(["", "-nopopup"], readConfigFiles=False)
            if old is not None:
                signal.signal(signal.SIGINT, old)
            gmsh.option.setNumber("General.Terminal", 0)
            if not _GMSH_DEFAULTS:
                _GMSH_DEFAULTS.update({o: gmsh.option.getNumber(o) for o in _GMSH_OPTIONS})
                atexit.register(_finalize_gmsh)
            _GMSH_READY = True
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.Verbosity", 0)
        for opt, val in _GMSH_DEFAULTS.items():
            gmsh.option.setNumber(opt, val)
        gmsh.model.add("block")
        return gmsh

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            # after an error gmsh 4.8 can stay "busy" and silently refuse later files: start afresh next time
            _finalize_gmsh()
            return False
        try:
            self.gmsh.clear()
        except Exception:
            _finalize_gmsh()
        return False


def _gmsh_cells(gmsh, source: str, dim: int):
    """Nodes and the single linear cell type of dimension `dim` of the current gmsh model: (node_tags, X (n, 3),
    cell_type, cell_tags, cells in gmsh node tags (nc, nv)); InputError on no cell, an unsupported or a mixed
    element type."""
    linear, what = (GMSH_LINEAR, ("triangles", "quadrangles")) if dim == 2 else \
        (GMSH_LINEAR_3D, ("tetrahedra", "hexahedra"))
    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    node_tags = np.asarray(node_tags, dtype=np.int64)
    X = np.asarray(coords, dtype=float).reshape(-1, 3)
    types, etags, enodes = gmsh.model.mesh.getElements(dim=dim)
    if len(types) == 0:
        raise InputError(f"{source}: the mesh has no {dim}D element (expected {what[0]} or {what[1]})")
    bad = [t for t in types if t not in linear]
    if bad:
        raise InputError(f"{source}: unsupported element type {GMSH_NAMES.get(bad[0], bad[0])!s} "
                         f"(gmsh type {bad[0]}); expected linear {what[0]} (P1) or {what[1]} (Q1)")
    if len(types) > 1:
        names = " and ".join(f"{GMSH_NAMES.get(t, t)} (gmsh type {t})" for t in types)
        raise InputError(f"{source}: mixed element types {names}; expected a single element type")
    cell_type = linear[types[0]]
    cell_tags = np.asarray(etags[0], dtype=np.int64)
    cells_t = np.asarray(enodes[0], dtype=np.int64).reshape(-1, _NV[cell_type])
    return node_tags, X, cell_type, cell_tags, cells_t


def _used_nodes(node_tags, cells_t):
    """Keep the nodes used by the cells, in gmsh node order: (pos: gmsh tag -> index in node_tags, used (n,)
    bool, new: index in node_tags -> used-node index or -1)."""
    pos = np.full(int(node_tags.max()) + 1, -1, dtype=np.int64)
    pos[node_tags] = np.arange(node_tags.size)
    used = np.zeros(node_tags.size, dtype=bool)
    used[pos[cells_t.ravel()]] = True
    new = -np.ones(node_tags.size, dtype=np.int64)
    new[used] = np.arange(used.sum())
    return pos, used, new


def _extract(gmsh, source: str) -> BlockMesh:
    """Arrays of the current gmsh model: 2D linear cells, used nodes, physical curves as tags."""
    node_tags, X, cell_type, cell_tags, cells_t = _gmsh_cells(gmsh, source, 2)
    if np.any(np.abs(X[:, 2]) > 1e-12 * max(1.0, np.abs(X[:, :2]).max())):
        raise InputError(f"{source}: nodes out of the z = 0 plane; expected a 2D mesh")
    # used nodes only, in gmsh node order
    pos, used, new = _used_nodes(node_tags, cells_t)
    points = X[used, :2].copy()
    cells = new[pos[cells_t]]
    node_ids = node_tags[used]
    # orientation: all clockwise -> flip (convention); mixed -> inverted elements
    A = _signed_areas(points, cells)
    if np.all(A < 0):
        cells = cells[:, ::-1].copy()
        A = -A
    neg = np.flatnonzero(A <= 0)
    if neg.size:
        raise InputError(f"{source}: element {cell_tags[neg[0]]} is inverted or degenerate "
                         f"(signed area {A[neg[0]]:.3g}); {neg.size} such element(s)")
    bedges, _ = boundary_from_cells(cells, source, lambda i: f"{int(node_ids[i])} (gmsh tag)")
    # physical curves -> tags (an edge in several physical curves gets the last one listed)
    tag_names = {}
    keys, vals = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    nn_ = np.int64(len(points))
    for dim, ptag in gmsh.model.getPhysicalGroups(dim=1):
        name = gmsh.model.getPhysicalName(dim, ptag) or f"curve{ptag}"
        tag_names[name] = int(ptag)
        for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, ptag):
            lt, _, ln = gmsh.model.mesh.getElements(1, ent)
            for t, nodes in zip(lt, ln):
                if t != 1:
                    continue
                nn = pos[np.asarray(nodes, dtype=np.int64).reshape(-1, 2)]
                ab = new[nn[np.all(used[nn], axis=1)]]
                keys.append(ab.min(axis=1) * nn_ + ab.max(axis=1))
                vals.append(np.full(len(ab), ptag, dtype=np.int64))
    keys, vals = np.concatenate(keys), np.concatenate(vals)
    bkeys = bedges.min(axis=1) * nn_ + bedges.max(axis=1)
    edge_tags = np.zeros(len(bedges), dtype=np.int64)
    if keys.size:
        order = np.argsort(keys, kind="stable")
        ks, vs = keys[order], vals[order]
        i = np.clip(np.searchsorted(ks, bkeys, side="right") - 1, 0, None)
        hit = ks[i] == bkeys
        edge_tags[hit] = vs[i[hit]]
    if np.any(edge_tags == 0):
        tag_names["untagged"] = 0
    return BlockMesh(points, cells.astype(np.int64), cell_type, bedges.astype(np.int64), edge_tags, tag_names,
                     source, node_ids=node_ids, cell_ids=cell_tags)


def _check_size(name, value):
    if value is None or not np.isfinite(value) or value <= 0:
        raise InputError(f"{name} = {value!r}: expected a mesh size > 0 [m]")


def mesh_rectangle(lx: float, ly: float, size: float, cell: str = "quad", name: str = "rectangle") -> BlockMesh:
    """Structured (transfinite) mesh of [0, lx] x [0, ly]: nx = max(1, round(lx/size)) divisions along x,
    ny likewise; quads (recombined) or triangles. Boundary tags bottom, right, top, left."""
    for k, v in (("lx", lx), ("ly", ly)):
        if not np.isfinite(v) or v <= 0:
            raise InputError(f"{name}.{k} = {v!r}: expected a length > 0 [m]")
    _check_size(f"{name}.mesh_size", size)
    if cell not in ("quad", "triangle"):
        raise InputError(f"{name}.cell = {cell!r}: expected 'quad' or 'triangle'")
    nx, ny = max(1, int(round(lx / size))), max(1, int(round(ly / size)))
    if (nx + 1) * (ny + 1) > 2_000_000:
        raise InputError(f"{name}.mesh_size = {size!r}: {nx} x {ny} elements is too many for one block")
    with _Gmsh() as gmsh:
        geo = gmsh.model.geo
        p = [geo.addPoint(0, 0, 0), geo.addPoint(lx, 0, 0), geo.addPoint(lx, ly, 0), geo.addPoint(0, ly, 0)]
        lines = [geo.addLine(p[i], p[(i + 1) % 4]) for i in range(4)]
        loop = geo.addCurveLoop(lines)
        surf = geo.addPlaneSurface([loop])
        for l, n in zip(lines, (nx, ny, nx, ny)):
            geo.mesh.setTransfiniteCurve(l, n + 1)
        geo.mesh.setTransfiniteSurface(surf, "Left", p)
        if cell == "quad":
            geo.mesh.setRecombine(2, surf)
        geo.synchronize()
        for l, nm in zip(lines, ("bottom", "right", "top", "left")):
            gmsh.model.setPhysicalName(1, gmsh.model.addPhysicalGroup(1, [l]), nm)
        gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [surf]), "block")
        gmsh.model.mesh.generate(2)
        mesh = _extract(gmsh, name)
    validate(mesh, name)
    return mesh


def mesh_polygon(vertices, size: float, cell: str = "triangle", name: str = "polygon") -> BlockMesh:
    """Unstructured mesh of a simple polygon (any orientation; normalised CCW). Tags side0.. (side i from
    vertex i to i+1 of the CCW polygon)."""
    V = np.asarray(vertices, dtype=float)
    if V.ndim != 2 or V.shape[1] != 2 or V.shape[0] < 3 or not np.all(np.isfinite(V)):
        raise InputError(f"{name}.vertices: expected at least 3 finite (x, y) points")
    _check_size(f"{name}.mesh_size", size)
    if cell not in ("quad", "triangle"):
        raise InputError(f"{name}.cell = {cell!r}: expected 'quad' or 'triangle'")
    A = 0.5 * np.sum(V[:, 0] * np.roll(V[:, 1], -1) - np.roll(V[:, 0], -1) * V[:, 1])
    if abs(A) <= 1e-14 * np.ptp(V) ** 2:
        raise InputError(f"{name}.vertices: the polygon has zero area")
    if A < 0:
        V = V[::-1].copy()
    n = len(V)
    # simple polygon: no two non-adjacent sides intersect
    for i in range(n):
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue
            if _segments_intersect(V[i], V[(i + 1) % n], V[j], V[(j + 1) % n]):
                raise InputError(f"{name}.vertices: sides {i} and {j} cross; expected a simple polygon")
    with _Gmsh() as gmsh:
        geo = gmsh.model.geo
        p = [geo.addPoint(x, y, 0, size) for x, y in V]
        lines = [geo.addLine(p[i], p[(i + 1) % n]) for i in range(n)]
        surf = geo.addPlaneSurface([geo.addCurveLoop(lines)])
        if cell == "quad":
            geo.mesh.setRecombine(2, surf)
        geo.synchronize()
        for i, l in enumerate(lines):
            gmsh.model.setPhysicalName(1, gmsh.model.addPhysicalGroup(1, [l]), f"side{i}")
        gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [surf]), "block")
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        if cell == "quad":
            # Blossom full-quad recombination (Mesh.Algorithm 8 segfaults in gmsh 4.8); if triangles remain,
            # remesh at twice the size and subdivide (all quads, about the requested size)
            gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 2)
        gmsh.model.mesh.generate(2)
        if cell == "quad" and len(gmsh.model.mesh.getElements(dim=2)[0]) > 1:
            gmsh.model.mesh.clear()
            gmsh.option.setNumber("Mesh.MeshSizeMax", 2 * size)
            gmsh.option.setNumber("Mesh.SubdivisionAlgorithm", 1)
            gmsh.model.mesh.generate(2)
        mesh = _extract(gmsh, name)
    validate(mesh, name)
    return mesh


def _segments_intersect(p1, p2, p3, p4) -> bool:
    def orient(a, b, c):
        return np.sign((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
    o1, o2, o3, o4 = orient(p1, p2, p3), orient(p1, p2, p4), orient(p3, p4, p1), orient(p3, p4, p2)
    return o1 * o2 < 0 and o3 * o4 < 0


def _open_file(gmsh, path: str, kind: str):
    if not os.path.isfile(path):
        raise InputError(f"{path}: {kind} file not found")
    if not os.access(path, os.R_OK):
        raise InputError(f"{path}: {kind} file not readable")
    try:
        gmsh.open(path)
    except Exception as e:  # gmsh raises a bare Exception with its log message
        raise InputError(f"{path}: gmsh could not read the {kind} file ({str(e).strip() or 'parse error'})") from None


def load_geo(path: str, size: float | None = None, cell: str | None = None) -> BlockMesh:
    """Mesh a gmsh .geo file (2D). `size` caps the element size; `cell = "quad"` recombines, `"triangle"`
    requires triangles, None keeps what the file asks for. Physical curves become boundary tags."""
    if cell not in (None, "quad", "triangle"):
        raise InputError(f"{path}: cell = {cell!r}: expected 'quad', 'triangle' or None")
    with _Gmsh() as gmsh:
        _open_file(gmsh, path, "geometry")
        if size is not None:
            _check_size(f"{path}: mesh_size", size)
            gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        if cell == "quad":
            gmsh.option.setNumber("Mesh.RecombineAll", 1)
            gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 2)
        try:
            gmsh.model.mesh.generate(2)
            if cell == "quad" and len(gmsh.model.mesh.getElements(dim=2)[0]) > 1:
                gmsh.option.setNumber("Mesh.SubdivisionAlgorithm", 1)
                gmsh.model.mesh.generate(2)
        except Exception as e:
            raise InputError(f"{path}: gmsh failed to mesh the geometry ({str(e).strip()})") from None
        mesh = _extract(gmsh, path)
    if cell is not None and mesh.cell_type != cell:
        raise InputError(f"{path}: the file produces {mesh.cell_type} elements (e.g. 'Recombine Surface'), "
                         f"but cell = {cell!r} was asked for")
    validate(mesh, path)
    return mesh


def load_msh(path: str) -> BlockMesh:
    """Read a gmsh .msh file (linear triangles or quadrangles; physical curves become tags)."""
    with _Gmsh() as gmsh:
        _open_file(gmsh, path, "mesh")
        mesh = _extract(gmsh, path)
    validate(mesh, path)
    return mesh


# ----------------------------------------------------------------------------- validation
def _check_arrays(mesh, source: str, gdim: int, cell_types: tuple):
    """Checks shared by validate and validate3d: points a float64 (n >= gdim + 1, gdim) array of finite
    coordinates, cell_type in cell_types, cells an int64 (nc >= 1, nv) array of existing nodes, every node used.
    Returns (points, cells, nv, nid, cid), nid/cid naming a node/element by its gmsh tag when known."""
    P, C = mesh.points, mesh.cells
    node_id = getattr(mesh, "node_ids", None)
    cell_id = getattr(mesh, "cell_ids", None)

    def nid(i):
        return f"{int(node_id[i])} (gmsh tag)" if node_id is not None else f"{int(i)}"

    def cid(i):
        return f"{int(cell_id[i])} (gmsh tag)" if cell_id is not None else f"{int(i)}"

    if not isinstance(P, np.ndarray) or P.ndim != 2 or P.shape[1] != gdim or P.shape[0] < gdim + 1 \
            or P.dtype != np.float64:
        raise InputError(f"{source}: points: expected a float64 (n >= {gdim + 1}, {gdim}) array, got "
                         f"{getattr(P, 'dtype', type(P).__name__)} {getattr(P, 'shape', '')}")
    if mesh.cell_type not in cell_types:
        raise InputError(f"{source}: cell_type = {mesh.cell_type!r}: expected "
                         f"{' or '.join(repr(t) for t in cell_types)}")
    nv = _NV[mesh.cell_type]
    if not isinstance(C, np.ndarray) or C.ndim != 2 or C.shape[1] != nv or C.shape[0] < 1 \
            or C.dtype != np.int64:
        raise InputError(f"{source}: cells: expected an int64 (nc >= 1, {nv}) array for {mesh.cell_type} "
                         f"cells, got {getattr(C, 'dtype', type(C).__name__)} {getattr(C, 'shape', '')}")
    bad = np.flatnonzero(~np.all(np.isfinite(P), axis=1))
    if bad.size:
        raise InputError(f"{source}: node {nid(bad[0])} has a non-finite coordinate")
    if C.min() < 0 or C.max() >= len(P):
        raise InputError(f"{source}: element {cid(int(np.flatnonzero((C < 0) | (C >= len(P)))[0] // nv))} "
                         f"refers to a node that does not exist")
    used = np.zeros(len(P), dtype=bool)
    used[C.ravel()] = True
    if not used.all():
        raise InputError(f"{source}: node {nid(np.flatnonzero(~used)[0])} is not used by any element")
    return P, C, nv, nid, cid


def _check_duplicate_nodes(P, source: str, nid) -> None:
    """InputError if two nodes are closer than 1e-12 x the bounding-box size."""
    size = float(np.ptp(P, axis=0).max())
    from scipy.spatial import cKDTree
    pairs = cKDTree(P).query_pairs(1e-12 * size, output_type="ndarray")
    if len(pairs):
        a, b = pairs[0]
        raise InputError(f"{source}: nodes {nid(a)} and {nid(b)} are duplicates (same position)")


def validate(mesh: BlockMesh, source: str = "mesh") -> None:
    """Reject meshes a FE block cannot use; the message names the element or node id.

    Checks: array shapes/dtypes, finite coordinates, cell indices in range, every node used,
    inverted or degenerate elements (area <= 1e-10 x mean), non-convex quads, duplicate nodes
    (closer than 1e-12 x bounding-box size), non-manifold edges and vertices, a single connected piece."""
    if isinstance(mesh, BlockMesh3D):
        return validate3d(mesh, source)
    P, C, nv, nid, cid = _check_arrays(mesh, source, 2, ("triangle", "quad"))
    for k in range(nv):
        for j in range(k + 1, nv):
            same = np.flatnonzero(C[:, k] == C[:, j])
            if same.size:
                raise InputError(f"{source}: element {cid(same[0])} repeats node {nid(C[same[0], k])}")
    A = _signed_areas(P, C)
    scale = np.abs(A).mean()
    bad = np.flatnonzero(A <= 1e-10 * scale)
    if bad.size:
        e = bad[0]
        what = "inverted (clockwise)" if A[e] < -1e-10 * scale else "degenerate (zero area)"
        raise InputError(f"{source}: element {cid(e)} is {what}; expected counter-clockwise elements of "
                         f"positive area")
    if nv == 4:
        d1 = P[C[:, [1, 2, 3, 0]]] - P[C]
        d0 = P[C] - P[C[:, [3, 0, 1, 2]]]
        cross = d0[..., 0] * d1[..., 1] - d0[..., 1] * d1[..., 0]
        bad = np.flatnonzero(np.any(cross <= 1e-12 * scale, axis=1))
        if bad.size:
            raise InputError(f"{source}: quadrangle {cid(bad[0])} is not convex")
    _check_duplicate_nodes(P, source, nid)
    bedges, _ = boundary_from_cells(C, source, nid)
    deg = np.bincount(bedges.ravel(), minlength=len(P))
    if np.any(deg > 2):
        raise InputError(f"{source}: non-manifold boundary at node {nid(np.flatnonzero(deg > 2)[0])} "
                         f"(touched by {deg.max()} boundary edges)")
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    rows = np.repeat(np.arange(len(C)), nv)
    inc = coo_matrix((np.ones(rows.size), (rows, C.ravel())), shape=(len(C), len(P))).tocsr()
    ncomp, label = connected_components(inc.T @ inc, directed=False)
    if ncomp > 1:
        e = int(np.flatnonzero(label[C[:, 0]] != label[C[0, 0]])[0])
        raise InputError(f"{source}: the mesh has {ncomp} disconnected pieces (element {cid(e)} is not connected "
                         f"to element {cid(0)}); expected one block")
    be, et = mesh.boundary_edges, mesh.edge_tags
    if not isinstance(be, np.ndarray) or not isinstance(et, np.ndarray) or be.dtype != np.int64 \
            or et.dtype != np.int64 or be.shape != bedges.shape or et.shape != (len(bedges),):
        raise InputError(f"{source}: boundary_edges/edge_tags: expected int64 arrays of shape {bedges.shape} and "
                         f"({len(bedges)},) matching the cells")
    if not np.array_equal(np.unique(be, axis=0), np.unique(bedges, axis=0)):
        raise InputError(f"{source}: boundary_edges do not match the edges used by a single element, oriented "
                         f"with the body on the left")


# ============================================================================= 3D blocks
# `BlockMesh3D`: points (n,3), cells (nc,4|8) positively oriented in the gmsh node order, cell_type
# "tetrahedron"|"hexahedron", boundary_faces (nf,3|4) ordered so that the right-hand-rule normal points out of
# the body, face_tags (nf,) (side index 0..5 of a generated hexahedral block, the gmsh physical surface tag for a
# read mesh, -1 untagged) and tag_names {name: tag}.
GMSH_NAMES.update({6: "6-node prism", 7: "5-node pyramid", 11: "10-node tetrahedron", 12: "27-node hexahedron",
                   17: "20-node hexahedron", 29: "20-node tetrahedron", 92: "64-node hexahedron"})
GMSH_LINEAR_3D = {4: "tetrahedron", 5: "hexahedron"}
NV_3D = {"tetrahedron": 4, "hexahedron": 8}
_NV = {"triangle": 3, "quad": 4, **NV_3D}  # nodes per linear cell
# outward faces of the reference cells (gmsh node order): right-hand rule normal points out of the cell
TET_FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], dtype=np.int64)
HEX_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]],
                     dtype=np.int64)
# sides of a hexahedral block given by its 8 corners, in the order of HEX_FACES (names for a box [0,lx]x[0,ly]x[0,lz])
HEX_SIDES = ("bottom", "top", "front", "right", "back", "left")
# tetrahedron / hexahedron that mirrors a cell (reverses its orientation) keeping its faces
_FLIP_3D = {"tetrahedron": np.array([0, 2, 1, 3]), "hexahedron": np.array([0, 3, 2, 1, 4, 7, 6, 5])}


def hex_shape_functions(xi: np.ndarray) -> np.ndarray:
    """N_a(xi) of the trilinear hexahedron: (k, 8)."""
    xi = np.atleast_2d(xi)
    return np.prod(1.0 + HEX_XI[None, :, :] * xi[:, None, :], axis=2) / 8.0


def gauss_hex(npt: int):
    """Tensor Gauss-Legendre rule on [-1,1]^3 with npt points per direction: (points (npt^3,3), weights)."""
    g, w = np.polynomial.legendre.leggauss(npt)
    X = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    W = np.einsum("i,j,k->ijk", w, w, w).ravel()
    return X, W


def cell_jacobians_3d(points: np.ndarray, cells: np.ndarray, cell_type: str, xi: np.ndarray | None = None):
    """det J per cell: tetrahedron (nc,) = 6 x signed volume; hexahedron (nc, k) at reference points xi
    (default: the 8 corners and the centre)."""
    P = points[cells]
    if cell_type == "tetrahedron":
        return np.einsum("ij,ij->i", np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), P[:, 3] - P[:, 0])
    if xi is None:
        xi = np.vstack([HEX_XI, np.zeros((1, 3))])
    J = np.einsum("cai,kaj->ckij", P, hex_shape_gradients(xi))
    return np.linalg.det(J)


def cell_volumes_3d(points: np.ndarray, cells: np.ndarray, cell_type: str) -> np.ndarray:
    """Signed cell volumes: tetrahedra exactly det/6, hexahedra by 2x2x2 Gauss (exact: det J is of degree
    2 per reference direction)."""
    if cell_type == "tetrahedron":
        return cell_jacobians_3d(points, cells, cell_type) / 6.0
    X, W = gauss_hex(2)
    return cell_jacobians_3d(points, cells, cell_type, X) @ W


@dataclass(eq=False)
class BlockMesh3D(_MeshArrays):
    """3D block mesh as plain arrays (contract in the section header above and docs/architecture.md).
    `node_ids`/`cell_ids` (optional) are the gmsh node/element tags, used only in error messages."""

    points: np.ndarray
    cells: np.ndarray
    cell_type: str
    boundary_faces: np.ndarray
    face_tags: np.ndarray
    tag_names: dict = field(default_factory=dict)
    source: str = "mesh"
    node_ids: np.ndarray | None = field(default=None, repr=False)
    cell_ids: np.ndarray | None = field(default=None, repr=False)

    gdim = 3
    _boundary = "boundary_faces"

    @classmethod
    def from_cells(cls, points, cells, cell_type: str | None = None, source: str = "mesh") -> "BlockMesh3D":
        """BlockMesh3D of given arrays (positively oriented cells): boundary faces from the cells, untagged (-1)."""
        P = np.asarray(points, dtype=np.float64)
        C = np.asarray(cells, dtype=np.int64)
        if cell_type is None:
            cell_type = "tetrahedron" if C.ndim == 2 and C.shape[1] == 4 else "hexahedron"
        bf, _ = boundary_faces_from_cells(C, cell_type, source)
        return cls(P, C, cell_type, bf.astype(np.int64), -np.ones(len(bf), dtype=np.int64), {"untagged": -1},
                   source)

    def translated(self, dx: float, dy: float, dz: float) -> "BlockMesh3D":
        """Same mesh (same node order and connectivity) moved by (dx, dy, dz)."""
        return self.transformed(np.eye(3), (dx, dy, dz))

    def transformed(self, R, c) -> "BlockMesh3D":
        """Same mesh with points x = R X + c for a rotation R (det R = +1 keeps the orientations)."""
        R = np.asarray(R, dtype=np.float64)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-12) or np.linalg.det(R) <= 0:
            raise InputError(f"{self.source}: R: expected a 3x3 rotation matrix (orthogonal, det = +1)")
        return BlockMesh3D(self.points @ R.T + np.asarray(c, dtype=np.float64).reshape(3), self.cells,
                           self.cell_type, self.boundary_faces, self.face_tags, dict(self.tag_names), self.source,
                           self.node_ids, self.cell_ids)

    def cell_volumes(self) -> np.ndarray:
        """Signed volume of each cell (positive for positively oriented cells)."""
        return cell_volumes_3d(self.points, self.cells, self.cell_type)

    def volume(self) -> float:
        return float(self.cell_volumes().sum())

    def face_areas(self) -> np.ndarray:
        """Area of each boundary face (bilinear quadrangles by 2x2 Gauss on the ruled surface)."""
        return face_quadrature(self.points, self.boundary_faces)[1].sum(axis=1)


def face_quadrature(points: np.ndarray, faces: np.ndarray):
    """Quadrature on boundary faces, exact for integrands linear on the face: (N (nf, k, nfv) shape function
    values, w (nf, k) weights x area element). Triangles: 3 points of the degree-2 rule; bilinear quadrangles:
    2x2 Gauss with the area element |x_,xi x x_,eta| of the ruled surface."""
    X = points[faces]
    if faces.shape[1] == 3:
        N = np.array([[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])
        A = 0.5 * np.linalg.norm(np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), axis=1)
        return np.broadcast_to(N, (len(faces), 3, 3)), np.repeat(A[:, None] / 3.0, 3, axis=1)
    g = 1 / np.sqrt(3.0)
    q = np.array([[-g, -g], [g, -g], [g, g], [-g, g]])
    s = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)
    N = 0.25 * (1 + s[None, :, 0] * q[:, None, 0]) * (1 + s[None, :, 1] * q[:, None, 1])  # (4 pts, 4 nodes)
    dxi = 0.25 * s[None, :, 0] * (1 + s[None, :, 1] * q[:, None, 1])
    deta = 0.25 * s[None, :, 1] * (1 + s[None, :, 0] * q[:, None, 0])
    t1 = np.einsum("ka,fai->fki", dxi, X)
    t2 = np.einsum("ka,fai->fki", deta, X)
    w = np.linalg.norm(np.cross(t1, t2), axis=2)
    return np.broadcast_to(N, (len(faces), 4, 4)), w


def boundary_faces_from_cells(cells: np.ndarray, cell_type: str, source: str = "mesh", node_name=str,
                              cell_name=str):
    """Faces used by exactly one cell, ordered as in that (positively oriented) cell so that their normal
    points out, and that cell's index. InputError on a face shared by more than 2 cells (non-manifold) or shared
    by 2 cells with the same orientation (overlapping or inverted elements)."""
    F = TET_FACES if cell_type == "tetrahedron" else HEX_FACES
    nfc, nfv = F.shape
    faces = cells[:, F].reshape(-1, nfv)
    key = np.sort(faces, axis=1)
    uniq, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    if np.any(cnt > 2):
        f = uniq[np.flatnonzero(cnt > 2)[0]]
        raise InputError(f"{source}: non-manifold mesh: the face with nodes "
                         f"{', '.join(node_name(a) for a in f)} is shared by {cnt.max()} elements "
                         f"(expected at most 2)")
    # orientation of each face occurrence: rotate the cycle so that its smallest node comes first; two
    # occurrences of an interior face must run in opposite directions (different node after the smallest)
    first = np.argmin(faces, axis=1)
    nxt = faces[np.arange(len(faces)), (first + 1) % nfv]
    twice = np.flatnonzero(cnt[inv] == 2)
    order = twice[np.argsort(inv[twice], kind="stable")]
    a, b = order[0::2], order[1::2]
    same = np.flatnonzero(nxt[a] == nxt[b])
    if same.size:
        i, j = a[same[0]] // nfc, b[same[0]] // nfc
        raise InputError(f"{source}: elements {cell_name(i)} and {cell_name(j)} overlap: their common face is "
                         f"oriented the same way in both (an inverted or folded element)")
    once = cnt[inv] == 1
    return faces[once], np.flatnonzero(once) // nfc


def _extract3d(gmsh, source: str) -> BlockMesh3D:
    """Arrays of the current gmsh model: 3D linear cells, used nodes, physical surfaces as face tags."""
    node_tags, X, cell_type, cell_tags, cells_t = _gmsh_cells(gmsh, source, 3)
    pos, used, new = _used_nodes(node_tags, cells_t)
    points = X[used].copy()
    cells = new[pos[cells_t]]
    node_ids = node_tags[used]
    # orientation: all negative -> mirror every cell (convention); mixed -> inverted elements (reported by
    # validate3d with the element id)
    detc = cell_jacobians_3d(points, cells, cell_type)
    centre = detc if detc.ndim == 1 else detc[:, -1]
    if np.all(centre < 0):
        cells = cells[:, _FLIP_3D[cell_type]].copy()
        centre = -centre
    neg = np.flatnonzero(centre <= 0)
    if neg.size:
        raise InputError(f"{source}: element {cell_tags[neg[0]]} (gmsh tag) is inverted or degenerate "
                         f"(det J {centre[neg[0]]:.3g} at its centre); {neg.size} such element(s)")
    bfaces, _ = boundary_faces_from_cells(cells, cell_type, source, lambda i: f"{int(node_ids[i])} (gmsh tag)",
                                          lambda i: f"{int(cell_tags[i])} (gmsh tag)")
    # physical surfaces -> face tags (a face in several physical surfaces gets the last one listed)
    tag_names = {}
    nfv = bfaces.shape[1]
    keys, vals = [np.zeros((0, nfv), np.int64)], [np.zeros(0, np.int64)]
    for dim, ptag in gmsh.model.getPhysicalGroups(dim=2):
        name = gmsh.model.getPhysicalName(dim, ptag) or f"surface{ptag}"
        tag_names[name] = int(ptag)
        for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, ptag):
            ft, _, fn = gmsh.model.mesh.getElements(2, ent)
            for t, nodes in zip(ft, fn):
                if t not in (2, 3) or (3 if t == 2 else 4) != nfv:
                    continue
                nn = pos[np.asarray(nodes, dtype=np.int64).reshape(-1, nfv)]
                nn = nn[np.all(nn >= 0, axis=1)]
                ok = np.all(used[nn], axis=1)
                keys.append(np.sort(new[nn[ok]], axis=1))
                vals.append(np.full(int(ok.sum()), ptag, dtype=np.int64))
    keys, vals = np.concatenate(keys), np.concatenate(vals)
    face_tags = -np.ones(len(bfaces), dtype=np.int64)
    if keys.size:
        bkeys = np.sort(bfaces, axis=1)
        allk = np.concatenate([keys, bkeys])
        _, inv = np.unique(allk, axis=0, return_inverse=True)
        inv = inv.ravel()
        tag_of = -np.ones(inv.max() + 1, dtype=np.int64)
        tag_of[inv[:len(keys)]] = vals  # later assignments win (fancy assignment keeps the last)
        face_tags = tag_of[inv[len(keys):]]
    if np.any(face_tags == -1):
        tag_names["untagged"] = -1
    return BlockMesh3D(points, cells.astype(np.int64), cell_type, bfaces.astype(np.int64), face_tags, tag_names,
                       source, node_ids=node_ids, cell_ids=cell_tags)


def _divisions(name, corners, size, divisions):
    """Divisions (n0, n1, n2) along the block edges 0->1, 0->3 and 0->4: given, or round(longest parallel
    edge / size), at least 1."""
    if (size is None) == (divisions is None):
        raise InputError(f"{name}: give exactly one of mesh_size or divisions")
    if divisions is not None:
        d = np.atleast_1d(np.asarray(divisions))
        if d.size == 1:
            d = np.repeat(d, 3)
        if d.shape != (3,) or not np.all(np.isfinite(d.astype(float))) or np.any(d != np.round(d)) or np.any(d < 1):
            raise InputError(f"{name}.divisions = {divisions!r}: expected an integer >= 1 or three of them")
        n = d.astype(np.int64)
    else:
        _check_size(f"{name}.mesh_size", size)
        edges = ([(0, 1), (3, 2), (4, 5), (7, 6)], [(0, 3), (1, 2), (4, 7), (5, 6)],
                 [(0, 4), (1, 5), (2, 6), (3, 7)])
        n = np.array([max(1, int(round(max(np.linalg.norm(corners[b] - corners[a]) for a, b in e) / size)))
                      for e in edges], dtype=np.int64)
    if int(np.prod(n + 1)) > 2_000_000:
        raise InputError(f"{name}: {n[0]} x {n[1]} x {n[2]} elements is too many for one block")
    return n


# Kuhn (Freudenthal) split of a hexahedron into 6 positively oriented tetrahedra around its diagonal 0-6: every
# face is cut along the diagonal from its local corner nearest node 0, so neighbouring hexahedra of a structured
# grid with the same local orientation are cut conformingly
KUHN_TETS = np.array([[0, 1, 2, 6], [0, 5, 1, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 4, 5, 6], [0, 7, 4, 6]],
                     dtype=np.int64)


def _split_hexes(hexmesh: BlockMesh3D, source: str) -> BlockMesh3D:
    """Tetrahedral mesh of a structured hexahedral mesh (same nodes, 6 tetrahedra per hexahedron, tet 6 e + k from
    hexahedron e); each boundary triangle inherits the tag of the boundary quadrangle it lies in. Raises
    RuntimeError if the split is not conforming (hexahedra with different local orientations)."""
    cells = hexmesh.cells[:, KUHN_TETS].reshape(-1, 4)
    bf, _ = boundary_faces_from_cells(cells, "tetrahedron", source)
    q = hexmesh.boundary_faces
    if len(bf) != 2 * len(q):
        raise RuntimeError(f"{source}: non-conforming tetrahedral split ({len(bf)} boundary triangles for "
                           f"{len(q)} boundary quadrangles)")
    # the 4 triangles spanned by 3 corners of each boundary quadrangle, keyed by their sorted nodes
    tri = q[:, [[0, 1, 2], [0, 2, 3], [0, 1, 3], [1, 2, 3]]].reshape(-1, 3)
    ttag = np.repeat(hexmesh.face_tags, 4)
    allk = np.concatenate([np.sort(tri, axis=1), np.sort(bf, axis=1)])
    _, inv, cnt = np.unique(allk, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    hit = inv[len(tri):]
    if np.any(cnt[hit] != 2):
        raise RuntimeError(f"{source}: a boundary triangle of the tetrahedral split is not in a boundary quadrangle")
    tag_of = np.empty(inv.max() + 1, dtype=np.int64)
    tag_of[inv[:len(tri)]] = ttag
    return BlockMesh3D(hexmesh.points, cells, "tetrahedron", bf.astype(np.int64), tag_of[hit],
                       dict(hexmesh.tag_names), source, node_ids=hexmesh.node_ids, cell_ids=None)


def mesh_hexahedron(corners, size: float | None = None, divisions=None, cell: str = "hexahedron",
                    structured: bool = True, name: str = "hexahedron") -> BlockMesh3D:
    """Mesh of the trilinear block spanned by 8 corners (gmsh hexahedron order, see check_hex_corners).

    Structured (transfinite) meshes have n0 x n1 x n2 hexahedra (recombined) whose nodes are the images of a
    regular grid by the trilinear map of the corners, or the 6 n0 n1 n2 tetrahedra of their Kuhn split (gmsh's own
    transfinite tetrahedra do not match its surface triangles in 4.8); `structured=False` (tetrahedra
    only) gives an unstructured Delaunay mesh of element size <= `size`. Faces are ruled (bilinear) surfaces.
    Face tags: side index 0..5 of HEX_SIDES (bottom 0-3-2-1, top 4-5-6-7, front 0-1-5-4, right 1-2-6-5,
    back 2-3-7-6, left 3-0-4-7)."""
    C = check_hex_corners(corners, name)
    if cell not in ("hexahedron", "tetrahedron"):
        raise InputError(f"{name}.cell = {cell!r}: expected 'hexahedron' or 'tetrahedron'")
    if not structured:
        if cell == "hexahedron":
            raise InputError(f"{name}: unstructured meshes are tetrahedral; expected cell = 'tetrahedron' or "
                             f"structured = true")
        if size is None or divisions is not None:
            raise InputError(f"{name}: an unstructured mesh needs mesh_size (and no divisions)")
        _check_size(f"{name}.mesh_size", size)
        n = None
    else:
        n = _divisions(name, C, size, divisions)
    with _Gmsh() as gmsh:
        geo = gmsh.model.geo
        p = [geo.addPoint(*c, size if size is not None else 0.0) for c in C]
        lines = {}

        def line(a, b):
            if (b, a) in lines:
                return -lines[(b, a)]
            if (a, b) not in lines:
                lines[(a, b)] = geo.addLine(p[a], p[b])
            return lines[(a, b)]

        surfs = []
        for f in HEX_FACES:
            loop = geo.addCurveLoop([line(f[i], f[(i + 1) % 4]) for i in range(4)])
            surfs.append(geo.addSurfaceFilling([loop]))
        vol = geo.addVolume([geo.addSurfaceLoop(surfs)])
        if structured:
            along = {(0, 1): 0, (2, 3): 0, (4, 5): 0, (6, 7): 0, (0, 3): 1, (1, 2): 1, (4, 7): 1, (5, 6): 1,
                     (0, 4): 2, (1, 5): 2, (2, 6): 2, (3, 7): 2}  # edge (sorted corners) -> direction
            for (a, b), tag in lines.items():
                geo.mesh.setTransfiniteCurve(tag, int(n[along[(min(a, b), max(a, b))]]) + 1)
            for s, f in zip(surfs, HEX_FACES):
                geo.mesh.setTransfiniteSurface(s, "Left", [p[i] for i in f])
                geo.mesh.setRecombine(2, s)
            geo.mesh.setTransfiniteVolume(vol, p)
            geo.mesh.setRecombine(3, vol)
        geo.synchronize()
        for i, (s, nm) in enumerate(zip(surfs, HEX_SIDES)):
            gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [s], i + 1), nm)
        gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, [vol]), "block")
        if not structured:
            gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.model.mesh.generate(3)
        mesh = _extract3d(gmsh, name)
    if mesh.cell_type != ("hexahedron" if structured else "tetrahedron"):
        raise RuntimeError(f"{name}: gmsh produced {mesh.cell_type} elements")
    mesh.face_tags = np.where(mesh.face_tags > 0, mesh.face_tags - 1, -1)
    mesh.tag_names = {nm: i for i, nm in enumerate(HEX_SIDES)}
    if np.any(mesh.face_tags < 0):
        mesh.tag_names["untagged"] = -1
    if structured and cell == "tetrahedron":
        mesh = _split_hexes(mesh, name)
    validate3d(mesh, name)
    return mesh


def mesh_box(lx: float, ly: float, lz: float, size: float | None = None, divisions=None,
             cell: str = "hexahedron", structured: bool = True, name: str = "box") -> BlockMesh3D:
    """Mesh of [0,lx]x[0,ly]x[0,lz] (see mesh_hexahedron); face tags bottom (z=0) 0, top 1, front (y=0) 2,
    right (x=lx) 3, back 4, left 5."""
    for k, v in (("lx", lx), ("ly", ly), ("lz", lz)):
        if v is None or not np.isfinite(v) or v <= 0:
            raise InputError(f"{name}.{k} = {v!r}: expected a length > 0 [m]")
    return mesh_hexahedron(box_corners(lx, ly, lz), size, divisions, cell, structured, name)


def load_msh3d(path: str) -> BlockMesh3D:
    """Read a gmsh .msh file of linear tetrahedra or hexahedra (physical surfaces become face tags)."""
    with _Gmsh() as gmsh:
        _open_file(gmsh, path, "mesh")
        mesh = _extract3d(gmsh, path)
    validate3d(mesh, path)
    return mesh


def load_geo3d(path: str, size: float | None = None, cell: str | None = None) -> BlockMesh3D:
    """Mesh a gmsh .geo file in 3D (the file chooses tetrahedra, or hexahedra by transfinite + Recombine);
    `size` caps the element size, `cell` if given must match what the file produces."""
    if cell not in (None, "tetrahedron", "hexahedron"):
        raise InputError(f"{path}: cell = {cell!r}: expected 'tetrahedron', 'hexahedron' or None")
    with _Gmsh() as gmsh:
        _open_file(gmsh, path, "geometry")
        if size is not None:
            _check_size(f"{path}: mesh_size", size)
            gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        try:
            gmsh.model.mesh.generate(3)
        except Exception as e:
            raise InputError(f"{path}: gmsh failed to mesh the geometry ({str(e).strip()})") from None
        mesh = _extract3d(gmsh, path)
    if cell is not None and mesh.cell_type != cell:
        raise InputError(f"{path}: the file produces {mesh.cell_type} elements, but cell = {cell!r} was asked for")
    validate3d(mesh, path)
    return mesh


def validate3d(mesh: BlockMesh3D, source: str = "mesh") -> None:
    """Reject 3D meshes a FE block cannot use; the message names the element or node id.

    Checks: array shapes/dtypes, finite coordinates, cell indices in range, every node used, repeated nodes in
    an element, inverted or degenerate elements (det J <= 1e-10 x mean at a tetrahedron, at the 8 corners and
    the centre of a hexahedron), duplicate nodes (closer than 1e-12 x bounding-box size), faces shared by more
    than 2 elements or with the same orientation in both, a single face-connected piece, a manifold boundary
    (each boundary edge in exactly 2 boundary faces, one fan of boundary faces around each boundary node), and
    boundary_faces/face_tags consistent with the cells."""
    P, C, nv, nid, cid = _check_arrays(mesh, source, 3, ("tetrahedron", "hexahedron"))
    Cs = np.sort(C, axis=1)
    same = np.flatnonzero(np.any(Cs[:, 1:] == Cs[:, :-1], axis=1))
    if same.size:
        e = same[0]
        k = int(np.flatnonzero(Cs[e, 1:] == Cs[e, :-1])[0])
        raise InputError(f"{source}: element {cid(e)} repeats node {nid(Cs[e, k])}")
    dj = cell_jacobians_3d(P, C, mesh.cell_type)
    dj = dj.reshape(len(C), -1)
    scale = np.abs(dj).mean()
    worst = dj.min(axis=1)
    bad = np.flatnonzero(worst <= 1e-10 * scale)
    if bad.size:
        e = bad[0]
        what = "inverted (negative orientation)" if worst[e] < -1e-10 * scale else "degenerate (zero volume)"
        where = "" if mesh.cell_type == "tetrahedron" else \
            f" at {'its centre' if np.argmin(dj[e]) == 8 else f'its corner {int(np.argmin(dj[e]))}'}"
        raise InputError(f"{source}: element {cid(e)} is {what}{where}; expected positively oriented elements "
                         f"(gmsh node order) of positive volume")
    _check_duplicate_nodes(P, source, nid)
    bfaces, _ = boundary_faces_from_cells(C, mesh.cell_type, source, nid, cid)
    # one piece, connected through faces
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    F = TET_FACES if mesh.cell_type == "tetrahedron" else HEX_FACES
    key = np.sort(C[:, F].reshape(-1, F.shape[1]), axis=1)
    _, finv = np.unique(key, axis=0, return_inverse=True)
    finv = finv.ravel()
    owner = np.repeat(np.arange(len(C)), len(F))
    inc = coo_matrix((np.ones(owner.size), (owner, finv)), shape=(len(C), finv.max() + 1)).tocsr()
    ncomp, label = connected_components(inc @ inc.T, directed=False)
    if ncomp > 1:
        e = int(np.flatnonzero(label != label[0])[0])
        raise InputError(f"{source}: the mesh has {ncomp} pieces not connected through faces (element {cid(e)} "
                         f"is not connected to element {cid(0)}); expected one block")
    # manifold boundary: every boundary edge in exactly 2 boundary faces ...
    nfv = bfaces.shape[1]
    ea = bfaces.ravel()
    eb = np.roll(bfaces, -1, axis=1).ravel()
    ekey = np.sort(np.stack([ea, eb], axis=1), axis=1)
    uk, einv, ecnt = np.unique(ekey, axis=0, return_inverse=True, return_counts=True)
    einv = einv.ravel()
    if np.any(ecnt != 2):
        a, b = uk[np.flatnonzero(ecnt != 2)[0]]
        raise InputError(f"{source}: non-manifold boundary at the edge between nodes {nid(a)} and {nid(b)} "
                         f"(in {ecnt[ecnt != 2][0]} boundary faces, expected 2)")
    # ... and one fan of boundary faces around each boundary node: incidences (node, face) linked across the
    # boundary edges at that node must form one connected component per node
    fidx = np.repeat(np.arange(len(bfaces)), nfv)
    inc_id = np.arange(fidx.size).reshape(-1, nfv)  # incidence id of (face f, corner k)
    order = np.argsort(einv, kind="stable")
    e0, e1 = order[0::2], order[1::2]  # the two occurrences (face corner k -> k+1) of each boundary edge
    f0, k0 = e0 // nfv, e0 % nfv
    f1, k1 = e1 // nfv, e1 % nfv
    # edge occurrence (f, k) joins corners k and k+1 of face f, i.e. nodes u -> v; link the incidences of u
    # (and of v) in the two faces that share the edge
    u = bfaces[f0, k0]
    a0, b0 = inc_id[f0, k0], inc_id[f0, (k0 + 1) % nfv]
    u_first = bfaces[f1, k1] == u
    a1 = np.where(u_first, inc_id[f1, k1], inc_id[f1, (k1 + 1) % nfv])
    b1 = np.where(u_first, inc_id[f1, (k1 + 1) % nfv], inc_id[f1, k1])
    rows = np.concatenate([a0, b0])
    cols = np.concatenate([a1, b1])
    g = coo_matrix((np.ones(rows.size), (rows, cols)), shape=(fidx.size, fidx.size))
    ncomp, lab = connected_components(g, directed=False)
    nodes = bfaces.ravel()
    comps_per_node = np.bincount(nodes[np.unique(lab, return_index=True)[1]], minlength=len(P))
    if np.any(comps_per_node > 1):
        raise InputError(f"{source}: non-manifold boundary at node {nid(np.flatnonzero(comps_per_node > 1)[0])} "
                         f"(the boundary surface touches itself there)")
    bf, ft = mesh.boundary_faces, mesh.face_tags
    if not isinstance(bf, np.ndarray) or not isinstance(ft, np.ndarray) or bf.dtype != np.int64 \
            or ft.dtype != np.int64 or bf.shape != bfaces.shape or ft.shape != (len(bfaces),):
        raise InputError(f"{source}: boundary_faces/face_tags: expected int64 arrays of shape {bfaces.shape} and "
                         f"({len(bfaces)},) matching the cells")
    canon_given = _canonical_faces(bf)
    canon_cells = _canonical_faces(bfaces)
    if not np.array_equal(np.unique(canon_given, axis=0), np.unique(canon_cells, axis=0)):
        raise InputError(f"{source}: boundary_faces do not match the faces used by a single element, ordered "
                         f"with the normal pointing out of the body")


def _canonical_faces(f: np.ndarray) -> np.ndarray:
    """Each face cycle rotated so that its smallest node comes first (orientation kept)."""
    k = np.argmin(f, axis=1)
    idx = (k[:, None] + np.arange(f.shape[1])[None, :]) % f.shape[1]
    return np.take_along_axis(f, idx, axis=1)
