"""Partition of the bodies of a 2D model across MPI ranks, with ghosts and owned contacts (docs/scaling.md, issue #24).

Input: a `model.Model` (build_model of a case, after case.load_case and expand.expand), bodies 0..nb-1 in their
reference placement. With r = max over the interfaces of (g0 + alert), the search distance of the contact
detection (contact/detection_2d.py), and dist(i, j) the Euclidean distance between the boundaries ∂i, ∂j of two
bodies (the polylines of their boundary edges: min over edge pairs of the segment–segment distance, 0 when two
segments cross):

* near pairs   N = {(i, j), i < j : dist(i, j) <= r}, found by the grid broad phase (contact/broadphase.py) on
  the boundary-edge boxes enlarged by r/2 (two boxes overlap iff their L∞ distance is <= r, a necessary condition
  for dist <= r), then the exact segment distance per edge pair (numba);
* contacts     C = the serial contact set of the detection (detection_2d.detect with the model's interfaces);
* body graph   vertices = bodies, edges = N ∪ {(cand_c, ant_c) : c ∈ C}, weight w_ij = max(1, #contacts between
  i and j) (PETSc edge weights are positive integers);
* owner        owner[i] ∈ {0..P-1}, P = comm.size: PETSc MatPartitioning ("ptscotch" by default) on the graph as a
  distributed MPIAIJ matrix (rows: a contiguous block of bodies per rank, values = weights, converted by PETSc to
  MPIAdj with edge weights), the result gathered on every rank (one int per body);
* per rank p   owned O_p = {i : owner[i] = p}; ghosts G_p = {j ∉ O_p : ∃ i ∈ O_p, (i, j) ∈ N}; owned contacts
  C_p = {c ∈ C : owner[cand_c] = p}, found by the detection on the boundaries of O_p ∪ G_p only (candidate owned);
  the check `RankPartition.check`: every c ∈ C_p has cand_c ∈ O_p and ant_c ∈ O_p ∪ G_p; and, for the contacts
  of the serial set C in its detection order, contact_owner[c] = owner[cand_c] (the contact ownership a
  distributed sweep takes with the serial W), with the exchange lists of the interface impulses
  (`exchange_lists`: contacts sharing a body with a contact owned by another rank).
  Edge cut = Σ_{(i,j) edge, owner[i] ≠ owner[j]} w_ij.

C_p is C restricted to owned candidates because every antagonist edge within r of an owned candidate edge belongs
to O_p ∪ G_p, and the detection's choices (the nearest antagonist edge, ties by edge index; slots by body index)
keep their order when bodies are renumbered increasingly. Dimension 2 only (3D: NotImplementedError).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ..contact import detection_2d as det
from ..contact.broadphase import grid_pairs
from .graph import body_graph, partition_graph  # noqa: F401 (the graph and its partition: graph.py)


@dataclass
class Boundaries:
    """Flat boundary arrays of a subset of bodies (global ids `bodies`, increasing) in the reference placement, in
    local numbering: bx (nbn, 2), bnode_body (local body), bnode_local (node id in the body's mesh), bedges (ne, 2)
    into bx, bedge_body (local body), kind (0 deformable, 1 rigid), group (contact group id) per local body."""
    bodies: np.ndarray
    bx: np.ndarray
    bnode_body: np.ndarray
    bnode_local: np.ndarray
    bedges: np.ndarray
    bedge_body: np.ndarray
    kind: np.ndarray
    group: np.ndarray


def boundaries(model, bodies=None) -> Boundaries:
    """The reference boundaries of `bodies` (global ids; default all) of a 2D model (ContactScene layout: a
    deformable body's type boundary nodes in BlockType.boundary_nodes order, a rigid body's polygon vertices)."""
    if model.dimension != 2:
        raise NotImplementedError("distributed.partition: 2D models only")
    ids = np.arange(len(model.bodies)) if bodies is None else np.unique(np.asarray(bodies, dtype=np.int64))
    gid = {g: k for k, g in enumerate(model.contact.group_names)} if model.contact is not None else None
    xs, nb_, nl, es, eb, kind, group = [], [], [], [], [], [], []
    off = 0
    for k, i in enumerate(ids):
        b = model.bodies[i]
        if b.kind == 0:
            bt = b.type
            X = bt.mesh.points[bt.boundary_nodes] @ b.R0.T + b.position0
            loc = bt.boundary_nodes
            e = bt.bnode_index[bt.mesh.boundary_edges]
        else:
            X = b.center0 + b.vertices_rel
            loc = np.arange(len(X))
            e = np.column_stack([loc, (loc + 1) % len(X)])
        xs.append(X)
        nb_.append(np.full(len(X), k))
        nl.append(loc)
        es.append(e + off)
        eb.append(np.full(len(e), k))
        off += len(X)
        kind.append(b.kind)
        group.append(gid[model.groups[i]] if gid is not None else 0)
    cat = (lambda a: np.concatenate(a).astype(np.int64)) if len(ids) else (lambda a: np.zeros(0, dtype=np.int64))
    return Boundaries(ids, np.concatenate(xs) if len(ids) else np.zeros((0, 2)), cat(nb_), cat(nl),
                      np.concatenate(es).astype(np.int64) if len(ids) else np.zeros((0, 2), dtype=np.int64),
                      cat(eb), np.array(kind, dtype=np.int64), np.array(group, dtype=np.int64))


def search_distance(model) -> float:
    """r = max over the interfaces of g0 + alert (the detection's search distance); 0 without interfaces."""
    if model.contact is None or not model.contact.interfaces:
        return 0.0
    return float(max(i.g0 + i.alert for i in model.contact.interfaces))


@njit(cache=True)
def _seg_point(px, py, ax, ay, bx, by):
    dx, dy = bx - ax, by - ay
    L2 = dx * dx + dy * dy
    t = 0.0 if L2 == 0.0 else ((px - ax) * dx + (py - ay) * dy) / L2
    t = min(max(t, 0.0), 1.0)
    ex, ey = ax + t * dx - px, ay + t * dy - py
    return np.sqrt(ex * ex + ey * ey)


@njit(cache=True)
def _cross(ox, oy, ax, ay, bx, by):
    return (ax - ox) * (by - oy) - (ay - oy) * (bx - ox)


@njit(cache=True)
def _near_edges(pairs, x, e, r):
    """Mask of the edge pairs whose segments are within distance r (0 when they cross)."""
    m = len(pairs)
    keep = np.zeros(m, dtype=np.bool_)
    for k in range(m):
        a0, a1 = x[e[pairs[k, 0], 0]], x[e[pairs[k, 0], 1]]
        b0, b1 = x[e[pairs[k, 1], 0]], x[e[pairs[k, 1], 1]]
        d1 = _cross(a0[0], a0[1], a1[0], a1[1], b0[0], b0[1])
        d2 = _cross(a0[0], a0[1], a1[0], a1[1], b1[0], b1[1])
        d3 = _cross(b0[0], b0[1], b1[0], b1[1], a0[0], a0[1])
        d4 = _cross(b0[0], b0[1], b1[0], b1[1], a1[0], a1[1])
        if ((d1 > 0 and d2 < 0) or (d1 < 0 and d2 > 0)) and ((d3 > 0 and d4 < 0) or (d3 < 0 and d4 > 0)):
            keep[k] = True
            continue
        d = min(_seg_point(a0[0], a0[1], b0[0], b0[1], b1[0], b1[1]),
                _seg_point(a1[0], a1[1], b0[0], b0[1], b1[0], b1[1]),
                _seg_point(b0[0], b0[1], a0[0], a0[1], a1[0], a1[1]),
                _seg_point(b1[0], b1[1], a0[0], a0[1], a1[0], a1[1]))
        keep[k] = d <= r
    return keep


def near_pairs(bnd: Boundaries, r: float) -> np.ndarray:
    """(m, 2) int64 global body pairs (i, j), i < j, with dist(∂i, ∂j) <= r, sorted, once each."""
    if len(bnd.bodies) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    a, b = bnd.bx[bnd.bedges[:, 0]], bnd.bx[bnd.bedges[:, 1]]
    L = np.linalg.norm(b - a, axis=1)
    cell = max(float(np.median(L)), 2 * r, 1e-12)
    ep = grid_pairs(np.minimum(a, b) - 0.5 * r, np.maximum(a, b) + 0.5 * r, bnd.bedge_body, cell)
    ep = ep[_near_edges(ep, bnd.bx, bnd.bedges, float(r))]
    bp = np.sort(bnd.bedge_body[ep], axis=1)
    bp = np.unique(bp, axis=0) if len(bp) else np.zeros((0, 2), dtype=np.int64)
    return bnd.bodies[bp].reshape(-1, 2)


def detect(model, bnd: Boundaries):
    """The contact set (detection_2d.ContactSet) of the bodies of `bnd` in their reference placement, with
    cand_body and ant_body as global body ids (the other fields in the local numbering of `bnd`)."""
    if model.contact is None or len(bnd.bodies) < 2:
        return None
    gid = {g: k for k, g in enumerate(model.contact.group_names)}
    table = det.build_table(model.contact.interfaces, gid)
    cs = det.detect(bnd.bx, bnd.bnode_body, bnd.bnode_local, bnd.bedges, bnd.bedge_body, bnd.kind, bnd.group, table)
    cs.cand_body = bnd.bodies[cs.cand_body]
    cs.ant_body = bnd.bodies[cs.ant_body]
    return cs


def exchange_lists(cand: np.ndarray, ant: np.ndarray, contact_owner: np.ndarray, rank: int) -> tuple[dict, dict]:
    """The interface impulses of a distributed Gauss–Seidel sweep, for rank `rank`: contacts α, β are coupled (a
    nonzero block W_αβ) iff they share a body; rank p needs the impulse of every contact owned elsewhere that is
    coupled to one of its own. Returns (send, recv): send[q] = the contacts owned by `rank` coupled to a contact
    owned by q ≠ rank, recv[q] = the contacts owned by q coupled to a contact owned by `rank` (global contact ids
    of the serial set, increasing; only ranks with a non-empty list). send of p to q = recv of q from p."""
    nc = len(cand)
    C = np.concatenate([np.arange(nc), np.arange(nc)])
    B = np.concatenate([cand, ant]).astype(np.int64)
    R = contact_owner[C]
    # the distinct (body, rank) pairs: the ranks owning a contact on each body
    nr = int(contact_owner.max()) + 1 if nc else 1
    T = np.unique(B * nr + R)
    tb, tr = T // nr, T % nr
    lo, hi = np.searchsorted(tb, B, "left"), np.searchsorted(tb, B, "right")
    k = hi - lo
    alpha = np.repeat(C, k)
    q = tr[np.repeat(lo, k) + (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k))]
    p = contact_owner[alpha]
    keep = p != q
    E = np.unique(np.column_stack([p[keep], q[keep], alpha[keep]]), axis=0)  # (sender, receiver, contact) sorted
    send = {int(r): E[(E[:, 0] == rank) & (E[:, 1] == r), 2] for r in np.unique(E[E[:, 0] == rank, 1])}
    recv = {int(r): E[(E[:, 1] == rank) & (E[:, 0] == r), 2] for r in np.unique(E[E[:, 1] == rank, 0])}
    return send, recv


@dataclass
class RankPartition:
    """What rank `rank` of `size` holds: the owner of every body, its owned and ghost bodies (global ids,
    increasing), its owned contacts (a ContactSet, cand/ant as global ids; None without contacts), the graph
    figures of the whole partition (edge_cut = Σ weights of the cut edges, graph_edges, cut_edges) and timings [s]
    (graph: near pairs, serial detection and CSR; partition: PETSc; local: ghosts and the local detection)."""
    rank: int
    size: int
    owner: np.ndarray
    owned: np.ndarray
    ghost: np.ndarray
    contacts: object
    edge_cut: int
    graph_edges: int
    timers: dict = field(default_factory=dict)
    cut_edges: int = 0  # graph edges between bodies of different ranks (edge_cut counts their weights)
    contact_owner: np.ndarray = None  # (nc,) rank of each contact of the serial contact set (detection order)
    send: dict = None  # exchange_lists: neighbour rank -> owned contacts whose impulses it needs (global ids)
    recv: dict = None  # neighbour rank -> its contacts whose impulses this rank needs

    @property
    def n_contacts(self) -> int:
        return 0 if self.contacts is None else len(self.contacts.gap)

    def check(self):
        """Raise AssertionError unless every owned contact has its candidate owned here and its antagonist owned
        or a ghost here."""
        if self.contacts is None or not len(self.contacts.gap):
            return
        have = np.zeros(len(self.owner), dtype=bool)
        have[self.owned] = True
        if not np.all(have[self.contacts.cand_body]):
            raise AssertionError(f"rank {self.rank}: a contact's candidate body is not owned")
        have[self.ghost] = True
        bad = np.flatnonzero(~have[self.contacts.ant_body])
        if len(bad):
            raise AssertionError(f"rank {self.rank}: contact antagonist bodies {np.unique(self.contacts.ant_body[bad])}"
                                 " are neither owned nor ghosts")


def partition_model(model, comm, method: str = "ptscotch") -> RankPartition:
    """The partition of a 2D model's bodies across `comm` (module docstring) and this rank's part of it, checked.
    Collective. The body graph (near pairs and serial contacts) is built on every rank from the whole model."""
    t = {}
    c0 = time.perf_counter()
    nb = len(model.bodies)
    r = search_distance(model)
    bnd = boundaries(model)
    pairs = near_pairs(bnd, r)
    cs = detect(model, bnd)
    cand = cs.cand_body if cs is not None else np.zeros(0, dtype=np.int64)
    ant = cs.ant_body if cs is not None else np.zeros(0, dtype=np.int64)
    indptr, indices, weights = body_graph(nb, pairs, cand, ant)
    t["graph"] = time.perf_counter() - c0
    c0 = time.perf_counter()
    owner = partition_graph(indptr, indices, weights, comm, method)
    t["partition"] = time.perf_counter() - c0
    c0 = time.perf_counter()
    rows = np.repeat(np.arange(nb), np.diff(indptr))
    cross = owner[rows] != owner[indices]
    cut = int(weights[cross].sum()) // 2
    p = comm.rank
    owned = np.flatnonzero(owner == p)
    mine = owner[pairs] == p
    ghost = np.setdiff1d(np.concatenate([pairs[mine[:, 0], 1], pairs[mine[:, 1], 0]]), owned)
    local = detect(model, boundaries(model, np.concatenate([owned, ghost])))
    if local is not None:
        local = local.subset(np.flatnonzero(owner[local.cand_body] == p))
    t["local"] = time.perf_counter() - c0
    rp = RankPartition(p, comm.size, owner, owned, ghost, local, cut, len(indices) // 2, t, int(cross.sum()) // 2,
                       owner[cand])
    rp.send, rp.recv = exchange_lists(cand, ant, rp.contact_owner, p)
    rp.check()
    return rp


def save_rank(rp: RankPartition, path: str):
    """Write this rank's partition to `path` (.npz): owner, owned, ghost, edge_cut, graph_edges, the owned contacts'
    cand_body, ant_body, cand_nodes, ant_nodes, point, gap, interface, and the timers."""
    cs = rp.contacts
    z = np.zeros(0, dtype=np.int64)
    np.savez(path, rank=rp.rank, size=rp.size, owner=rp.owner, owned=rp.owned, ghost=rp.ghost, edge_cut=rp.edge_cut,
             graph_edges=rp.graph_edges, cand_body=cs.cand_body if cs is not None else z,
             ant_body=cs.ant_body if cs is not None else z,
             cand_nodes=cs.cand_nodes if cs is not None else z.reshape(0, 2),
             ant_nodes=cs.ant_nodes if cs is not None else z.reshape(0, 2),
             point=cs.point if cs is not None else np.zeros((0, 2)), gap=cs.gap if cs is not None else np.zeros(0),
             interface=cs.interface if cs is not None else z, contact_owner=rp.contact_owner,
             **{f"send{q}": v for q, v in rp.send.items()}, **{f"recv{q}": v for q, v in rp.recv.items()},
             timers=np.array([rp.timers.get(k, 0.0) for k in ("graph", "partition", "local")]))


def main(argv=None):
    """mpirun -n N python -m fem_blocks.distributed.partition CASE.toml OUT_PREFIX [--method ptscotch]: the
    partition of the case's bodies; each rank writes OUT_PREFIX.rank<p>.npz (save_rank) and prints one line."""
    import argparse
    from mpi4py import MPI
    from ..case import load_case
    from ..model import build_model
    ap = argparse.ArgumentParser(description=main.__doc__.splitlines()[0])
    ap.add_argument("case")
    ap.add_argument("out")
    ap.add_argument("--method", default="ptscotch")
    a = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    c0 = time.perf_counter()
    model = build_model(load_case(a.case))
    t_model = time.perf_counter() - c0
    rp = partition_model(model, comm, a.method)
    save_rank(rp, f"{a.out}.rank{comm.rank}.npz")
    print(f"rank {rp.rank}/{rp.size}: bodies {len(rp.owned)} owned, {len(rp.ghost)} ghosts; contacts {rp.n_contacts}; "
          f"edge cut {rp.edge_cut} of {rp.graph_edges} edges; model {t_model:.2f} s, "
          + ", ".join(f"{k} {v:.3f} s" for k, v in rp.timers.items()), flush=True)


if __name__ == "__main__":
    main()
