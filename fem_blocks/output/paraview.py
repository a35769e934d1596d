"""ParaView output of the bodies: one merged unstructured grid per frame, in a .pvd series.

Points are the *reference* positions of every deformable node and rigid vertex; the point field
`displacement` (current - reference) lets ParaView's "Warp By Vector" show the deformed state. Co-rotational
bodies (docs/method.md §7): displacement = R (X + q) + c - (R0 X + c0), velocity R u, stress R σ(q) Rᵀ with the
current frame R (q holds the small deformation only).
Point data: displacement, velocity (global frame). Cell data: Cauchy stress (sxx, syy, sxy),
von Mises stress (deformable cells; 0 on rigid polygons), body id, body kind (0 deformable,
1 rigid). Fields are computed per block type with batched array operations (no per-node loop).
`BodiesWriter3D`: the same for 3D bodies (Voigt stress (sxx, syy, szz, syz, sxz, sxy), 3D von Mises).

On N MPI ranks (comm given; every rank calls write at the same steps): rank p writes the piece of its bodies as
`blocks_<frame>_p<p>.vtu`, the grid the serial writer makes of those bodies alone (the same arrays, per body the same
points, cells and values, bitwise; a rank with no body writes no piece); rank 0 writes `blocks_<frame>.pvtu` over the
pieces and `blocks.pvd` over the .pvtu files (pvd.SeriesWriter). A rank's bodies (`piece_of`): once the simulation's
bodies are partitioned (the contact step's partition, dynamics.Simulation.own_bodies) those it owns, the only ones
whose state it holds when the bodies are stepped per rank (dynamics.py, "Bodies stepped per rank"); before (the
first frame) the block [p nb / N, (p + 1) nb / N) (integer division, nb bodies), every rank holding every body then.
The contact writer (contacts.py) writes each rank's own contacts the same way.
"""
from __future__ import annotations

import numpy as np

from ..fem_backend import von_mises
from .pvd import SeriesWriter


def piece_bodies(n_bodies: int, comm) -> range:
    """The bodies whose piece this rank writes: [p nb / N, (p + 1) nb / N) on rank p of N (all on one process)."""
    if comm is None or comm.Get_size() == 1:
        return range(n_bodies)
    p, n = comm.Get_rank(), comm.Get_size()
    return range(p * n_bodies // n, (p + 1) * n_bodies // n)


def piece_owner(n_bodies: int, size: int) -> np.ndarray:
    """The rank whose piece holds each body (piece_bodies on each of `size` ranks): the last p with p nb / N <= i."""
    starts = np.arange(size, dtype=np.int64) * n_bodies // size
    return np.searchsorted(starts, np.arange(n_bodies, dtype=np.int64), side="right").astype(np.int64) - 1


def piece_of(source, n_bodies: int, comm) -> np.ndarray:
    """The bodies (increasing indices) whose piece this rank writes (module docstring): its own bodies when `source`
    (a Simulation) has them partitioned (`own_bodies()` with a communicator), else `piece_bodies`."""
    own = getattr(source, "own_bodies", None)
    if comm is not None and own is not None:
        _, mask, part = own()
        if part is not None:
            return np.flatnonzero(mask)
    return np.asarray(piece_bodies(n_bodies, comm), dtype=np.int64)


def _follow(writer, source, n_bodies: int) -> None:
    """Rebuild `writer`'s static grid when the bodies of its piece changed (`piece_of`; at the first frame after the
    partition)."""
    mine = piece_of(source, n_bodies, writer.comm)
    if not np.array_equal(mine, writer.mine):
        writer.mine = mine
        writer._build_static()


# Voigt order of the stresses: 2D (xx, yy, xy), 3D (xx, yy, zz, yz, xz, xy)
_VOIGT = {2: ((0, 0), (1, 1), (0, 1)), 3: ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))}


def _rotate_vectors(V: np.ndarray, R: np.ndarray) -> np.ndarray:
    """V (k, n, d) in type frames, R (k, d, d) -> global vectors (k, n, d): v = R v_type."""
    return np.einsum("kij,knj->kni", R, V)


def rotate_voigt(s: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Stresses s (k, nc, 3 | 6) in Voigt order (2D xx, yy, xy; 3D xx, yy, zz, yz, xz, xy) in the type frames of
    k bodies with rotations R (k, d, d) -> global Voigt stresses: sigma = R sigma_type R^T."""
    d = R.shape[-1]
    T = np.empty(s.shape[:2] + (d, d))
    for c, (i, j) in enumerate(_VOIGT[d]):
        T[..., i, j] = T[..., j, i] = s[..., c]
    Tg = np.einsum("kij,kcjl,kml->kcim", R, T, R)
    return np.stack([Tg[..., i, j] for i, j in _VOIGT[d]], -1)


def _type_fields(bodies, members, offs, block_type, disp, vel, stress: bool):
    """Displacements and velocities (global frame: v = R v_type per node) of the bodies `members` of one block
    type, written into the rows offs[i] + node of disp / vel (n_points, d); returns their global Voigt cell
    stresses (k, nc, 3 | 6) (stress operator of the type applied to all q at once, then R sigma R^T), or None
    when stress is False."""
    d = disp.shape[1]
    k, n = len(members), block_type.mesh.points.shape[0]
    R = np.stack([bodies[b].R for b in members])
    Qc = np.column_stack([bodies[b].q for b in members])  # (d n, k), type frame
    U = np.stack([bodies[b].u for b in members]).reshape(k, n, d)
    idx = (np.asarray(offs)[:, None] + np.arange(n)[None, :]).ravel()
    D = _rotate_vectors(Qc.T.reshape(k, n, d), R)
    f = np.array([getattr(bodies[b], "framed", False) for b in members], dtype=bool)
    if f.any():  # co-rotational bodies: current R (X + q) + c - reference (R0 X + c0)
        X = block_type.mesh.points
        R0 = np.stack([bodies[b].R0 for b in members])[f]
        C = np.stack([bodies[b].position - bodies[b].position0 for b in members])[f]
        D[f] = (_rotate_vectors(X[None] + Qc.T.reshape(k, n, d)[f], R[f])
                - _rotate_vectors(np.broadcast_to(X, (int(f.sum()), n, d)), R0) + C[:, None, :])
    disp[idx] = D.reshape(-1, d)
    vel[idx] = _rotate_vectors(U, R).reshape(-1, d)
    if not stress:
        return None
    S = block_type.stress_operator @ Qc  # (nv nc, k), nv = 3 (2D) or 6 (3D)
    return rotate_voigt(S.T.reshape(k, -1, 3 if d == 2 else 6), R)


class BodiesWriter(SeriesWriter):
    """Writes `paraview/blocks.pvd` + one `.vtu` per frame for a `Simulation` (comm: one piece per rank, a
    .pvtu per frame; module docstring)."""

    def __init__(self, sim, directory: str, stress: bool = True, append: bool = False,
                 basename: str = "blocks", keep_until_time: float | None = None, comm=None):
        self.sim, self.stress = sim, stress
        super().__init__(directory, basename, append, keep_until_time, comm)
        self.mine = piece_of(sim, len(sim.bodies), self.comm)
        self._build_static()

    # ---------------------------------------------------------------- static topology
    def _build_static(self):
        sim = self.sim
        self._nu = self._pe = None  # (the cells' Poisson ratios and plane-strain flags, taken at the first write)
        pts, blocks_tri, blocks_quad, polys = [], [], [], []
        body_of_cell = {"triangle": [], "quad": [], "polygon": []}
        self.layout = []  # (group, its members in this piece, point offset per member (k,), n_nodes)
        offset = 0
        mine = set(self.mine)
        for gr in sim.groups:
            bt = gr.type
            n = bt.n_nodes
            offs = []
            members = [b for b in gr.members if b in mine]
            if not members:
                continue
            for b in members:
                body = sim.bodies[b]
                pts.append(body.reference_points)
                conn = bt.mesh.cells + offset
                (blocks_tri if bt.mesh.cell_type == "triangle" else blocks_quad).append(conn)
                body_of_cell[bt.mesh.cell_type].append(np.full(len(conn), b))
                offs.append(offset)
                offset += n
            self.layout.append((gr, members, np.array(offs), n))
        self.rigid_layout = []
        for i in sim.rigid:
            if i not in mine:
                continue
            body = sim.bodies[i]
            V = body.center0 + body.vertices_rel
            pts.append(V)
            polys.append(np.arange(offset, offset + len(V)))
            body_of_cell["polygon"].append(np.array([i]))
            self.rigid_layout.append((i, offset, len(V)))
            offset += len(V)
        self.X = np.concatenate(pts) if pts else np.zeros((0, 2))
        self.cells = []
        order = []
        if blocks_tri:
            self.cells.append(("triangle", np.concatenate(blocks_tri)))
            order.append("triangle")
        if blocks_quad:
            self.cells.append(("quad", np.concatenate(blocks_quad)))
            order.append("quad")
        if polys:
            self.cells.append(("polygon", polys))
            order.append("polygon")
        self.cell_body = np.concatenate([np.concatenate(body_of_cell[k]) for k in order]).astype(np.int64) \
            if order else np.zeros(0, np.int64)
        self.cell_kind = np.array([self.sim.bodies[b].kind for b in self.cell_body], dtype=np.int64)
        self.order = order
        self.n_points = len(self.X)

    # ---------------------------------------------------------------- fields
    def fields(self):
        """Point and cell fields of the current state (global frame)."""
        sim = self.sim
        disp = np.zeros((self.n_points, 2))
        vel = np.zeros((self.n_points, 2))
        stress = {k: [] for k in ("triangle", "quad")}
        for gr, members, offs, n in self.layout:
            # from the bodies, not gr.Q: Simulation.set_step (a stage with another h) rebuilds its groups
            sg = _type_fields(sim.bodies, members, offs, gr.type, disp, vel, self.stress)
            if sg is not None:
                stress[gr.type.mesh.cell_type].append(sg.reshape(-1, 3))
        for i, off, nv in self.rigid_layout:
            body = sim.bodies[i]
            cur = body.current_vertices()
            disp[off:off + nv] = cur - (body.center0 + body.vertices_rel)
            rel = cur - body.center
            vel[off:off + nv] = body.u[:2] + body.u[2] * np.column_stack([-rel[:, 1], rel[:, 0]])
        point_data = {"displacement": disp, "velocity": vel}
        cell_data = {"body_id": self.cell_body, "body_kind": self.cell_kind}
        if self.stress:
            parts = []
            for name in self.order:
                if name == "polygon":
                    parts.append(np.zeros((len(self.rigid_layout), 3)))
                else:
                    parts.append(np.concatenate(stress[name]))
            sig = np.concatenate(parts)
            cell_data["stress"] = sig
            cell_data["von_mises"] = von_mises(sig, self._cell_nu(), self._cell_plane_strain())
        return point_data, cell_data

    def _cell_nu(self):
        if self._nu is None:
            self._nu = np.array([getattr(getattr(self.sim.bodies[b], "type", None), "material", None).nu
                                 if self.sim.bodies[b].kind == 0 else 0.0 for b in self.cell_body])
        return self._nu

    def _cell_plane_strain(self):
        if self._pe is None:
            self._pe = np.array([self.sim.bodies[b].kind == 0 and self.sim.bodies[b].type.material.plane == "strain"
                                 for b in self.cell_body])
        return self._pe

    # ---------------------------------------------------------------- write
    def write(self, time: float) -> str:
        _follow(self, self.sim, len(self.sim.bodies))
        if not self.cells:  # (N ranks: no body in this rank's piece)
            return self.write_frame(time, None, None)
        point_data, cell_data = self.fields()
        return self.write_frame(time, self.X, self.cells, point_data, cell_data)


_VTK_NAME = {"tetrahedron": "tetra", "hexahedron": "hexahedron"}
_ORDER_3D = ("hexahedron", "tetra", "quad", "triangle")


class BodiesWriter3D(SeriesWriter):
    """3D bodies (DeformableBody3D, RigidBody3D) as one merged grid per frame in `blocks.pvd`.

    `bodies`: a list, or an object with `.bodies` (a 3D simulation); the list is read at every frame, its
    topology fixed at construction. Points: reference positions (deformable nodes x = R X + c, rigid surface
    points); deformable cells = the type mesh's tetrahedra/hexahedra, a rigid body = its boundary faces
    (triangles/quads). Point data: displacement, velocity (global frame; rigid v + w x (x - c)). Cell data:
    body_id, body_kind (0 deformable, 1 rigid), stress (sxx, syy, szz, syz, sxz, sxy) at the cell centroid
    (global frame: R sigma_type R^T, batched per block type), von_mises (0 on rigid faces)."""

    def __init__(self, bodies, directory: str, stress: bool = True, append: bool = False,
                 basename: str = "blocks", keep_until_time: float | None = None, comm=None):
        self.source, self.stress = bodies, stress
        super().__init__(directory, basename, append, keep_until_time, comm)
        self.mine = piece_of(self.source, len(self.bodies), self.comm)
        self._build_static()

    @property
    def bodies(self) -> list:
        return list(getattr(self.source, "bodies", self.source))

    def _build_static(self):
        bodies = self.bodies
        pts, offset = [], 0
        blocks = {k: [] for k in _ORDER_3D}   # cell name -> [(connectivity, body)]
        self.groups = {}                      # id(type) -> (type, [body], [point offset])
        self.rigid_layout = []                # (body, point offset, n points)
        mine = set(self.mine)
        for b, body in enumerate(bodies):
            if b not in mine:
                continue
            if body.kind == 0:
                m = body.type.mesh
                X = body.reference_points
                blocks[_VTK_NAME[m.cell_type]].append((m.cells + offset, b))
                g = self.groups.setdefault(id(body.type), (body.type, [], []))
                g[1].append(b)
                g[2].append(offset)
            else:
                X = body.center0 + body.points_rel
                F = body.boundary_faces
                tri = F[:, 3] < 0 if F.shape[1] == 4 else np.ones(len(F), bool)
                if F.shape[1] == 4 and np.any(~tri):
                    blocks["quad"].append((F[~tri] + offset, b))
                if np.any(tri):
                    blocks["triangle"].append((F[tri, :3] + offset, b))
                self.rigid_layout.append((b, offset, len(X)))
            pts.append(X)
            offset += len(X)
        self.X = np.concatenate(pts) if pts else np.zeros((0, 3))
        self.n_points = offset
        self.cells, cell_body = [], []
        self._cell_slices = {}  # (cell name, body) -> slice of the merged cell list
        start = 0
        for name in _ORDER_3D:
            if not blocks[name]:
                continue
            self.cells.append((name, np.concatenate([c for c, _ in blocks[name]])))
            for c, b in blocks[name]:
                self._cell_slices[b] = slice(start, start + len(c))
                cell_body.append(np.full(len(c), b))
                start += len(c)
        self.n_cells = start
        self.cell_body = np.concatenate(cell_body).astype(np.int64) if cell_body else np.zeros(0, np.int64)
        self.cell_kind = np.array([bodies[b].kind for b in self.cell_body], dtype=np.int64)

    def fields(self):
        """Point and cell fields of the current state (global frame)."""
        bodies = self.bodies
        disp = np.zeros((self.n_points, 3))
        vel = np.zeros((self.n_points, 3))
        sig = np.zeros((self.n_cells, 6))
        for bt, members, offs in self.groups.values():
            sg = _type_fields(bodies, members, offs, bt, disp, vel, self.stress)
            if sg is not None:
                for i, b in enumerate(members):
                    sig[self._cell_slices[b]] = sg[i]
        for b, off, nv in self.rigid_layout:
            body = bodies[b]
            cur = body.current_points()
            disp[off:off + nv] = cur - (body.center0 + body.points_rel)
            vel[off:off + nv] = body.u[:3] + np.cross(body.u[3:], cur - body.center)
        point_data = {"displacement": disp, "velocity": vel}
        cell_data = {"body_id": self.cell_body, "body_kind": self.cell_kind}
        if self.stress:
            cell_data["stress"] = sig
            cell_data["von_mises"] = von_mises(sig)
        return point_data, cell_data

    def write(self, time: float) -> str:
        _follow(self, self.source, len(self.bodies))
        if not self.cells:  # (N ranks: no body in this rank's piece)
            return self.write_frame(time, None, None)
        point_data, cell_data = self.fields()
        return self.write_frame(time, self.X, self.cells, point_data, cell_data)
