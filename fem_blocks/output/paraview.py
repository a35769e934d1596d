"""ParaView output of the bodies: one merged unstructured grid per frame, in a .pvd series.

Points are the *reference* positions of every deformable node and rigid vertex; the point field
`displacement` (current - reference) lets ParaView's "Warp By Vector" show the deformed state.
Point data: displacement, velocity (global frame). Cell data: Cauchy stress (sxx, syy, sxy),
von Mises stress (deformable cells; 0 on rigid polygons), body id, body kind (0 deformable,
1 rigid). Fields are computed per block type with batched array operations (no per-node loop).
"""
from __future__ import annotations

import os

import numpy as np

from .pvd import PvdSeries
from .vtu import write_vtu


def _rotate_vectors(V: np.ndarray, R: np.ndarray) -> np.ndarray:
    """V (k, n, 2) in type frames, R (k, 2, 2) -> global vectors (k, n, 2): v = R v_type."""
    return np.einsum("kij,knj->kni", R, V)


class BodiesWriter:
    """Writes `paraview/blocks.pvd` + one `.vtu` per frame for a `Simulation`."""

    def __init__(self, sim, directory: str, stress: bool = True, append: bool = False,
                 basename: str = "blocks", keep_until_time: float | None = None):
        self.sim, self.dir, self.stress, self.base = sim, directory, stress, basename
        os.makedirs(directory, exist_ok=True)
        pvd = os.path.join(directory, f"{basename}.pvd")
        self.series = PvdSeries.open_existing(pvd, keep_until_time) if append and os.path.exists(pvd) \
            else PvdSeries(pvd)
        self.frame = len(self.series.entries) if hasattr(self.series, "entries") else 0
        self._build_static()

    # ---------------------------------------------------------------- static topology
    def _build_static(self):
        sim = self.sim
        pts, blocks_tri, blocks_quad, polys = [], [], [], []
        body_of_cell = {"triangle": [], "quad": [], "polygon": []}
        self.layout = []  # (group, point offset per member (k,), n_nodes, cell block name, cell offset)
        offset = 0
        for gr in sim.groups:
            bt = gr.type
            n = bt.n_nodes
            offs = []
            for b in gr.members:
                body = sim.bodies[b]
                pts.append(body.reference_points)
                conn = bt.mesh.cells + offset
                (blocks_tri if bt.mesh.cell_type == "triangle" else blocks_quad).append(conn)
                body_of_cell[bt.mesh.cell_type].append(np.full(len(conn), b))
                offs.append(offset)
                offset += n
            self.layout.append((gr, np.array(offs), n))
        self.rigid_layout = []
        for i in sim.rigid:
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
        self.cell_body = np.concatenate([np.concatenate(body_of_cell[k]) for k in order]).astype(np.int64)
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
        for gr, offs, n in self.layout:
            # from the bodies, not gr.Q: Simulation.set_step (a stage with another h) rebuilds its groups
            k = len(gr.members)
            R = np.stack([sim.bodies[b].R for b in gr.members])
            Qc = np.column_stack([sim.bodies[b].q for b in gr.members])
            Q = Qc.T.reshape(k, n, 2)
            U = np.stack([sim.bodies[b].u for b in gr.members]).reshape(k, n, 2)
            idx = (offs[:, None] + np.arange(n)[None, :]).ravel()
            disp[idx] = _rotate_vectors(Q, R).reshape(-1, 2)
            vel[idx] = _rotate_vectors(U, R).reshape(-1, 2)
            if self.stress:
                S = gr.type.stress_operator @ Qc  # (3 nc, k), type frame (sxx, syy, sxy)
                nc = S.shape[0] // 3
                s = S.T.reshape(k, nc, 3)
                T = np.empty((k, nc, 2, 2))
                T[..., 0, 0], T[..., 1, 1] = s[..., 0], s[..., 1]
                T[..., 0, 1] = T[..., 1, 0] = s[..., 2]
                Tg = np.einsum("kij,kcjl,kml->kcim", R, T, R)  # R T R^T
                sg = np.stack([Tg[..., 0, 0], Tg[..., 1, 1], Tg[..., 0, 1]], -1)
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
            nu = self._cell_nu()
            szz = np.where(self._cell_plane_strain(), nu * (sig[:, 0] + sig[:, 1]), 0.0)
            vm = np.sqrt(0.5 * ((sig[:, 0] - sig[:, 1]) ** 2 + (sig[:, 1] - szz) ** 2 + (szz - sig[:, 0]) ** 2)
                         + 3.0 * sig[:, 2] ** 2)
            cell_data["stress"] = sig
            cell_data["von_mises"] = vm
        return point_data, cell_data

    def _cell_nu(self):
        if not hasattr(self, "_nu"):
            self._nu = np.array([getattr(getattr(self.sim.bodies[b], "type", None), "material", None).nu
                                 if self.sim.bodies[b].kind == 0 else 0.0 for b in self.cell_body])
        return self._nu

    def _cell_plane_strain(self):
        if not hasattr(self, "_pe"):
            self._pe = np.array([self.sim.bodies[b].kind == 0 and self.sim.bodies[b].type.material.plane == "strain"
                                 for b in self.cell_body])
        return self._pe

    # ---------------------------------------------------------------- write
    def write(self, time: float) -> str:
        point_data, cell_data = self.fields()
        name = f"{self.base}_{self.frame:06d}.vtu"
        write_vtu(os.path.join(self.dir, name), self.X, self.cells, point_data=point_data, cell_data=cell_data)
        self.series.add(time, name)
        self.frame += 1
        return name
