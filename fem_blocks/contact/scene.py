"""Flat-array view of the bodies of a Simulation, as the contact layer sees them (architecture.md).

Bodies 0..nb-1 (deformable and rigid in one list), dimension d = sim.dim (2 or 3). Boundary nodes of all
bodies are concatenated in `bx (nbn, d)` (deformable: the type's boundary nodes in
`BlockType.boundary_nodes` order; rigid: polygon vertices in 2D, the points of its polyhedron in 3D).
2D: `bedges` index `bx`, counter-clockwise per body. 3D: `bfaces (nf, 4)` index `bx` (-1 in column 3 for
a triangle), outward by the right-hand rule, `bface_body (nf,)` (detection_3d.flatten_boundaries layout).
Velocities and impulses are exchanged in the *W numbering*: deformable body = its type's boundary dofs
`d*bnode_index + c` in the type frame, rigid body = (vx, vy, omega) in 2D, (v, ω) (6 dofs) in 3D at its
centre of mass. `U_offset[b]` locates body b in flat vectors.

Frames: a deformable body's W numbering and G blocks use its frame R (type/body frame -> global). In a co-rotational
simulation (dynamics.py, docs/method.md §7) the frame of a framed group turns every step: the scene holds views of
the group's frames (R, position: current positions) and its placements (R0, position0: reference positions), and
`refresh_frames` copies the current R into `rot` (the G blocks of the step use the frame of its start).

All per-step gathers/scatters are batched per group of bodies sharing a step operator.
"""
from __future__ import annotations

import numpy as np


class ContactScene:
    def __init__(self, sim, body_group=None):
        self.sim = sim
        bodies = sim.bodies
        nb = len(bodies)
        self.nb = nb
        d = self.dim = sim.dim
        self.rigid_ndof = 3 if d == 2 else 6
        self.kind = np.array([b.kind for b in bodies], dtype=np.int64)
        self.rot = np.zeros((nb, d, d))
        self.body_group = (np.zeros(nb, dtype=np.int64) if body_group is None
                           else np.asarray(body_group, dtype=np.int64))
        # per-type boundary numbering (shared offsets), rigid: identity over its vertices
        type_offset = {}
        index_parts, off = [], 0
        self.bnode_offset = np.zeros(nb, dtype=np.int64)
        self.nbnodes = np.zeros(nb, dtype=np.int64)
        for i, b in enumerate(bodies):
            if b.kind == 0:
                self.rot[i] = b.R
                key = id(b.type)
                if key not in type_offset:
                    type_offset[key] = off
                    index_parts.append(b.type.bnode_index)
                    off += b.type.n_nodes
                self.bnode_offset[i] = type_offset[key]
                self.nbnodes[i] = b.type.boundary_nodes.size
            else:
                self.rot[i] = np.eye(d)
                nv = len(self._rigid_points(b))
                self.bnode_offset[i] = off
                index_parts.append(np.arange(nv, dtype=np.int64))
                off += nv
                self.nbnodes[i] = nv
        self.bnode_index_flat = np.concatenate(index_parts).astype(np.int64)
        # boundary nodes and edges (2D) / faces (3D) in bx numbering
        self.bx_start = np.zeros(nb + 1, dtype=np.int64)
        self.bx_start[1:] = np.cumsum(self.nbnodes)
        nbn = int(self.bx_start[-1])
        self.bnode_body = np.repeat(np.arange(nb), self.nbnodes)
        self.bnode_local = np.zeros(nbn, dtype=np.int64)
        edges, ebody = [], []
        for i, b in enumerate(bodies):
            s = self.bx_start[i]
            if b.kind == 0:
                bt = b.type
                self.bnode_local[s:s + bt.boundary_nodes.size] = bt.boundary_nodes
                local = bt.mesh.boundary_edges if d == 2 else bt.mesh.boundary_faces
                e = bt.bnode_index[local] + s
            else:
                nv = self.nbnodes[i]
                self.bnode_local[s:s + nv] = np.arange(nv)
                k = np.arange(nv)
                e = (np.column_stack([k, (k + 1) % nv]) if d == 2 else b.boundary_faces) + s
            if d == 3 and e.shape[1] == 3:
                e = np.column_stack([e, -np.ones(len(e), dtype=np.int64)])
            edges.append(e)
            ebody.append(np.full(len(e), i, dtype=np.int64))
        if d == 2:
            self.bedges = np.concatenate(edges).astype(np.int64)
            self.bedge_body = np.concatenate(ebody)
        else:
            self.bfaces = np.ascontiguousarray(np.concatenate(edges).astype(np.int64))
            self.bface_body = np.concatenate(ebody)
        # W numbering
        self.W_size = np.where(self.kind == 0, d * self.nbnodes, self.rigid_ndof).astype(np.int64)
        self.U_offset = np.zeros(nb + 1, dtype=np.int64)
        self.U_offset[1:] = np.cumsum(self.W_size)
        self.n_udof = int(self.U_offset[-1])
        self._group_index()

    @staticmethod
    def _rigid_points(b) -> np.ndarray:
        """Reference boundary points of a rigid body relative to its centre of mass (2D vertices / 3D points)."""
        return b.vertices_rel if getattr(b, "gdim", 2) == 2 else b.points_rel

    def _group_index(self):
        """Per simulation group: index matrices into bx and into the flat W-numbered vectors."""
        sim = self.sim
        self.groups = []
        self.ref_frames = []  # per group: (R0 (k, d, d), position0 (k, d)) of the placements
        for gr in sim.groups:
            bt = gr.type
            nbd = self.dim * bt.boundary_nodes.size
            members = gr.members
            uidx = self.U_offset[members][:, None] + np.arange(nbd)[None, :]  # (k, nbd)
            xidx = self.bx_start[members][:, None] + np.arange(bt.boundary_nodes.size)[None, :]
            if getattr(gr, "framed", False):  # live views of the frames (co-rotational), placements for reference
                R, C, R0, C0 = gr.R, gr.pos, gr.R0, gr.pos0
            else:
                R = np.stack([sim.bodies[b].R for b in members])
                C = np.stack([sim.bodies[b].position for b in members])
                R0, C0 = R, C
            self.groups.append((gr, uidx, xidx, R, C))
            self.ref_frames.append((R0, C0))
        self.framed = [gr.members for gr in sim.groups if getattr(gr, "framed", False)]
        self.rigid = np.array(sim.rigid, dtype=np.int64)
        self.rigid_W = {}  # rigid W used in the last Delassus assembly (3D: depends on the orientation)

    # ------------------------------------------------------------------ geometry
    def refresh_frames(self):
        """rot of the bodies of framed (co-rotational) groups := their current frames R (the start of the step)."""
        for gr, uidx, xidx, R, C in self.groups:
            if getattr(gr, "framed", False):
                self.rot[gr.members] = R

    def positions(self, reference: bool = False) -> np.ndarray:
        """bx (nbn, d): global positions of all boundary nodes (current, or reference: the placements)."""
        d = self.dim
        bx = np.zeros((int(self.bx_start[-1]), d))
        for (gr, uidx, xidx, R, C), (R0, C0) in zip(self.groups, self.ref_frames):
            bt = gr.type
            X = bt.mesh.points[bt.boundary_nodes]  # (nbn_t, 2)
            k = len(gr.members)
            if reference:
                R, C = R0, C0
                P = np.broadcast_to(X, (k,) + X.shape)
            else:
                Q = gr.Q[bt.boundary_dofs, :].T.reshape(k, -1, d)
                P = X[None] + Q
            bx[xidx.ravel()] = (np.einsum("kij,knj->kni", R, P) + C[:, None, :]).reshape(-1, d)
        for i in self.rigid:
            b = self.sim.bodies[i]
            s, e = self.bx_start[i], self.bx_start[i + 1]
            if reference:
                bx[s:e] = b.center0 + self._rigid_points(b)
            else:
                bx[s:e] = b.current_vertices() if d == 2 else b.current_points()
        return bx

    def centers(self, reference: bool = False) -> np.ndarray:
        c = np.zeros((self.nb, self.dim))
        for i in self.rigid:
            b = self.sim.bodies[i]
            c[i] = b.center0 if reference else b.center
        return c

    # ------------------------------------------------------------------ W numbering
    def W_blocks(self, rigid_W=None):
        """(W_flat, W_offset, W_size): dense W per body, row-major; bodies sharing a step operator share it.
        `rigid_W` (nr, d, d): the W of the rigid bodies to use instead of their current `W` (a restored run: in 3D
        W = inverse of the free block of diag(m) ⊕ Rot I0 Rotᵀ depends on the orientation when it was built)."""
        parts, off = [], 0
        W_offset = np.zeros(self.nb, dtype=np.int64)
        for gr, uidx, xidx, R, C in self.groups:
            Wbb = gr.op.W_bb
            parts.append(Wbb.ravel())
            W_offset[gr.members] = off
            off += Wbb.size
        for k, i in enumerate(self.rigid):
            Wr = self.rigid_W[i] = self.sim.bodies[i].W if rigid_W is None else np.array(rigid_W[k])
            parts.append(Wr.ravel())
            W_offset[i] = off
            off += Wr.size
        W_flat = np.ascontiguousarray(np.concatenate(parts)) if parts else np.zeros(0)
        return W_flat, W_offset, self.W_size.copy()

    def gather(self, which: str, cols=None) -> np.ndarray:
        """Flat W-numbered vector of 'ufree', 'u' (start-of-step velocity) or 'q' (displacement). `cols`: per group the
        columns of the bodies to take (Simulation.stepped_columns; None: every member); the other bodies' entries
        are 0."""
        out = np.zeros(self.n_udof)
        for (gr, uidx, xidx, R, C), c in zip(self.groups, cols or [None] * len(self.groups)):
            A = {"ufree": gr.Ufree, "u": gr.U, "q": gr.Q}[which]
            if c is None:
                out[uidx.ravel()] = A[gr.type.boundary_dofs, :].T.ravel()
            else:
                out[uidx[c].ravel()] = A[np.ix_(gr.type.boundary_dofs, c)].T.ravel()
        for i in self.rigid:
            b = self.sim.bodies[i]
            s = self.U_offset[i]
            out[s:s + self.rigid_ndof] = {"ufree": b.ufree, "u": b.u, "q": b.q}[which]
        return out

    def corrections(self, imp: np.ndarray, cols=None):
        """Velocity corrections W H (h r) from flat W-numbered impulses `imp`: one batched solve per group.
        `cols`: per group the columns of the bodies to correct (Simulation.stepped_columns; None: every member).

        Returns (group_corr, rigid_corr, rigid_impulse): per group of `sim.groups` its correction (ndof, k) of those
        columns (clamped dofs 0), or None when no impulse reaches them; per rigid body (sim.rigid order) W p and the
        impulse p. Writes nothing into the simulation (the caller applies them)."""
        group_corr = []
        for (gr, uidx, xidx, R, C), c in zip(self.groups, cols or [None] * len(self.groups)):
            rows = uidx if c is None else uidx[c]
            rhs = np.zeros((gr.U.shape[0], len(rows)))
            rhs[gr.type.boundary_dofs, :] = imp[rows].T
            rhs[gr.clamped, :] = 0.0
            corr = None
            if np.any(rhs):
                corr = gr.op.solve(rhs)
                corr[gr.clamped, :] = 0.0
            group_corr.append(corr)
        nr = len(self.rigid)
        rigid_corr = np.zeros((nr, self.rigid_ndof))
        rigid_impulse = np.zeros((nr, self.rigid_ndof))
        for k, i in enumerate(self.rigid):
            s = self.U_offset[i]
            p = imp[s:s + self.rigid_ndof]
            rigid_impulse[k] = p
            # the W of the Delassus operator (3D rigid: inertia of the orientation at assembly), so that the
            # corrected local velocities are exactly those of the contact solution
            rigid_corr[k] = self.rigid_W.get(i, self.sim.bodies[i].W) @ p
        return group_corr, rigid_corr, rigid_impulse

    def contact_points(self, cs, reference: bool = False) -> np.ndarray:
        """(nc, 2) current (or reference) positions of the candidate points of a 2D contact set `cs`: the ends of
        the candidate edge weighted by cs.cand_w."""
        bx = self.positions(reference=reference)
        b = cs.cand_body
        idx = self.bx_start[b][:, None] + self.bnode_index_flat[self.bnode_offset[b][:, None] + cs.cand_nodes]
        return cs.cand_w[:, :1] * bx[idx[:, 0]] + cs.cand_w[:, 1:] * bx[idx[:, 1]]
