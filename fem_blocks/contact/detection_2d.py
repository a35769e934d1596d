"""2D contact detection on plain arrays: candidate points on candidate edges, projected on antagonist edges.

Conventions (docs/method.md §1, §6): boundary edges are counter-clockwise per body (body on the left), so the
outward normal of an edge with unit direction e is (e_y, -e_x). For a contact, the normal n is the
outward normal of the *antagonist* edge (it points toward the candidate), t = (-n_y, n_x) (the
antagonist edge direction), local arrays are (n, t). Gap g = (x_c - x_a)·n, x_a the orthogonal
projection of the candidate point on the antagonist edge; a thick joint has g0 = joint thickness.

Candidate/antagonist (one side only, deterministic): the interface's `candidate` group if given and the
two bodies differ in group; else a deformable body is candidate against a rigid one; else the lower
body index is candidate.

Candidate points (`placement`, per interface):
* "overlap" (the default of InterfaceSpec in 2D): for each facing (candidate edge, antagonist edge) pair, the
  two ends of the overlap [s_lo, s_hi] of the candidate edge with the antagonist edge projected on it (ends
  within SNAP of a candidate node snap to it): candidate nodes where the meshes match, and the antagonist's
  nodes (e.g. its corners) where they fall inside a candidate edge. Each end receives half of the overlap
  length (trapezoidal rule), summed over the pairs ending at the same point with the same antagonist body, so
  the points of a joint sum to its overlap length; a candidate node facing several antagonist bodies (where a bed
  joint meets a head joint in running bond) carries one point per body. Hinges can form at either body's corner
  whatever the mesh.
* "nodes": the candidate's FE nodes (one point per node, shared nodes counted once; tributary = half of every
  candidate edge producing it);
* "positions": relative positions on each candidate edge (e.g. 0.25, 0.75 — retreated from the corners,
  thesis §7.2.1.a; the hinge then sits a quarter of an edge inside the corner).
Each point carries its tributary length x thickness (`area`). A point is paired with the nearest facing
antagonist edge (angle between outward normals within `max_angle` of opposite: InterfaceSpec.max_angle, default
MAX_ANGLE = 60°: one edge of a right-angled corner faces a flat antagonist at any tilt) onto which it projects inside
the edge, with -(reach) <= g <= g0 + alert.

Broad phase: edge boxes enlarged by the search distance on a uniform grid (contact/broadphase.py, shared with
3D; numba, linear in the number of edges); each edge pair of two bodies is examined once. A rank's detection
(`detect(..., bodies=)`: the contacts of its own candidate bodies) runs it on the edges of its bodies and their
neighbours on the whole set's grid, which keeps the whole detection's order: the same contacts, bit for bit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..errors import InputError
from ..specs import InterfaceSpec, default_of
from .tables import check_g0_alert, check_lengths, check_positions
from .broadphase import body_pairs, grid_pairs, near_bodies


@dataclass
class InterfaceTable:
    """pair_iface[gi, gj] -> interface id (-1: no contact); split_head[i] -> interface id used instead of i for
    contacts whose normal is closer to horizontal than to vertical (head joints), -1 none."""

    pair_iface: np.ndarray  # (ng, ng) int64, symmetric
    g0: np.ndarray          # (ni,)
    alert: np.ndarray       # (ni,)
    placement: np.ndarray   # (ni,) 0 positions, 1 nodes, 2 overlap
    positions: np.ndarray   # (ni, P) padded with -1
    cand_group: np.ndarray  # (ni,) group id whose bodies are candidates, -1 default rule
    thickness: np.ndarray   # (ni,) out-of-plane thickness (tributary area = length x thickness)
    cos_max_angle: np.ndarray  # (ni,)
    split_head: np.ndarray  # (ni,) int64

    def validate(self):
        ni = len(self.g0)
        check_lengths(self, ("alert", "placement", "cand_group", "thickness", "cos_max_angle", "split_head"), ni)
        check_g0_alert(self.g0, self.alert)
        if np.any(self.thickness <= 0):
            raise InputError("interfaces.thickness: expected > 0 [m]")
        check_positions(self.positions, self.placement, ni)


@dataclass
class ContactSet:
    cand_body: np.ndarray
    ant_body: np.ndarray
    cand_nodes: np.ndarray  # (nc, 2) body-local node ids (bnode_local) of the candidate edge ends
    ant_nodes: np.ndarray
    cand_w: np.ndarray      # (nc, 2) interpolation weights
    ant_w: np.ndarray
    point: np.ndarray       # (nc, 2)
    n: np.ndarray
    t: np.ndarray
    gap: np.ndarray
    g0: np.ndarray
    area: np.ndarray
    interface: np.ndarray
    cand_edge: np.ndarray
    ant_edge: np.ndarray
    key: np.ndarray         # stable id of the candidate point: edge*P + k (positions); -(node index)-1 (nodes,
    #                         overlap at a candidate node); -(nbn*(1 + edge) + antagonist node index)-1 (overlap
    #                         at an antagonist node inside candidate edge `edge`; nbn = number of boundary nodes)

    def __len__(self):
        return len(self.gap)

    def subset(self, idx) -> "ContactSet":
        return ContactSet(**{k: v[idx] for k, v in self.__dict__.items()})


# ----------------------------------------------------------------------------- narrow phase
SNAP = 1e-6  # overlap placement: relative distance along a candidate edge below which an end snaps to its node


@njit(cache=True)
def _narrow(pairs, bx, bedges, bedge_body, kind, body_group, pair_iface, g0, alert, placement, positions,
            cand_group, cos_max, reach_frac):
    """For each oriented (candidate edge, antagonist edge) pair: candidate points and their projections.
    Returns arrays of raw matches (possibly several per candidate point)."""
    npairs = pairs.shape[0]
    P = positions.shape[1]
    cap = max(16, 4 * npairs)
    ce = np.empty(cap, dtype=np.int64)
    ae = np.empty(cap, dtype=np.int64)
    sk = np.empty(cap, dtype=np.float64)   # relative position on the candidate edge
    lam = np.empty(cap, dtype=np.float64)  # relative position on the antagonist edge
    gap = np.empty(cap, dtype=np.float64)
    itf = np.empty(cap, dtype=np.int64)
    pk = np.empty(cap, dtype=np.int64)     # position index (or 0/1 = start/end node, 2/3 = antagonist node)
    tr = np.empty(cap, dtype=np.float64)   # overlap: tributary length contributed by this match
    s_pt = np.empty(max(P, 2), dtype=np.float64)   # candidate points of one pair (relative positions)
    code_pt = np.empty(max(P, 2), dtype=np.int64)  # and their codes (pk)
    m = 0
    for p in range(npairs):
        e1 = pairs[p, 0]
        e2 = pairs[p, 1]
        b1 = bedge_body[e1]
        b2 = bedge_body[e2]
        i = pair_iface[body_group[b1], body_group[b2]]
        if i < 0:
            continue
        # who is candidate
        c1 = True
        cg = cand_group[i]
        if cg >= 0 and body_group[b1] != body_group[b2] and (body_group[b1] == cg or body_group[b2] == cg):
            c1 = body_group[b1] == cg
        elif kind[b1] != kind[b2]:
            c1 = kind[b1] == 0
        else:
            c1 = b1 < b2
        ec = e1 if c1 else e2
        ea = e2 if c1 else e1
        ax = bx[bedges[ea, 0], 0]
        ay = bx[bedges[ea, 0], 1]
        dx = bx[bedges[ea, 1], 0] - ax
        dy = bx[bedges[ea, 1], 1] - ay
        la = np.sqrt(dx * dx + dy * dy)
        cx = bx[bedges[ec, 0], 0]
        cy = bx[bedges[ec, 0], 1]
        ex = bx[bedges[ec, 1], 0] - cx
        ey = bx[bedges[ec, 1], 1] - cy
        lc = np.sqrt(ex * ex + ey * ey)
        if la <= 0.0 or lc <= 0.0:
            continue
        tax, tay = dx / la, dy / la
        nax, nay = tay, -tax           # outward normal of the antagonist edge
        ncx, ncy = ey / lc, -ex / lc   # outward normal of the candidate edge
        if -(nax * ncx + nay * ncy) < cos_max[i]:
            continue
        reach = reach_frac * min(la, lc) + alert[i]
        # the candidate points of this pair: relative positions s_pt on the candidate edge, their codes (pk) and the
        # tributary length each match contributes (overlap only; the other placements set it after the search)
        trib = 0.0
        npts = 0
        if placement[i] == 2:
            # overlap: the ends of the part of the candidate edge facing the antagonist edge (antagonist ends
            # projected on the candidate edge, clipped to it; ends within SNAP of a candidate node snap to it)
            sa0 = ((ax - cx) * ex + (ay - cy) * ey) / (lc * lc)
            sa1 = ((ax + dx - cx) * ex + (ay + dy - cy) * ey) / (lc * lc)
            lo = max(0.0, min(sa0, sa1))
            hi = min(1.0, max(sa0, sa1))
            if hi - lo <= SNAP:
                continue
            if lo <= SNAP:
                lo = 0.0
            if hi >= 1.0 - SNAP:
                hi = 1.0
            trib = 0.5 * (hi - lo) * lc   # trapezoidal rule over the overlap: half its length to each end
            for k in range(2):
                s = lo if k == 0 else hi
                s_pt[k] = s
                if s == 0.0 or s == 1.0:
                    code_pt[k] = 0 if s == 0.0 else 1              # candidate node (start / end)
                else:
                    code_pt[k] = 2 if (sa0 < sa1) == (k == 0) else 3  # antagonist node (start / end of ea)
            npts = 2
        elif placement[i] == 1:  # nodes: both ends of the candidate edge
            for k in range(2):
                s_pt[k] = float(k)
                code_pt[k] = k
            npts = 2
        else:  # positions (padded with -1 at the end)
            for k in range(P):
                if positions[i, k] >= 0:
                    s_pt[npts] = positions[i, k]
                    code_pt[npts] = k
                    npts += 1
        for k in range(npts):
            s = s_pt[k]
            px = cx + s * ex
            py = cy + s * ey
            l = ((px - ax) * tax + (py - ay) * tay) / la
            if placement[i] != 2 and (l < -1e-9 or l > 1.0 + 1e-9):  # overlap ends face the antagonist edge
                continue
            g = (px - ax) * nax + (py - ay) * nay
            if g > g0[i] + alert[i] or g < -reach:
                continue
            if m == cap:
                cap *= 2
                ce = _grow_i(ce, cap); ae = _grow_i(ae, cap); itf = _grow_i(itf, cap); pk = _grow_i(pk, cap)
                sk = _grow_f(sk, cap); lam = _grow_f(lam, cap); gap = _grow_f(gap, cap)
                tr = _grow_f(tr, cap)
            ce[m] = ec
            ae[m] = ea
            sk[m] = s
            lam[m] = min(max(l, 0.0), 1.0)
            gap[m] = g
            itf[m] = i
            pk[m] = code_pt[k]
            tr[m] = trib
            m += 1
    return ce[:m], ae[:m], sk[:m], lam[:m], gap[:m], itf[:m], pk[:m], tr[:m]


@njit(cache=True)
def _grow_i(a, cap):
    b = np.empty(cap, dtype=a.dtype)
    b[:a.shape[0]] = a
    return b


@njit(cache=True)
def _grow_f(a, cap):
    b = np.empty(cap, dtype=a.dtype)
    b[:a.shape[0]] = a
    return b


# ----------------------------------------------------------------------------- public API
SLOTS = 8   # overlap points: at most this many antagonist bodies per candidate node (keys: SLOTS x key - slot)


def _body_slots(mask, node, ant_body, cand_body) -> np.ndarray:
    """Per match: 0, or where `mask`, the rank of its antagonist body among the distinct antagonist bodies of the
    masked matches at the same candidate node (by body index). InputError when a node faces more than SLOTS
    bodies (an alert distance larger than the blocks)."""
    slot = np.zeros(len(mask), dtype=np.int64)
    idx = np.flatnonzero(mask)
    if len(idx) == 0:
        return slot
    # the (node, antagonist body) pairs as one int64 in their lexicographic order (one sort of integers)
    nbody = int(ant_body[idx].max()) + 1
    codes, inv = np.unique(node[idx].astype(np.int64) * nbody + ant_body[idx], return_inverse=True)
    pairs = np.column_stack([codes // nbody, codes % nbody])
    first = np.searchsorted(pairs[:, 0], pairs[:, 0])   # rows sorted by node: the first row of each node
    rank = np.arange(len(pairs)) - first
    if rank.max() >= SLOTS:
        k = int(np.argmax(rank))
        j = int(idx[np.flatnonzero(inv.ravel() == k)[0]])
        raise InputError(f"contact detection: a boundary node of body {int(cand_body[j])} faces more than {SLOTS} "
                         "bodies within the alert distance; expected a smaller alert distance than the blocks")
    slot[idx] = rank[inv.ravel()]
    return slot


def detect(bx, bnode_body, bnode_local, bedges, bedge_body, kind, body_group, table: InterfaceTable,
           reach_frac: float = 0.25, bodies=None) -> ContactSet:
    """Contact points between bodies (see module docstring). All inputs are flat arrays (architecture.md).
    bodies: (nb,) bool, or None: only the contacts whose candidate body is one of `bodies` (a rank's own bodies),
    bitwise the rows of the whole detection that have such a candidate, in the same (key) order. The broad phase runs
    on the edges of these bodies and of the bodies near them, on the grid of the whole set: their pairs come in the
    whole set's relative order, so are their matches, and every sum over the matches of a point (the overlap and
    node points' tributary lengths) adds the same terms in the same order."""
    bx = np.ascontiguousarray(bx, dtype=np.float64)
    bedges = np.ascontiguousarray(bedges, dtype=np.int64)
    if bx.ndim != 2 or bx.shape[1] != 2:
        raise InputError(f"bx: expected an (n, 2) array, got shape {bx.shape}")
    if not np.all(np.isfinite(bx)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(bx), axis=1))[0])
        raise InputError(f"body {int(bnode_body[bad])}: node {int(bnode_local[bad])} has a non-finite position")
    table.validate()
    bedge_body = np.ascontiguousarray(bedge_body, dtype=np.int64)
    kind = np.ascontiguousarray(kind, dtype=np.int64)
    body_group = np.ascontiguousarray(body_group, dtype=np.int64)
    a, b = bx[bedges[:, 0]], bx[bedges[:, 1]]
    L = np.linalg.norm(b - a, axis=1)
    if len(L) and np.any(L <= 1e-12 * max(1.0, float(np.ptp(bx)))):
        e = int(np.flatnonzero(L <= 1e-12 * max(1.0, float(np.ptp(bx))))[0])
        raise InputError(f"body {int(bedge_body[e])}: boundary edge {e} has zero length (degenerate edge)")
    search = float(np.max(table.g0 + table.alert)) if len(table.g0) else 0.0
    cell = max(float(np.median(L)) if len(L) else 1.0, 2 * search, 1e-12)
    lo, hi = np.minimum(a, b) - search, np.maximum(a, b) + search
    if len(L) <= 1:
        pairs = np.zeros((0, 2), dtype=np.int64)
    elif bodies is None:
        pairs = grid_pairs(lo, hi, bedge_body, cell)
    else:
        bodies = np.asarray(bodies, dtype=bool)
        sub = np.flatnonzero(near_bodies(body_pairs(lo, hi, bedge_body, len(bodies)), bodies)[bedge_body])
        pairs = sub[grid_pairs(lo[sub], hi[sub], bedge_body[sub], cell, origin=lo.min(axis=0), top=hi.max(axis=0))] \
            if sub.size > 1 else np.zeros((0, 2), dtype=np.int64)
        pairs = pairs[bodies[bedge_body[pairs[:, 0]]] | bodies[bedge_body[pairs[:, 1]]]]
    ce, ae, sk, lam, gap, itf, pk, tr = _narrow(pairs, bx, bedges, bedge_body, kind, body_group,
                                            np.ascontiguousarray(table.pair_iface, dtype=np.int64),
                                            table.g0.astype(float), table.alert.astype(float),
                                            table.placement.astype(np.int64),
                                            np.ascontiguousarray(table.positions, dtype=float),
                                            table.cand_group.astype(np.int64), table.cos_max_angle.astype(float),
                                            float(reach_frac))
    if bodies is not None:  # the matches of the candidates of `bodies` (every match of their points)
        m = bodies[bedge_body[ce]]
        ce, ae, sk, lam, gap, itf, pk, tr = ce[m], ae[m], sk[m], lam[m], gap[m], itf[m], pk[m], tr[m]
    P = table.positions.shape[1]
    nodes_pl = table.placement[itf] == 1
    ovl_pl = table.placement[itf] == 2
    # key: position points -> edge * P + k ; node points -> -(global boundary node index) - 1; overlap points at
    # a candidate node -> as node points; at antagonist node `an` inside candidate edge ce -> -(nbn(1 + ce) + an) - 1
    nbn = len(bx)
    node_idx = np.where(pk == 1, bedges[ce, 1], bedges[ce, 0])
    ant_node = bedges[ae, np.clip(pk - 2, 0, 1)]
    key = np.where(nodes_pl | (ovl_pl & (pk < 2)), -node_idx - 1,
                   np.where(ovl_pl, -(nbn * (1 + ce) + ant_node) - 1, ce * P + pk))
    # overlap points at a candidate node: one point per (node, antagonist body), so that a node where a bed joint
    # meets a head joint (running bond: it faces two bricks) keeps the overlap with each; the slot s < SLOTS is
    # the rank of the antagonist body among those the node faces, key = SLOTS x key - s (the order of the other
    # points and their keys' relative order unchanged)
    key = key * SLOTS - _body_slots(ovl_pl & (pk < 2), node_idx, bedge_body[ae], bedge_body[ce])
    Lc = L[ce]
    trib = np.where(nodes_pl, 0.5 * Lc, Lc / np.maximum(1, (table.positions[itf] >= 0).sum(axis=1)))
    # keep, per key, the match with the smallest |g - g0| (ties: lower antagonist edge index)
    score = np.abs(gap - table.g0[itf])
    order = np.lexsort((ae, score, key))
    ks = key[order]
    first = np.ones(len(ks), dtype=bool)
    first[1:] = ks[1:] != ks[:-1]
    sel = order[first]
    # node points: tributary length = half of every candidate edge that produced this node
    if np.any(nodes_pl):
        uk, inv = np.unique(key, return_inverse=True)
        # sum of L/2 over distinct candidate edges per node key
        ne = len(bedges)  # (the distinct (node key, candidate edge) pairs, in lexicographic order)
        pc = np.unique(inv.ravel().astype(np.int64) * ne + ce)
        pair_code = np.column_stack([pc // ne, pc % ne])
        tsum = np.zeros(len(uk))
        np.add.at(tsum, pair_code[:, 0], 0.5 * L[pair_code[:, 1]])
        trib_sel = np.where(nodes_pl[sel], tsum[np.searchsorted(uk, key[sel])], trib[sel])
    else:
        trib_sel = trib[sel]
    # overlap points: tributary length = sum of the half overlaps of every match of this key with the kept
    # antagonist body (the points of a joint sum to its overlap length)
    if np.any(ovl_pl):
        ks_sel = key[sel]
        o = np.argsort(ks_sel, kind="stable")
        pos = o[np.searchsorted(ks_sel[o], key)]  # index into sel of each raw match's key
        same = ovl_pl & (bedge_body[ae] == bedge_body[ae[sel[pos]]])
        tsum = np.zeros(len(sel))
        np.add.at(tsum, pos[same], tr[same])
        trib_sel = np.where(ovl_pl[sel], tsum, trib_sel)
    sel_order = np.argsort(key[sel], kind="stable")
    sel = sel[sel_order]
    trib_sel = trib_sel[sel_order]
    ce, ae, sk, lam, gap, itf, key = ce[sel], ae[sel], sk[sel], lam[sel], gap[sel], itf[sel], key[sel]
    na = (b[ae] - a[ae]) / L[ae][:, None]
    n = np.column_stack([na[:, 1], -na[:, 0]])
    t = np.column_stack([-n[:, 1], n[:, 0]])
    point = a[ce] + sk[:, None] * (b[ce] - a[ce])
    # head/bed split: contacts whose normal is closer to horizontal use the head-joint interface
    head = table.split_head[itf]
    use_head = (head >= 0) & (np.abs(n[:, 1]) < np.sqrt(0.5))
    itf = np.where(use_head, head, itf)
    return ContactSet(
        cand_body=bedge_body[ce], ant_body=bedge_body[ae],
        cand_nodes=bnode_local[bedges[ce]], ant_nodes=bnode_local[bedges[ae]],
        cand_w=np.column_stack([1 - sk, sk]), ant_w=np.column_stack([1 - lam, lam]),
        point=point, n=n, t=t, gap=gap, g0=table.g0[itf].astype(float),
        area=trib_sel * table.thickness[itf], interface=itf.astype(np.int64),
        cand_edge=ce, ant_edge=ae, key=key.astype(np.int64))


@njit(cache=True)
def _inside_depth(pairs, bx, bedges, node_start, edge_start, tol):
    """For body pairs (A, B): deepest boundary node of one body strictly inside the other (ray casting),
    depth = distance to the other body's boundary. Returns (depth per pair)."""
    out = np.zeros(pairs.shape[0])
    for p in range(pairs.shape[0]):
        for side in range(2):
            A = pairs[p, side]
            B = pairs[p, 1 - side]
            for k in range(node_start[A], node_start[A + 1]):
                x = bx[k, 0]
                y = bx[k, 1]
                inside = False
                dmin = np.inf
                for e in range(edge_start[B], edge_start[B + 1]):
                    x0 = bx[bedges[e, 0], 0]
                    y0 = bx[bedges[e, 0], 1]
                    x1 = bx[bedges[e, 1], 0]
                    y1 = bx[bedges[e, 1], 1]
                    if (y0 > y) != (y1 > y):
                        xc = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
                        if xc > x:
                            inside = not inside
                    dx = x1 - x0
                    dy = y1 - y0
                    l2 = dx * dx + dy * dy
                    tpar = ((x - x0) * dx + (y - y0) * dy) / l2 if l2 > 0 else 0.0
                    tpar = min(max(tpar, 0.0), 1.0)
                    ex = x0 + tpar * dx - x
                    ey = y0 + tpar * dy - y
                    d = np.sqrt(ex * ex + ey * ey)
                    if d < dmin:
                        dmin = d
                if inside and dmin > tol and dmin > out[p]:
                    out[p] = dmin
    return out


def find_overlap(bx, bnode_body, bedges, bedge_body, tol: float):
    """(body_a, body_b, depth) of the deepest overlap — a boundary node of one body inside another by more
    than `tol` — or None. Bodies only touching are not overlapping. Nodes and edges must be grouped by body."""
    bx = np.ascontiguousarray(bx, dtype=np.float64)
    bedges = np.ascontiguousarray(bedges, dtype=np.int64)
    nb = int(max(bnode_body.max(), bedge_body.max())) + 1 if len(bnode_body) else 0
    if nb < 2:
        return None
    node_start = np.zeros(nb + 1, dtype=np.int64)
    node_start[1:] = np.cumsum(np.bincount(bnode_body, minlength=nb))
    edge_start = np.zeros(nb + 1, dtype=np.int64)
    edge_start[1:] = np.cumsum(np.bincount(bedge_body, minlength=nb))
    if np.any(np.diff(bnode_body) < 0) or np.any(np.diff(bedge_body) < 0):
        raise ValueError("find_overlap: nodes and edges must be sorted by body")
    pairs = body_pairs(bx, bx, bnode_body, nb)  # the bodies' boxes: their nodes'
    if len(pairs) == 0:
        return None
    depth = _inside_depth(pairs, bx, bedges, node_start, edge_start, float(tol))
    k = int(np.argmax(depth))
    if depth[k] <= 0:
        return None
    return int(pairs[k, 0]), int(pairs[k, 1]), float(depth[k])


def update_geometry(cs: ContactSet, bx, bedges) -> ContactSet:
    """Same pairs and weights, frames and gaps recomputed from current positions (small-sliding mode)."""
    a, b = bx[bedges[cs.ant_edge, 0]], bx[bedges[cs.ant_edge, 1]]
    ca, cb = bx[bedges[cs.cand_edge, 0]], bx[bedges[cs.cand_edge, 1]]
    d = b - a
    L = np.linalg.norm(d, axis=1)
    e = d / L[:, None]
    n = np.column_stack([e[:, 1], -e[:, 0]])
    t = np.column_stack([-n[:, 1], n[:, 0]])
    xc = cs.cand_w[:, :1] * ca + cs.cand_w[:, 1:] * cb
    xa = cs.ant_w[:, :1] * a + cs.ant_w[:, 1:] * b
    gap = np.einsum("ij,ij->i", xc - xa, n)
    out = ContactSet(**dict(cs.__dict__))
    out.point, out.n, out.t, out.gap = xc, n, t, gap
    return out


MAX_ANGLE = default_of(InterfaceSpec, "max_angle")  # [degrees] the facing angle's default (specs.InterfaceSpec)
PLACEMENT_CODE = {"positions": 0, "nodes": 1, "overlap": 2, None: 2}  # None: the 2D default, "overlap"


def build_table(interfaces, group_index: dict) -> InterfaceTable:
    """InterfaceTable from interface specs (objects with name, groups, g0, alert, placement, positions,
    candidate, orientation, and optional thickness / max_angle)."""
    ng = len(group_index)
    ni = len(interfaces)
    pair = -np.ones((ng, ng), dtype=np.int64)
    P = max([len(i.positions) for i in interfaces] + [1])
    positions = -np.ones((ni, P))
    split = -np.ones(ni, dtype=np.int64)
    by_pair: dict = {}
    for k, itf in enumerate(interfaces):
        ga, gb = (group_index[g] for g in itf.groups)
        positions[k, :len(itf.positions)] = itf.positions
        if itf.orientation == "crack":  # assigned after detection, by parent brick (ContactStep._assign_laws)
            continue
        by_pair.setdefault((min(ga, gb), max(ga, gb)), []).append((k, itf.orientation))
    for (ga, gb), lst in by_pair.items():
        orients = sorted(o for _, o in lst)
        if len(lst) == 1 and orients[0] == "any":
            main = lst[0][0]
        elif len(lst) == 2 and orients == ["bed", "head"]:
            main = next(k for k, o in lst if o == "bed")
            split[main] = next(k for k, o in lst if o == "head")
        else:
            names = [interfaces[k].name for k, _ in lst]
            raise InputError(f"interfaces {names}: one group pair takes either one interface (orientation 'any') "
                             f"or two ('bed' and 'head')")
        pair[ga, gb] = pair[gb, ga] = main
    return InterfaceTable(
        pair_iface=pair,
        g0=np.array([i.g0 for i in interfaces], dtype=float),
        alert=np.array([i.alert for i in interfaces], dtype=float),
        placement=np.array([PLACEMENT_CODE[i.placement] for i in interfaces], dtype=np.int64),
        positions=positions,
        cand_group=np.array([group_index[i.candidate] if i.candidate else -1 for i in interfaces], dtype=np.int64),
        thickness=np.array([getattr(i, "thickness", 1.0) for i in interfaces], dtype=float),
        cos_max_angle=np.cos(np.deg2rad([getattr(i, "max_angle", MAX_ANGLE) for i in interfaces])),
        split_head=split)
