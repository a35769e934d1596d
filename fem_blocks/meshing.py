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


@dataclass
class BlockMesh:
    points: np.ndarray
    cells: np.ndarray
    cell_type: str
    boundary_edges: np.ndarray
    edge_tags: np.ndarray
    tag_names: dict = field(default_factory=dict)
    source: str = "mesh"

    @property
    def n_nodes(self) -> int:
        return int(self.points.shape[0])

    def boundary_nodes(self) -> np.ndarray:
        return np.unique(self.boundary_edges)

    def translated(self, dx: float, dy: float) -> "BlockMesh":
        return BlockMesh(self.points + np.array([dx, dy]), self.cells, self.cell_type, self.boundary_edges,
                         self.edge_tags, dict(self.tag_names), self.source)

    def cell_areas(self) -> np.ndarray:
        return _signed_areas(self.points, self.cells)

    def area(self) -> float:
        return float(self.cell_areas().sum())

    def bbox(self):
        return (*self.points.min(axis=0), *self.points.max(axis=0))


def _signed_areas(points, cells) -> np.ndarray:
    """Shoelace formula per cell (positive when counter-clockwise)."""
    x = points[cells, 0]
    y = points[cells, 1]
    return 0.5 * np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)


def boundary_from_cells(cells: np.ndarray, source: str = "mesh"):
    """Edges used by exactly one cell, oriented as in that (CCW) cell; error on non-manifold edges."""
    nv = cells.shape[1]
    e = np.stack([cells, np.roll(cells, -1, axis=1)], axis=2).reshape(-1, 2)
    key = np.sort(e, axis=1)
    uniq, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    if np.any(cnt > 2):
        a, b = uniq[np.flatnonzero(cnt > 2)[0]]
        raise InputError(f"{source}: non-manifold mesh: edge between nodes {a} and {b} is shared by "
                         f"{cnt.max()} elements (expected at most 2)")
    once = cnt[inv] == 1
    return e[once], np.flatnonzero(once) // nv


# ----------------------------------------------------------------------------- gmsh helpers
_GMSH_READY = False


class _Gmsh:
    """Context manager: initialise gmsh once per process, a fresh model per use, quiet."""

    def __enter__(self):
        import gmsh
        self.gmsh = gmsh
        global _GMSH_READY
        if not _GMSH_READY:
            gmsh.initialize(["", "-nopopup"], readConfigFiles=False, interruptible=False) \
                if "interruptible" in gmsh.initialize.__code__.co_varnames else gmsh.initialize(["", "-nopopup"])
            _GMSH_READY = True
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.Verbosity", 0)
        gmsh.clear()
        for opt, val in (("Mesh.MeshSizeMax", 1e22), ("Mesh.RecombineAll", 0), ("Mesh.RecombinationAlgorithm", 1),
                         ("Mesh.SubdivisionAlgorithm", 0), ("Mesh.Algorithm", 6)):
            gmsh.option.setNumber(opt, val)
        gmsh.model.add("block")
        return gmsh

    def __exit__(self, *exc):
        self.gmsh.clear()
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
        raise InputError(f"{source}: mixed triangles and quadrangles; expected a single element type")
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
    bedges, _ = boundary_from_cells(cells, source)
    # physical curves -> tags
    tag_names = {}
    key_to_tag = {}
    for dim, ptag in gmsh.model.getPhysicalGroups(dim=1):
        name = gmsh.model.getPhysicalName(dim, ptag) or f"curve{ptag}"
        tag_names[name] = int(ptag)
        for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, ptag):
            lt, _, ln = gmsh.model.mesh.getElements(1, ent)
            for t, nodes in zip(lt, ln):
                if t != 1:
                    continue
                nn = np.asarray(nodes, dtype=np.int64).reshape(-1, 2)
                ok = np.all(used[pos[nn]], axis=1)
                for a, b in new[pos[nn[ok]]]:
                    key_to_tag[(min(a, b), max(a, b))] = int(ptag)
    edge_tags = np.array([key_to_tag.get((min(a, b), max(a, b)), 0) for a, b in bedges], dtype=np.int64)
    if np.any(edge_tags == 0):
        tag_names["untagged"] = 0
    mesh = BlockMesh(points, cells.astype(np.int64), cell_type, bedges.astype(np.int64), edge_tags, tag_names,
                     source)
    mesh.node_ids = node_ids  # gmsh node tags, to name nodes in error messages
    mesh.cell_ids = cell_tags
    return mesh


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
        geo.mesh.setTransfiniteSurface(surf, "Left" if cell == "triangle" else "Left", p)
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
            # Blossom full-quad recombination (Mesh.Algorithm 8 segfaults in gmsh 4.8); if triangles remain, subdivide (all quads, half size)
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
    """Mesh a gmsh .geo file (2D). `size` caps the element size; `cell = "quad"` recombines."""
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
    (closer than 1e-10 x block size), non-manifold edges and vertices, a single connected piece."""
    P, C = mesh.points, mesh.cells
    node_id = getattr(mesh, "node_ids", None)
    cell_id = getattr(mesh, "cell_ids", None)

    def nid(i):
        return int(node_id[i]) if node_id is not None else int(i)

    def cid(i):
        return int(cell_id[i]) if cell_id is not None else int(i)

    if not isinstance(P, np.ndarray) or P.ndim != 2 or P.shape[1] != 2 or P.shape[0] < 3:
        raise InputError(f"{source}: points: expected an (n >= 3, 2) array")
    if mesh.cell_type not in ("triangle", "quad"):
        raise InputError(f"{source}: cell_type = {mesh.cell_type!r}: expected 'triangle' or 'quad'")
    nv = 3 if mesh.cell_type == "triangle" else 4
    if not isinstance(C, np.ndarray) or C.ndim != 2 or C.shape[1] != nv or C.shape[0] < 1 \
            or not np.issubdtype(C.dtype, np.integer):
        raise InputError(f"{source}: cells: expected an integer (nc >= 1, {nv}) array")
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
    pairs = cKDTree(P).query_pairs(1e-10 * size, output_type="ndarray")
    if len(pairs):
        a, b = pairs[0]
        raise InputError(f"{source}: nodes {nid(a)} and {nid(b)} are duplicates (same position)")
    bedges, _ = boundary_from_cells(C, source)
    deg = np.bincount(bedges.ravel(), minlength=len(P))
    if np.any(deg > 2):
        raise InputError(f"{source}: non-manifold boundary at node {nid(np.flatnonzero(deg > 2)[0])} "
                         f"(touched by {deg.max()} boundary edges)")
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    rows = np.repeat(np.arange(len(C)), nv)
    inc = coo_matrix((np.ones(rows.size), (rows, C.ravel())), shape=(len(C), len(P))).tocsr()
    ncomp, _ = connected_components(inc.T @ inc, directed=False)
    if ncomp > 1:
        raise InputError(f"{source}: the mesh has {ncomp} disconnected pieces; expected one block")
    if mesh.boundary_edges.shape != bedges.shape or mesh.edge_tags.shape != (len(mesh.boundary_edges),):
        raise InputError(f"{source}: boundary_edges/edge_tags do not match the cells")
