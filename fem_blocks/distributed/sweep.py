"""Distributed colour-order Gauss–Seidel: rows of W owned per rank, only interface impulses exchanged.

Problem (solver/nlgs.py, FCLIB convention, d = 2 or 3 rows per contact, normal first):

    u = W r + q,   r_N >= 0, u_N >= 0, r_N u_N = 0,   ‖r_T‖ <= mu r_N  (Coulomb).

Contacts are coloured so that two contacts of one colour are uncoupled (W_αβ = W_βα = 0, e.g.
`solver.parallel.colour_contacts`). One sweep visits the colours c = 0, 1, ... in turn; for every contact α of
colour c it computes v_α = q_α + Σ_{β≠α} W_αβ r_β and the exact local solve r_α = local(W_αα, v_α, mu_α)
(`nlgs.sweep`). Contacts of one colour read no impulse of their own colour, so the result does not depend on the
order within a colour: this is the serial Gauss–Seidel sweep in colour order (`parallel.colour_order`).

Distribution. Rank p owns a set of contacts (any disjoint cover, e.g. contiguous blocks or the contacts of its
bodies) and holds only their rows W_α· (columns renumbered: owned contacts first, then the *ghost* contacts, the
ones its rows couple to and owned elsewhere), q_α, mu_α, and the impulses r of owned and ghost contacts. After its
contacts of colour c are solved, the new impulses of colour c are sent to the ranks that hold them as ghosts: one
PETSc VecScatter per colour (from the distributed impulse vector, d entries per contact, to the rank's ghost array),
so messages go only to neighbour ranks and carry only the colour's interface impulses. Sums over a row are taken in
the stored column order of the global row (sorted by global contact number), so every rank computes each v_α
bitwise as the serial sweep does: N ranks give the serial colour-order iterates, bitwise, for any N and ownership.

The solve is `colour.ColourSolver`'s (its sweep loop over these rows and scatters, its stopping tests with exact
sums: the same sweep count and residual on any N); this module is its set-up on N ranks (`DistSweep`: the rows,
the scatters and the exchange counters) and the contact ownerships of the file driver (`python -m
fem_blocks.distributed.colour`).

"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..linalg import BlockCSR


@dataclass
class LocalRows:
    """The rows of W owned by one rank. Local contact numbering: owned[0..n_own) then ghost[0..n_ghost).
    indptr/indices/blocks/diag_pos: block-CSR of the owned rows, column indices local, in the global row's order."""
    owned: np.ndarray    # (n_own,) int64 global contact numbers, increasing (in the solver: in sweep order)
    ghost: np.ndarray    # (n_ghost,) int64 global numbers of the coupled contacts owned elsewhere, increasing
    indptr: np.ndarray
    indices: np.ndarray
    blocks: np.ndarray
    diag_pos: np.ndarray
    q: np.ndarray        # (d n_own,)
    mu: np.ndarray       # (n_own,)

    @property
    def dim(self) -> int:
        return self.blocks.shape[1]


def local_rows(W: BlockCSR, q, mu, owned) -> LocalRows:
    """The rows of the contacts `owned` (global numbers) of a global block-CSR W (a test and file driver's helper:
    in the time stepper each rank assembles its own rows directly, in its sweep order,
    colour.ColourSolver.from_sweep_rows)."""
    owned = np.unique(np.asarray(owned, dtype=np.int64))
    d = W.dim
    q = np.asarray(q, dtype=np.float64).reshape(-1, d)
    mu = np.broadcast_to(np.asarray(mu, dtype=np.float64).ravel(), (W.n,))
    starts, ends = W.indptr[owned], W.indptr[owned + 1]
    cnt = ends - starts
    pos = np.repeat(starts - np.cumsum(cnt) + cnt, cnt) + np.arange(cnt.sum())  # entries of the owned rows, in order
    indptr = np.concatenate([[0], np.cumsum(cnt)]).astype(np.int64)
    dpos = W.diag_pos[owned]
    diag = np.where(dpos >= 0, dpos - starts + indptr[:-1], -1).astype(np.int64)
    rows = localise(owned, indptr, W.indices[pos], np.ascontiguousarray(W.blocks[pos]), diag)
    rows.q, rows.mu = np.ascontiguousarray(q[owned]).ravel(), np.ascontiguousarray(mu[owned])
    return rows


def localise(owned, indptr, cols, blocks, diag_pos, in_place: bool = False) -> LocalRows:
    """LocalRows of the rows of the contacts `owned` (global numbers, distinct; row i is owned[i]'s): block-CSR
    indptr, global column numbers `cols` (increasing per row), blocks and the diagonal positions within these rows;
    the columns renumbered owned first (in the order given), then the ghosts (the other columns, increasing), their
    order within a row kept. in_place: `cols` (int64) itself renumbered, no second array of column numbers. q and
    mu empty."""
    owned = np.asarray(owned, dtype=np.int64)
    cols = np.asarray(cols, dtype=np.int64)
    # a table over the global numbers (linear in the blocks and the contacts, no sort of the blocks' columns):
    # the columns met, less the owned ones, are the ghosts (increasing); local number = owned's position, then
    # the ghost's after them
    top = int(max(cols.max(initial=-1), owned.max(initial=-1))) + 1
    seen = np.zeros(top, dtype=bool)
    seen[cols] = True
    seen[owned] = False
    ghost = np.flatnonzero(seen).astype(np.int64)
    lut = np.empty(top, dtype=np.int64)
    lut[owned] = np.arange(owned.size, dtype=np.int64)
    lut[ghost] = owned.size + np.arange(ghost.size, dtype=np.int64)
    local = np.take(lut, cols, out=cols, mode="clip") if in_place else lut[cols]  # ("clip": not buffered)
    return LocalRows(owned, ghost, np.asarray(indptr, dtype=np.int64), local, blocks,
                     np.asarray(diag_pos, dtype=np.int64), np.zeros(0), np.zeros(0))


class DistSweep:
    """Set-up of the distributed colour-order sweep on `comm` (collective): rows = this rank's LocalRows,
    colour_local = the colour of every local contact (owned then ghost), n_colours = the global number of colours.
    """

    def __init__(self, rows: LocalRows, colour_local, n_colours: int, comm):
        from petsc4py import PETSc
        self.comm = comm
        d = rows.dim
        self.d = d
        n_own, n_gh = rows.owned.size, rows.ghost.size
        colour_local = np.asarray(colour_local, dtype=np.int64)
        if colour_local.size != n_own + n_gh:
            raise InputError(f"colour_local: expected {n_own + n_gh} colours (owned then ghost), got {colour_local.size}")
        pcomm = PETSc.Comm(comm)
        # PETSc numbering: rank p's owned contacts are start_p .. start_p + n_own - 1 (LocalRows.owned order)
        start = comm.exscan(n_own) or 0
        self.n_total = comm.allreduce(n_own)
        ao = PETSc.AO().createMapping(rows.owned.astype(PETSc.IntType),
                                      np.arange(start, start + n_own, dtype=PETSc.IntType), comm=pcomm)
        gh_petsc = np.asarray(ao.app2petsc(rows.ghost.astype(PETSc.IntType)), dtype=np.int64)
        ao.destroy()
        if np.any(gh_petsc < 0):
            raise InputError("ghost contacts not owned by any rank (the ownership must cover every contact)")
        self.r = np.zeros(d * (n_own + n_gh))
        self.vec = PETSc.Vec().createMPI((d * n_own, d * self.n_total), bsize=d, comm=pcomm)
        self.vec.placeArray(self.r[:d * n_own])  # the owned impulses are the distributed vector's local part
        self.gvec = PETSc.Vec().createSeq(d * n_gh, bsize=d, comm=PETSc.COMM_SELF)
        self.gvec.placeArray(self.r[d * n_own:])
        cown, cgh = colour_local[:n_own], colour_local[n_own:]
        self.order = []
        self.scatters = []
        self.n_colours = int(n_colours)
        for c in range(self.n_colours):
            self.order.append(np.ascontiguousarray(np.flatnonzero(cown == c), dtype=np.int64))
            g = np.flatnonzero(cgh == c)
            isf = PETSc.IS().createBlock(d, gh_petsc[g].astype(PETSc.IntType), comm=PETSc.COMM_SELF)
            ist = PETSc.IS().createBlock(d, g.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
            self.scatters.append(PETSc.Scatter().create(self.vec, isf, self.gvec, ist))
            isf.destroy()
            ist.destroy()
        # exchange volume: entries received = ghost entries; entries sent = Σ_owned (ranks that ghost it), counted
        # by a reverse scatter (ADD) of ones; messages received = (colour, owner rank) pairs among the ghosts
        remote_owner = np.searchsorted(np.asarray(comm.allgather(start + n_own)), gh_petsc, side="right")
        ones = PETSc.Vec().createSeq(d * n_gh, bsize=d, comm=PETSc.COMM_SELF)
        ones.set(1.0)
        sent = []
        per_colour_msgs = 0
        cnt = PETSc.Vec().createMPI((d * n_own, d * self.n_total), bsize=d, comm=pcomm)
        for c in range(self.n_colours):
            cnt.set(0.0)
            self.scatters[c].scatter(ones, cnt, addv=PETSc.InsertMode.ADD_VALUES, mode=PETSc.ScatterMode.REVERSE)
            sent.append(float(cnt.getArray().sum()))
            per_colour_msgs += int(np.unique(remote_owner[cgh == c]).size)  # messages received per colour
        cnt.destroy()
        ones.destroy()
        self.entries_sent = int(round(sum(sent)))
        self.entries_recv = d * n_gh
        self.messages = per_colour_msgs  # messages received per sweep (one per colour and neighbour owner)
        self.start = start

    def destroy(self):
        for s in self.scatters:
            s.destroy()
        self.vec.resetArray()
        self.gvec.resetArray()
        self.vec.destroy()
        self.gvec.destroy()


def exchange(comm, x, scounts, rcounts=None):
    """COLLECTIVE: the rows x (n, ...) (int64 or float64) sent in order, scounts[p] of them to rank p (x grouped by
    destination rank, in rank order); returns (the rows received, grouped by sending rank in rank order, rcounts).
    One Alltoall of the counts, unless `rcounts` (the rows to receive from each rank) is known — the reply to an
    exchange, whose scounts they are — and one Alltoallv."""
    from mpi4py import MPI
    x = np.ascontiguousarray(x)
    if x.dtype not in (np.int64, np.float64):
        raise TypeError(f"exchange: rows of int64 or float64, got {x.dtype}")
    scounts = np.asarray(scounts, dtype=np.int64)
    if rcounts is None:
        rcounts = np.empty(scounts.size, dtype=np.int64)
        comm.Alltoall(scounts, rcounts)
    rcounts = np.asarray(rcounts, dtype=np.int64)
    w = int(np.prod(x.shape[1:], dtype=np.int64))
    out = np.empty((int(rcounts.sum()),) + x.shape[1:], dtype=x.dtype)
    mt = MPI.DOUBLE if x.dtype == np.float64 else MPI.INT64_T
    comm.Alltoallv([x.reshape(-1), (scounts * w, (np.cumsum(scounts) - scounts) * w), mt],
                   [out.reshape(-1), (rcounts * w, (np.cumsum(rcounts) - rcounts) * w), mt])
    return out, rcounts


def gather_rows(comm, order, counts, x: np.ndarray) -> np.ndarray:
    """COLLECTIVE: the rows x (n_own, ...) of every rank's own contacts as the rows of every contact in contact order,
    on every rank (one Allgatherv). order: every contact grouped by owner rank (rank 0's own contacts, then rank
    1's, ..., each rank's in the order of its rows), counts: the number each rank owns."""
    from mpi4py import MPI
    x = np.ascontiguousarray(x)
    shape = x.shape[1:]
    width = int(np.prod(shape, dtype=np.int64))
    buf = np.empty((int(counts.sum()),) + shape, dtype=x.dtype)
    displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
    mt = MPI.DOUBLE if x.dtype == np.float64 else MPI.INT64_T
    comm.Allgatherv(x.ravel(), [buf.reshape(-1), counts * width, displs * width, mt])
    out = np.empty_like(buf)
    out[order] = buf
    return out


class OwnRowsGather:
    """COLLECTIVE when called: gather(x), the rows x (n_own, ...) of every rank's own contacts as the rows of every
    contact, in the whole contact set's order (increasing contact id, contact/matching.contact_ids), on every rank
    (one Allgatherv). ids: this rank's own contacts' ids, increasing. The layout (every rank's ids: n integers on
    every rank) is gathered at the first call only, for the outputs that need every contact (and the step's rows of
    a run leaving colour order); a step in colour order never calls it."""

    def __init__(self, comm, ids):
        self.comm, self.ids, self._layout = comm, np.asarray(ids, dtype=np.int64), None

    def layout(self):
        """(order, counts): gather_rows' layout, made once (two all-gathers); RuntimeError on every rank if two
        ranks hold the same contact."""
        if self._layout is None:
            from mpi4py import MPI
            counts = np.array(self.comm.allgather(self.ids.size), dtype=np.int64)
            every = np.empty(int(counts.sum()), dtype=np.int64)
            self.comm.Allgatherv(self.ids, [every, counts, np.concatenate([[0], np.cumsum(counts)[:-1]]),
                                            MPI.INT64_T])
            o = np.argsort(every, kind="stable")
            if np.any(every[o][1:] == every[o][:-1]):
                raise RuntimeError("the ranks' own contacts overlap: a contact id held by two ranks")
            order = np.empty(every.size, dtype=np.int64)
            order[o] = np.arange(every.size)
            self._layout = (order, counts)
        return self._layout

    def __call__(self, x):
        return gather_rows(self.comm, *self.layout(), x)


def gather_fields(gather, fields: dict) -> dict:
    """COLLECTIVE: every array of `fields` (rows of this rank's contacts, the same number of rows each; int or
    float) gathered by `gather` (`OwnRowsGather` or gather_rows bound to a layout) in two gathers: the integer
    arrays packed side by side in one int64 buffer, the floating-point ones in one float64 buffer. Returns the
    gathered arrays, each with its dtype and trailing shape."""
    fields = {k: np.asarray(v) for k, v in fields.items()}
    n = len(next(iter(fields.values()))) if fields else 0
    out = {}
    for floats, dt in ((False, np.int64), (True, np.float64)):
        names = [k for k, v in fields.items() if (v.dtype.kind == "f") == floats]
        if not names:
            continue
        cols = [fields[k].reshape(n, int(np.prod(fields[k].shape[1:], dtype=np.int64))).astype(dt, copy=False)
                for k in names]
        rows = gather(np.hstack(cols))
        at = np.cumsum([0] + [c.shape[1] for c in cols])
        for i, k in enumerate(names):
            v = fields[k]
            out[k] = np.ascontiguousarray(rows[:, at[i]:at[i + 1]].reshape((len(rows),) + v.shape[1:])).astype(
                v.dtype, copy=False)
    return out


def ownership(n: int, size: int, kind: str = "blocks") -> np.ndarray:
    """Owner rank per contact: "blocks" contiguous blocks in contact order, "cyclic" contact a on rank a mod size,
    "skip0" contiguous blocks on ranks 1..size-1 and none on rank 0 (size >= 2); "ptscotch": see
    partition_contacts (collective, through the file driver only)."""
    if kind == "blocks":
        return (np.arange(n) * size // max(n, 1)).astype(np.int64)
    if kind == "cyclic":
        return (np.arange(n) % size).astype(np.int64)
    if kind == "skip0":
        if size < 2:
            return np.zeros(n, dtype=np.int64)
        return 1 + (np.arange(n) * (size - 1) // max(n, 1)).astype(np.int64)
    raise InputError(f"ownership {kind!r}: expected 'blocks', 'cyclic' or 'skip0'")


def partition_contacts(W: BlockCSR, comm, kind: str = "ptscotch") -> np.ndarray:
    """Owner rank per contact from PETSc MatPartitioning (`kind`) of the contact graph (α ~ β when W_αβ ≠ 0 or
    W_βα ≠ 0); a stand-in, in the file driver, for the ownership by bodies of the time stepper. Collective; each
    rank passes the rows of its contiguous block of contacts, every rank returns the whole owner array."""
    import scipy.sparse as sp
    from petsc4py import PETSc
    size, rank = comm.Get_size(), comm.Get_rank()
    n = W.n
    if size == 1:
        return np.zeros(n, dtype=np.int64)
    lo, hi = rank * n // size, (rank + 1) * n // size
    A = sp.csr_matrix((np.ones(W.indices.size), W.indices, W.indptr), shape=(n, n))
    S = (A + A.T).tocsr()[lo:hi]
    S.setdiag(0, k=lo)
    S.eliminate_zeros()
    S.sort_indices()
    adj = PETSc.Mat().createAIJ(size=((hi - lo, n), (hi - lo, n)), comm=PETSc.Comm(comm),
                                csr=(S.indptr.astype(PETSc.IntType), S.indices.astype(PETSc.IntType),
                                     np.ones(S.nnz)))
    part = PETSc.MatPartitioning().create(comm=PETSc.Comm(comm))
    part.setAdjacency(adj)
    part.setType(kind)
    isp = PETSc.IS()
    part.apply(isp)
    owner = np.concatenate(comm.allgather(np.asarray(isp.getIndices(), dtype=np.int64)))
    isp.destroy()
    part.destroy()
    adj.destroy()
    return owner
