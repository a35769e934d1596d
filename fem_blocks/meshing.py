"""Block meshes with gmsh, returned as plain arrays (`BlockMesh`), and mesh validation.

A block type is meshed once (gmsh is not translation-stable: the same rectangle meshed at two
offsets can give different node counts), then instanced by translation and rotation.

`BlockMesh`: points (n,2), cells (nc,3|4) counter-clockwise, cell_type "triangle"|"quad",
boundary_edges (ne,2) oriented with the body on the left (outer loop CCW, holes CW), edge_tags
(ne,) and tag_names {name: id} from gmsh physical curves ("untagged" = 0 for the rest).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError

GMSH_LINEAR = {2: "triangle", 3: "quad"}
GMSH_NAMES = {1: "2-node line", 2: "3-node triangle", 3: "4-node quadrangle", 4: "4-node tetrahedron",
              5: "8-node hexahedron", 8: "3-node line", 9: "6-node triangle", 10: "9-node quadrangle",
              15: "point", 16: "8-node quadrangle", 20: "9-node incomplete triangle", 21: "10-node triangle"}


@dataclass(eq=False)
class BlockMesh:
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

    @classmethod
    def from_cells(cls, points, cells, cell_type: str | None = None, source: str = "mesh") -> "BlockMesh":
        """BlockMesh of given arrays: boundary edges from the cells, all untagged (tag 0)."""
        P = np.asarray(points, dtype=np.float64)
        C = np.asarray(cells, dtype=np.int64)
        if cell_type is None:
            cell_type = "triangle" if C.ndim == 2 and C.shape[1] == 3 else "quad"
        be, _ = boundary_from_cells(C, source)
        return cls(P, C, cell_type, be.astype(np.int64), np.zeros(len(be), dtype=np.int64), {"untagged": 0}, source)

    @property
    def n_nodes(self) -> int:
        return int(self.points.shape[0])

    def boundary_nodes(self) -> np.ndarray:
        """Sorted unique node indices on the boundary (int64)."""
        return np.unique(np.asarray(self.boundary_edges, dtype=np.int64))

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

    def bbox(self):
        """(xmin, ymin, xmax, ymax)."""
        return (*self.points.min(axis=0), *self.points.max(axis=0))


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


def _extract(gmsh, source: str) -> BlockMesh:
    """Arrays of the current gmsh model: 2D linear cells, used nodes, physical curves as tags."""
    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    node_tags = np.asarray(node_tags, dtype=np.int64)
    X = np.asarray(coords, dtype=float).reshape(-1, 3)
    types, etags, enodes = gmsh.model.mesh.getElements(dim=2)
    if len(types) == 0:
        raise InputError(f"{source}: the mesh has no 2D element (expected triangles or quadrangles)")
    bad = [t for t in types if t not in GMSH_LINEAR]
    if bad:
        raise InputError(f"{source}: unsupported element type {GMSH_NAMES.get(bad[0], bad[0])!s} "
                         f"(gmsh type {bad[0]}); expected linear triangles (P1) or quadrangles (Q1)")
    if len(types) > 1:
        names = " and ".join(f"{GMSH_NAMES.get(t, t)} (gmsh type {t})" for t in types)
        raise InputError(f"{source}: mixed element types {names}; expected a single element type")
    cell_type = GMSH_LINEAR[types[0]]
    nv = 3 if cell_type == "triangle" else 4
    cell_tags = np.asarray(etags[0], dtype=np.int64)
    cells_t = np.asarray(enodes[0], dtype=np.int64).reshape(-1, nv)
    if np.any(np.abs(X[:, 2]) > 1e-12 * max(1.0, np.abs(X[:, :2]).max())):
        raise InputError(f"{source}: nodes out of the z = 0 plane; expected a 2D mesh")
    # used nodes only, in gmsh node order
    pos = np.full(int(node_tags.max()) + 1, -1, dtype=np.int64)
    pos[node_tags] = np.arange(node_tags.size)
    used = np.zeros(node_tags.size, dtype=bool)
    used[pos[cells_t.ravel()]] = True
    new = -np.ones(node_tags.size, dtype=np.int64)
    new[used] = np.arange(used.sum())
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
def validate(mesh: BlockMesh, source: str = "mesh") -> None:
    """Reject meshes a FE block cannot use; the message names the element or node id.

    Checks: array shapes/dtypes, finite coordinates, cell indices in range, every node used,
    inverted or degenerate elements (area <= 1e-10 x mean), non-convex quads, duplicate nodes
    (closer than 1e-12 x bounding-box size), non-manifold edges and vertices, a single connected piece."""
    P, C = mesh.points, mesh.cells
    node_id = getattr(mesh, "node_ids", None)
    cell_id = getattr(mesh, "cell_ids", None)

    def nid(i):
        return f"{int(node_id[i])} (gmsh tag)" if node_id is not None else f"{int(i)}"

    def cid(i):
        return f"{int(cell_id[i])} (gmsh tag)" if cell_id is not None else f"{int(i)}"

    if not isinstance(P, np.ndarray) or P.ndim != 2 or P.shape[1] != 2 or P.shape[0] < 3 \
            or P.dtype != np.float64:
        raise InputError(f"{source}: points: expected a float64 (n >= 3, 2) array, got "
                         f"{getattr(P, 'dtype', type(P).__name__)} {getattr(P, 'shape', '')}")
    if mesh.cell_type not in ("triangle", "quad"):
        raise InputError(f"{source}: cell_type = {mesh.cell_type!r}: expected 'triangle' or 'quad'")
    nv = 3 if mesh.cell_type == "triangle" else 4
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
    size = float(np.ptp(P, axis=0).max())
    from scipy.spatial import cKDTree
    pairs = cKDTree(P).query_pairs(1e-12 * size, output_type="ndarray")
    if len(pairs):
        a, b = pairs[0]
        raise InputError(f"{source}: nodes {nid(a)} and {nid(b)} are duplicates (same position)")
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
