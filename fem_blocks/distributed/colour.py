"""Nonlinear Gauss–Seidel in colour order, on one process or on N MPI ranks with the same iterates (`[contact] order =
"colours"`).

Problem (solver/problem.py; d = 2 or 3 entries per contact, normal first): u = W r + q with Signorini–Coulomb or an
interface law per contact (the transformed impulse P̃ = P + h A r_adh(u) of docs/laws.md).

Colours. Two contacts α, β are coupled when W_αβ ≠ 0 or W_βα ≠ 0 (they share a body that moves). Contacts are
grouped by their (candidate, antagonist) body pair; two groups are coupled when one of their contacts is coupled
to one of the other's. The greedy colouring of the group graph (groups in increasing (candidate, antagonist)
order, `colour_groups`) gives colours c = 0, 1, ... whose contacts of different groups are uncoupled. A sweep visits the colours in turn
and the contacts of colour c in increasing contact number; for each contact α it computes
v_α = q_α + Σ_{β≠α} W_αβ r_β and the exact local solve of solver/nlgs.py (the same numba kernels: `_sweep`,
`_sweep3`, `_sweep_cohesive`, `_sweep_cohesive3`). The contacts of one group are swept one after the other (they
are coupled); a contact reads no impulse of another group of its colour, so how the groups of a colour interleave
does not matter: this is the serial Gauss–Seidel sweep in colour order. (Without the body pairs, `ColourSolver`
colours the contacts themselves, solver/parallel.colour_contacts: pairwise uncoupled contacts per colour. A
deformable brick couples all its contact points through its W_bb, so that needs far more colours, and every colour
is one exchange between ranks: on the running-bond walls of bench/bench_dist.py 200 (10³ bricks) and 641 (10⁴)
contact colours against 6 group colours. Blocks of zeros count: with them, the contacts on a fixed foundation all
couple and the groups need 25 and 74 colours.)

Distribution (comm with N > 1 ranks; distributed/sweep.py). Rank p owns the contacts `owner == p` (the time stepper:
the rank of the contact's candidate body, distributed/partition.py; with groups, one group's contacts must have one
owner) and holds their rows of W (without the blocks of zeros, `coupling_rows`, as the serial sweep; column order of
the global row kept, so every v_α is summed exactly as serially), q_α, μ_α, the law data and the impulses of its
contacts and of the *ghost* contacts its rows couple to. The rows come from the whole W (`ColourSolver`) or are
assembled by the rank itself (`ColourSolver.from_rows`, the time stepper: each rank colours its own groups from its
rows, distributed/greedy.py, the colours of the whole group graph without gathering it). After colour c, one PETSc
scatter carries the new impulses of colour c to the ranks that hold them as ghosts (neighbour ranks only). The iterates
are the serial ones, bitwise, for any N and any ownership.

Stopping tests, as solver/nlgs.py's `_run` / `_run_cohesive` / `solve_cohesive`, with every sum over contacts exact
(distributed/exact.py: correctly rounded, independent of the order of the terms and of how they are split among
ranks), so the decisions, the sweep count and the reported change and residual are bitwise the same on any N:

    change    = sqrt(Σ (r_new - r_old)² / Σ r_new²) over a sweep (sqrt(Σ (r_new - r_old)²) when r_new = 0),
    residual  = sqrt(Σ_α ‖F_α‖²) / ‖q‖,  F_α the FCLIB natural map (Coulomb) or the transformed problem's map
                (interface laws, nlgs.natural_map_cohesive_terms), ‖q‖ = sqrt(Σ q_i²),
    interface laws: staggered passes at fixed internal variables x, then x from the converged jumps
                (nlgs._update_internal) until max_α |Δx_α| <= 1e-12 (the max is order-independent).

These sums are not the running sums of solver/nlgs.py (which add in sweep order), so "colours" is its own order:
its results are compared with itself across N, and with the "given" order within the solver's tolerance.

Run: `mpirun -n N python -m fem_blocks.distributed.colour PROBLEM OUT.npz [--own blocks|cyclic|skip0|ptscotch]
[--tol T] [--max-sweeps S]` (PROBLEM: an FCLIB .hdf5 or an .npz with indptr, indices, blocks, diag_pos, q, mu and
optionally tol). It solves with `ColourSolver(W, contact_owner=owner, comm)`, contacts coloured one by one
(`parallel.colour_contacts`), residual criterion checked every 10 sweeps; OUT on rank 0: r, sweeps, residual,
converged, ranks, t_setup, and per rank n_own, n_ghost, t_solve, bytes_sent, bytes_recv, messages (per sweep).
(The former `--residual ordered|allreduce` option and the timings t_sweeps, t_exchange, t_check of the driver's own
sweep loop are gone with that loop: the stopping test is ColourSolver's.)
"""
from __future__ import annotations

import sys
import time

import numpy as np

from ..errors import InputError
from ..linalg import BlockCSR, matvec_bcsr
from ..solver import nlgs
from ..solver.parallel import colour_contacts, pair_colouring
from ..solver.problem import SolverResult
from .exact import exact_sums, largest

MAX_OUTER = 100      # interface laws: most staggered passes (solver/nlgs.solve_cohesive's max_outer)
X_TOL = 1e-12        # interface laws: the internal variables have stopped changing


def body_pair_groups(cand, ant, nb: int) -> tuple[np.ndarray, int]:
    """(group of each contact, number of groups): contacts grouped by (candidate, antagonist) body pair, groups
    numbered in increasing (candidate, antagonist) order."""
    cand = np.asarray(cand, dtype=np.int64)
    ant = np.asarray(ant, dtype=np.int64)
    keys, group = np.unique(cand * nb + ant, return_inverse=True)
    return group.astype(np.int64).ravel(), int(keys.size)


def colour_group_graph(n_groups: int, ga, gb) -> np.ndarray:
    """Colour per group: greedy (groups in increasing number) on the symmetric graph of the group pairs
    (ga[k], gb[k]) (self-pairs allowed, they couple nothing): solver/parallel.pair_colouring, the colouring of
    single contacts too. (On N > 1 ranks each rank colours its own groups: distributed/greedy.py, the same
    colours.)"""
    ga = np.asarray(ga, dtype=np.int64)
    gb = np.asarray(gb, dtype=np.int64)
    e = np.unique(ga * n_groups + gb)
    return pair_colouring(n_groups, e // n_groups, e % n_groups)


def _nonzero_blocks(W: BlockCSR):
    """(rows, cols): the row and column of every block of W with a nonzero entry (rows numbered 0..W.n-1)."""
    nz = np.any(W.blocks != 0.0, axis=(1, 2))
    rows = np.repeat(np.arange(W.n, dtype=np.int64), np.diff(W.indptr))
    return rows[nz], W.indices[nz]


def colour_groups(W: BlockCSR, cand, ant, nb: int) -> np.ndarray:
    """Colour per contact: contacts grouped by (candidate, antagonist) body pair; two groups are coupled when a
    contact of one and a contact of the other have a block W_αβ with a nonzero entry (they share a body that moves:
    through a body held in every dof, like a fixed foundation, the assembly stores blocks of zeros, which couple
    nothing: 0·r_β is 0 whatever the ghost copy of r_β holds); coupled groups get different colours (greedy,
    groups in increasing (candidate, antagonist) order, `colour_group_graph`); every contact takes its group's
    colour."""
    cand = np.asarray(cand, dtype=np.int64)
    if cand.size == 0:
        return np.zeros(0, dtype=np.int64)
    group, ng = body_pair_groups(cand, ant, nb)
    rows, cols = _nonzero_blocks(W)
    return colour_group_graph(ng, group[rows], group[cols])[group]


def coupling_rows(W: BlockCSR) -> BlockCSR:
    """W without its off-diagonal blocks of zeros (the assembly stores them between contacts that share only a body
    held in every dof): the rows the colour solver sweeps. A contact then reads only the impulses it is coupled to,
    so that reading a ghost impulse of its own colour before that colour's exchange (a block of zeros, the colours
    ignore it) cannot happen; the sums of the other blocks keep their order. W itself if it has none."""
    keep = np.any(W.blocks != 0.0, axis=(1, 2))
    keep[W.diag_pos[W.diag_pos >= 0]] = True
    if keep.all():
        return W
    row = np.repeat(np.arange(W.n), np.diff(W.indptr))
    cnt = np.bincount(row[keep], minlength=W.n)
    new_pos = np.cumsum(keep) - 1
    diag = np.where(W.diag_pos >= 0, new_pos[np.maximum(W.diag_pos, 0)], -1).astype(np.int64)
    return BlockCSR(np.concatenate([[0], np.cumsum(cnt)]).astype(np.int64), np.ascontiguousarray(W.indices[keep]),
                    np.ascontiguousarray(W.blocks[keep]), diag)


def _in_sweep_order(lr, colour_own, shared: bool, fresh_indices: bool = False):
    """The rows `lr` (sweep.LocalRows) with the owned contacts renumbered in sweep order: by colour, increasing
    contact number within a colour (the order the sweep visits them), so that the rows of a colour lie one after
    the other in memory and a sweep streams through W instead of jumping between colours' rows. The rows move in
    place (linalg.permute_rows; a copy first if `shared`: the blocks are still the caller's, or, without
    `fresh_indices`, the column indices); the ghosts keep their numbers after the owned ones. Every row keeps its
    blocks in their order, so each local velocity is summed as before and the iterates keep their bits. Returns
    (LocalRows in sweep order, the colours of its owned contacts in that order)."""
    from ..linalg import permute_rows
    from .sweep import LocalRows
    no = lr.owned.size
    colour_own = np.asarray(colour_own, dtype=np.int64)
    perm = np.argsort(colour_own, kind="stable").astype(np.int64)  # sweep position i <- local contact perm[i]
    relabel = np.arange(no + lr.ghost.size, dtype=np.int64)
    relabel[perm] = np.arange(no, dtype=np.int64)
    blocks = lr.blocks.copy() if shared else lr.blocks
    indices = lr.indices if fresh_indices or not shared else lr.indices.copy()
    indptr = np.asarray(lr.indptr, dtype=np.int64)
    dpos = lr.diag_pos[perm]
    indptr_new = permute_rows(indptr, indices, blocks, perm, relabel)
    diag = np.where(dpos >= 0, dpos - indptr[perm] + indptr_new[:-1], -1).astype(np.int64)
    return (LocalRows(lr.owned[perm], lr.ghost, indptr_new, indices, blocks, diag, lr.q, lr.mu),
            colour_own[perm])


def _signature(W: BlockCSR, *arrays) -> bytes | None:
    """What fixes a colour solver's structure besides its blocks' values (ColourSolver's `previous`): W's block
    pattern (indptr, indices) and the arrays given (contacts, groups, owners), as a digest (SHA-256: 2.5 times
    faster than blake2b on this CPU's SHA instructions, 0.04 s for 50 MB); None if W has an off-diagonal block of
    zeros (its colours would depend on the values: `coupling_rows`)."""
    import hashlib
    if coupling_rows(W) is not W:
        return None
    h = hashlib.sha256()
    for a in (W.indptr, W.indices) + arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape};".encode())
        h.update(a.tobytes() if a.ndim == 0 else memoryview(a).cast("B"))
    return h.digest()


class ColourSolver:
    """The colour-order NLGS for one Delassus operator W (set up once per W; collective when `comm` has N > 1
    ranks). contact_owner: (nc,) rank of each contact (N > 1); comm: an mpi4py communicator or None (serial);
    bodies: (cand, ant, nb) the contacts' body pairs and the number of bodies (colours of body-pair groups,
    `colour_groups`; every group must have one owner), or None (contacts coloured one by one).

    The solver sweeps its rows in sweep order (`_in_sweep_order`: a colour's rows one after the other in memory).
    take_rows=True gives it W's arrays: they are put in that order in place and W, kept as `self.W` only to
    recognise the operator, is no longer a valid operator (the contact step, which assembles W for the solver
    alone); otherwise the solver works on its own copy (W unchanged).

    previous: the solver of the operator before (updated geometry: W is assembled again at every step, mostly for
    the same contacts). When the new operator has the structure of the previous one — the same contacts, body-pair
    groups and owners, the same block pattern row by row, and no block of zeros (`_signature`) — the colours, the
    sweep order and the PETSc scatters are those the new operator would get (they depend on that structure only),
    so they are taken over (`_take_over`) and only the new blocks are put in sweep order: the same solver, bit for
    bit, as one built from scratch, without the colouring and the rows' permutation (most of the set-up). On N > 1
    ranks the ranks take over only if every rank can (one all-reduce). `previous` is then spent (its PETSc objects
    are this solver's); otherwise it is left as it is, for its owner to destroy. reusable: keep what a next
    solver needs to take this one over (set when `previous` is given)."""

    def __init__(self, W: BlockCSR, contact_owner=None, comm=None, bodies=None, take_rows: bool = False,
                 previous: "ColourSolver | None" = None, reusable: bool = False):
        self.W = W
        self.d = W.dim
        n = self.n = W.n
        self.comm = comm if comm is not None and comm.Get_size() > 1 else None
        self._sig = None
        if (previous is not None or reusable) and bodies is not None and self.comm is None:
            cand, ant, nb = bodies
            self._sig = _signature(W, n, np.asarray(cand, dtype=np.int64), np.asarray(ant, dtype=np.int64),
                                   np.int64(nb))
            if self._take_over(previous, W, take_rows):
                return
        if bodies is not None:
            cand, ant, nb = bodies
            if len(cand) != n or len(ant) != n:
                raise InputError(f"bodies: expected the body pairs of {n} contacts")
            colour = colour_groups(W, cand, ant, int(nb))
        else:
            colour = colour_contacts(W) if n else np.zeros(0, dtype=np.int64)
        self.colour = colour
        self.n_colours = int(colour.max()) + 1 if n else 0
        self.dist = None
        Wc = coupling_rows(W) if n else W
        if self.comm is None:
            from .sweep import LocalRows
            self.owned = np.arange(n, dtype=np.int64)
            self.ghost = np.zeros(0, dtype=np.int64)
            lr = LocalRows(self.owned, self.ghost, Wc.indptr, Wc.indices, Wc.blocks, Wc.diag_pos, np.zeros(0),
                           np.zeros(0))
            self._ip0 = np.array(lr.indptr, dtype=np.int64) if self._sig is not None else None
            lr, c_sweep = _in_sweep_order(lr, colour, shared=Wc is W and not take_rows)
            self._sweep = lr.owned
            self._back = np.searchsorted(self.owned, self._sweep)  # sweep position -> position in `owned`
            self.rows = (lr.indptr, lr.indices, lr.blocks, lr.diag_pos)
            if take_rows:
                self._give_rows(W)
            self.order = [np.ascontiguousarray(np.flatnonzero(c_sweep == c), dtype=np.int64)
                          for c in range(self.n_colours)]
            self.r = np.zeros(self.d * n)
            return
        from .sweep import local_rows
        owner = np.asarray(contact_owner, dtype=np.int64)
        if owner.shape != (n,):
            raise InputError(f"contact_owner: expected {n} ranks (one per contact), got shape {owner.shape}")
        lr = local_rows(Wc, np.zeros(self.d * n), np.zeros(n), np.flatnonzero(owner == self.comm.Get_rank()))
        del Wc
        self._distribute(lr, colour[np.concatenate([lr.owned, lr.ghost])], shared=False)

    @classmethod
    def from_rows(cls, rows: BlockCSR, owned, columns, n: int, group, owner, comm,
                  take_rows: bool = False, previous: "ColourSolver | None" = None,
                  reusable: bool = False) -> "ColourSolver":
        """The colour solver of a run whose ranks hold only the rows of their own contacts (collective on `comm`,
        N > 1 ranks). rows: the rows of W of this rank's contacts `owned` (global numbers, increasing; row i is
        contact owned[i]), their column k meaning contact columns[k] (global numbers, increasing), as
        delassus.assemble(..., rows=...) gives them on a rank's contact subset; n: the number of contacts of the
        whole run; group: (n,) the body-pair group of every contact (`body_pair_groups`); owner: (n,) the rank of
        every contact (one per group). The colours are those of `colour_groups` on the whole W: the greedy colouring
        of the group graph, each rank colouring its own groups from the nonzero blocks of its rows
        (distributed/greedy.py, no rank holds the whole graph), so the iterates are those of one process in colour
        order, bitwise. take_rows, previous, reusable: as for the constructor."""
        from .greedy import greedy_colours
        from .sweep import localise
        self = cls.__new__(cls)
        self.W, self.d, self.n = rows, rows.dim, int(n)
        self.comm = comm
        owned = np.asarray(owned, dtype=np.int64)
        columns = np.asarray(columns, dtype=np.int64)
        group = np.asarray(group, dtype=np.int64)
        owner = np.asarray(owner, dtype=np.int64)
        self._sig = None
        if previous is not None or reusable:
            self._sig = _signature(rows, np.int64(n), np.int64(comm.Get_size()), owned, columns, group[columns],
                                   owner[columns])
            if self._take_over(previous, rows, take_rows):
                return self
        one = np.zeros(int(group.max()) + 1 if group.size else 0, dtype=np.int64)
        one[group] = np.arange(group.size)  # a contact of each group: its owner is the group's
        r_loc, c_loc = _nonzero_blocks(rows)
        ids, col, self.colour_rounds = greedy_colours(group[owned], group[owned[r_loc]], group[columns[c_loc]],
                                                      lambda g: owner[one[g]], comm)
        from mpi4py import MPI
        self.n_colours = comm.allreduce(int(col.max()) + 1 if col.size else 0, op=MPI.MAX)
        self.colour = None
        Wc = coupling_rows(rows)
        lr = localise(owned, Wc.indptr, columns[Wc.indices], Wc.blocks, Wc.diag_pos)
        shared = Wc is rows and not take_rows
        del Wc
        g_local = group[np.concatenate([lr.owned, lr.ghost])]
        pos = np.minimum(np.searchsorted(ids, g_local), max(ids.size - 1, 0))
        if g_local.size and not np.array_equal(ids[pos], g_local):
            raise RuntimeError("ColourSolver.from_rows: a ghost contact whose group is not coupled to an own group "
                               "(the rows and the group graph disagree)")
        self._distribute(lr, col[pos], shared)
        if take_rows:
            self._give_rows(rows)
        return self

    def _distribute(self, lr, colour_local, shared: bool):
        """N > 1 ranks: this rank's rows `lr` (sweep.LocalRows; shared: its blocks are the caller's), the colours of
        its owned then ghost contacts; the rows put in sweep order (`_in_sweep_order`), the PETSc scatters
        (sweep.DistSweep) and the layout of the Allgatherv of the owned rows (`gather`)."""
        from .sweep import DistSweep
        self.dist = None
        self.owned, self.ghost = lr.owned, lr.ghost
        self._ip0 = np.array(lr.indptr, dtype=np.int64) if self._sig is not None else None
        lr, c_sweep = _in_sweep_order(lr, colour_local[:lr.owned.size], shared=shared, fresh_indices=True)
        self._sweep = lr.owned
        self._back = np.searchsorted(self.owned, self._sweep)  # sweep position -> position in `owned`
        self.rows = (lr.indptr, lr.indices, lr.blocks, lr.diag_pos)
        self.dist = DistSweep(lr, np.concatenate([c_sweep, colour_local[self.owned.size:]]), self.n_colours,
                              self.comm)
        self.order = self.dist.order
        self.r = self.dist.r  # owned then ghost impulses; the owned part is the PETSc vector's array
        counts = np.array(self.comm.allgather(self.owned.size), dtype=np.int64)
        self._counts = counts
        self._ids = np.concatenate(self.comm.allgather(self.owned))  # gathered owned contacts, in rank order

    def _take_over(self, previous, W: BlockCSR, take_rows: bool) -> bool:
        """Become `previous` with the blocks of W (module docstring of the class, `previous`) if both have the same
        signature (`_sig`; on N > 1 ranks if every rank's has: one all-reduce); False, and nothing done, if not.
        W's rows are in `previous`'s layout before its sweep order (the structure is the same): the new blocks are
        taken row by row into the sweep order (one gather into the solver's own blocks array, which held the
        previous operator's); with take_rows W's arrays become the solver's, as when its rows are moved in place."""
        same = previous is not None and self._sig is not None and previous._sig == self._sig
        if self.comm is not None:
            from mpi4py import MPI
            same = bool(self.comm.allreduce(int(same), op=MPI.MIN))
        if not same:
            return False
        self.__dict__.update({k: v for k, v in previous.__dict__.items() if k != "W"})  # (its _sig is this one's)
        ip, _, bl, _ = self.rows
        perm, ip0 = self._back, self._ip0  # sweep row i <- row perm[i] of the rows as assembled
        # src[k]: the block of W that goes to sweep position k, one int64 per block (no other temporary): ones,
        # the jump to the source row at each row start, summed
        lens = ip[1:] - ip[:-1]
        full = lens > 0
        a, n_ = ip0[:-1][perm][full], lens[full]
        src = np.ones(int(ip[-1]), dtype=np.int64)
        if src.size:
            src[ip[:-1][full]] = a - np.concatenate([[0], a[:-1] + n_[:-1] - 1])
            np.cumsum(src, out=src)
        np.take(W.blocks, src, axis=0, out=bl, mode="clip")  # ("clip": not buffered; src is in range)
        previous.dist = previous.rows = None  # (spent: its scatters and arrays are this solver's)
        if take_rows:
            self._give_rows(W)
        return True

    def _give_rows(self, W: BlockCSR):
        """take_rows: W's arrays become the solver's rows (in sweep order), so that W keeps no array of its own
        beside them — its column indices before the renumbering for the sweep (`localise`) would otherwise stay, a
        second copy of one int64 per block, or its blocks, if `coupling_rows` had copied them. W then only
        identifies the operator the solver was built for."""
        W.indptr, W.indices, W.blocks, W.diag_pos = self.rows

    @property
    def n_owned(self) -> int:
        return int(self.owned.size)

    def destroy(self):
        if self.dist is not None:
            self.dist.destroy()
            self.dist = None

    # ------------------------------------------------------------------ helpers
    def _exchange(self, c: int):
        if self.dist is not None:
            self.dist.scatters[c].scatter(self.dist.vec, self.dist.gvec)

    def gather(self, x_own: np.ndarray, width: int) -> np.ndarray:
        """The owned rows' values (n_own, width) of every rank, as one (n, width) array in contact order, on every
        rank (one Allgatherv)."""
        if self.comm is None:
            return x_own.reshape(-1, width).copy()
        from .sweep import gather_rows
        return gather_rows(self.comm, self._ids, self._counts, np.asarray(x_own).reshape(-1, width))

    def _sum_int(self, x: np.ndarray) -> np.ndarray:
        if self.comm is None:
            return x
        from mpi4py import MPI
        out = np.empty_like(x)
        self.comm.Allreduce(x, out, op=MPI.SUM)
        return out

    # ------------------------------------------------------------------ the solve
    def solve(self, q, mu, r0=None, tol: float = 1e-8, max_sweeps: int = 10000, omega: float = 1.0,
              criterion: str = "change", check_every: int = 10, laws=None, own_rows: bool = False) -> SolverResult:
        """Colour-order NLGS from r0 (zeros by default). laws: an solver.problem.InterfaceLaws (interface laws) or
        None (Signorini–Coulomb). q, mu, r0 and the laws' arrays hold the rows of every contact (the same on every
        rank), or, with own_rows (the same on every rank), those of this rank's own contacts only (`owned`,
        increasing numbers: a run whose ranks hold their own contacts' values, contact/step.py). Returns r and
        u = W r + q for the same rows (SolverResult; with laws, `trial` the internal variables to commit): every
        contact's, gathered on every rank, or the own contacts'."""
        if criterion not in ("change", "residual"):
            raise InputError(f"criterion = {criterion!r}: expected 'change' or 'residual'")
        d, n = self.d, self.n
        q = np.ascontiguousarray(q, dtype=np.float64).ravel()
        own, gh = self._sweep, self.ghost  # (own: this rank's contacts in sweep order)
        no = own.size
        whole = not own_rows
        m, pick = (n, own) if whole else (no, self._back)  # rows given; the rows of the sweep among them
        mu = np.ascontiguousarray(np.broadcast_to(np.asarray(mu, dtype=np.float64).ravel(), (m,)))
        if q.size != d * m:
            raise InputError(f"q: expected {d * m} entries ({d} per contact of {m}), got {q.size}")
        if not (tol > 0) or int(max_sweeps) < 1 or not (0 < omega <= 2) or int(check_every) < 1:
            raise InputError("expected tol > 0, max_sweeps >= 1, 0 < omega <= 2, check_every >= 1")
        r0 = np.zeros(d * m) if r0 is None else np.asarray(r0, dtype=np.float64).ravel()
        if r0.size != d * m or not np.all(np.isfinite(r0)):
            raise InputError(f"r0: expected {d * m} finite entries")
        R0 = r0.reshape(-1, d)
        self.r[:d * no] = R0[pick].ravel()
        if whole:
            self.r[d * no:] = R0[gh].ravel()
        else:  # the ghosts' r0 from their owners: every colour's exchange once
            for c in range(self.n_colours):
                self._exchange(c)
        qo = np.ascontiguousarray(q.reshape(-1, d)[pick]).ravel()
        muo = np.ascontiguousarray(mu[pick])
        coh = None
        if laws is not None:
            from ..laws import step_start
            law = np.ascontiguousarray(np.asarray(laws.law, dtype=np.int64)[pick])
            par = np.ascontiguousarray(np.asarray(laws.par, dtype=np.float64)[pick])
            st = np.ascontiguousarray(np.asarray(laws.state, dtype=np.float64)[pick])
            coh = dict(law=law, par=par, st=st,
                       trial=np.ascontiguousarray(step_start(law, par, st, float(laws.h))),  # committed x (IMPL-EX)
                       ueff=np.ascontiguousarray(np.asarray(laws.ueff, dtype=np.float64)[pick]),
                       area=np.ascontiguousarray(np.asarray(laws.area, dtype=np.float64)[pick]),
                       h=float(laws.h), theta=float(laws.theta))
        qnorm = float(np.sqrt(exact_sums([qo * qo], self.comm)[0])) or 1.0
        cases = np.zeros(6, dtype=np.int64)
        u = np.empty(d * no)
        if coh is None:
            sweeps, change, converged = self._run(qo, muo, tol, int(max_sweeps), float(omega), criterion,
                                                  int(check_every), qnorm, cases, u, None)
        else:
            sweeps, converged, change = 0, False, np.inf
            for _ in range(MAX_OUTER):
                s, change, converged = self._run(qo, muo, tol, int(max_sweeps) - sweeps, float(omega), criterion,
                                                 int(check_every), qnorm, cases, u, coh)
                sweeps += s
                self._u(qo, u)
                dx = largest(nlgs._update_internal(coh["law"], coh["par"], coh["st"], coh["ueff"], u, coh["h"],
                                                   coh["theta"], coh["trial"]), self.comm)
                if dx <= X_TOL or sweeps >= max_sweeps:
                    converged = converged and dx <= X_TOL
                    break
        self._u(qo, u)
        res_abs = float(np.sqrt(self._residual2(qo, muo, u, coh)))
        res = res_abs / qnorm
        cases = self._sum_int(cases)
        if converged:
            msg = f"converged in {sweeps} sweeps (colour order, {self.n_colours} colours)"
        else:
            msg = (f"not converged after {sweeps} sweeps (colour order; change {change:.3g}, residual {res:.3g}, "
                   f"tolerance {tol:g} on the {criterion})")
        if d == 3 and cases[0]:
            msg += f"; {cases[0]} local solves without a positive diagonal block"
        rows = (lambda x, w: self.gather(self._in_contact_order(x, w), w).ravel()) if whole else \
            (lambda x, w: self._in_contact_order(x, w).ravel())
        out = SolverResult(rows(self.r[:d * no], d), rows(u, d), int(sweeps), bool(converged), float(change), res,
                           res_abs, msg, cases if d == 3 else None)
        if coh is not None:
            out.trial = rows(coh["trial"], 1)
        return out

    def _in_contact_order(self, x, width: int) -> np.ndarray:
        """Rows (n_own, width) of this rank's contacts in sweep order -> in `owned` order (increasing numbers)."""
        x = np.asarray(x).reshape(-1, width)
        out = np.empty_like(x)
        out[self._back] = x
        return out

    def _u(self, qo, u):
        """u = W r + q on the owned rows."""
        ip, ix, bl, _ = self.rows
        matvec_bcsr(ip, ix, bl, self.r, u)
        u += qo

    def _residual2(self, qo, muo, u, coh) -> float:
        """Σ_α ‖F_α‖² over all contacts (exact sum), u = W r + q on the owned rows."""
        if coh is None:
            t = nlgs.natural_map_terms(self.r, u, muo, self.d)
        else:
            ip, ix, bl, _ = self.rows
            t = nlgs.natural_map_cohesive_terms(ip, ix, bl, qo, muo, self.r, coh["law"], coh["par"], coh["st"],
                                                coh["trial"], coh["ueff"], coh["area"], coh["h"], coh["theta"])
        return exact_sums([t], self.comm)[0]

    def _run(self, qo, muo, tol, max_sweeps, omega, criterion, check_every, qnorm, cases, u, coh):
        """Sweeps until the criterion holds or max_sweeps (nlgs._run / nlgs._run_cohesive)."""
        d, no = self.d, self.owned.size
        ip, ix, bl, dp = self.rows
        r = self.r
        J = np.empty((3, 3))
        wl = np.zeros((2, 3, 3))
        use_residual = criterion == "residual"
        change, sweeps, converged = np.inf, 0, False
        while sweeps < max_sweeps:
            r_old = r[:d * no].copy()
            for c in range(self.n_colours):
                o = self.order[c]
                if coh is None:
                    if d == 2:
                        nlgs._sweep(ip, ix, bl, dp, qo, muo, r, o, omega)
                    else:
                        nlgs._sweep3(ip, ix, bl, dp, qo, muo, r, o, omega, J, cases)
                elif d == 2:
                    nlgs._sweep_cohesive(ip, ix, bl, dp, qo, muo, r, o, omega, coh["law"], coh["par"], coh["st"],
                                         coh["trial"], coh["ueff"], coh["area"], coh["h"], coh["theta"])
                else:
                    nlgs._sweep_cohesive3(ip, ix, bl, dp, qo, muo, r, o, omega, coh["law"], coh["par"], coh["st"],
                                          coh["trial"], coh["ueff"], coh["area"], coh["h"], coh["theta"], wl, J,
                                          cases)
                self._exchange(c)
            sweeps += 1
            dr = r[:d * no] - r_old
            rn = r[:d * no]
            dr2, r2 = exact_sums([dr * dr, rn * rn], self.comm)
            change = float(np.sqrt(dr2 / r2)) if r2 > 0.0 else float(np.sqrt(dr2))
            if use_residual:
                if sweeps % check_every == 0 or sweeps == max_sweeps or (coh is None and change == 0.0):
                    self._u(qo, u)
                    res = float(np.sqrt(self._residual2(qo, muo, u, coh))) / qnorm
                    if coh is None:
                        if res <= tol:
                            converged = True
                            break
                        if change == 0.0 and sweeps > 1:  # stationary: a solution when the local solve is exact
                            converged = d == 2
                            break
                    elif res <= tol or (change == 0.0 and sweeps > 1):
                        converged = True
                        break
            elif change <= tol and (coh is None or sweeps > 1):
                converged = True
                break
        return sweeps, change, converged


def _load(path):
    from ..linalg import to_block_csr
    if path.endswith(".npz"):
        with np.load(path) as z:
            W = BlockCSR(z["indptr"].astype(np.int64), z["indices"].astype(np.int64),
                         np.ascontiguousarray(z["blocks"]), z["diag_pos"].astype(np.int64))
            return W, np.ascontiguousarray(z["q"], dtype=np.float64), np.asarray(z["mu"], dtype=np.float64)
    from ..io import fclib
    p = fclib.read(path)
    return to_block_csr(p.W, p.dim), np.ascontiguousarray(p.q, dtype=np.float64), np.asarray(p.mu, dtype=np.float64)


def main(argv=None) -> int:
    """The file driver of the colour-order Gauss–Seidel (module docstring, "Run")."""
    import argparse
    from mpi4py import MPI
    from .sweep import ownership, partition_contacts
    ap = argparse.ArgumentParser(prog="python -m fem_blocks.distributed.colour")
    ap.add_argument("problem")
    ap.add_argument("out")
    ap.add_argument("--own", default="blocks", choices=["blocks", "cyclic", "skip0", "ptscotch"])
    ap.add_argument("--tol", type=float, default=None)
    ap.add_argument("--max-sweeps", type=int, default=100000)
    a = ap.parse_args(sys.argv[1:] if argv is None else argv)
    comm = MPI.COMM_WORLD
    rank, size = comm.Get_rank(), comm.Get_size()
    t0 = time.perf_counter()
    # driver: every rank reads the file and colours the whole graph (a stand-in for the assembly of its own rows and
    # a distributed colouring); ColourSolver keeps only the rank's rows
    W, q, mu = _load(a.problem)
    tol = a.tol
    if tol is None:
        tol = 1e-8
        if a.problem.endswith(".npz"):
            with np.load(a.problem) as z:
                tol = float(z["tol"]) if "tol" in z.files else tol
    owner = partition_contacts(W, comm) if a.own == "ptscotch" else ownership(W.n, size, a.own)
    cs = ColourSolver(W, contact_owner=owner, comm=comm)
    t_setup = time.perf_counter() - t0
    comm.Barrier()
    t1 = time.perf_counter()
    res = cs.solve(q, mu, tol=tol, criterion="residual", max_sweeps=a.max_sweeps, check_every=10)
    t_solve = time.perf_counter() - t1
    dist = cs.dist  # None on one rank: nothing exchanged
    per_rank = comm.gather(dict(n_own=cs.n_owned, n_ghost=int(cs.ghost.size), t_solve=t_solve,
                                bytes_sent=8 * dist.entries_sent if dist else 0,
                                bytes_recv=8 * dist.entries_recv if dist else 0,
                                messages=dist.messages if dist else 0), root=0)
    if rank == 0:
        np.savez(a.out, r=res.r, sweeps=res.sweeps, residual=res.residual, converged=res.converged, ranks=size,
                 t_setup=t_setup, **{k: [p[k] for p in per_rank] for k in per_rank[0]})
        print(res.message)
        for p, st in enumerate(per_rank):
            print(f"rank {p}: {st['n_own']} owned, {st['n_ghost']} ghost contacts; "
                  f"{st['t_solve'] / max(res.sweeps, 1) * 1e6:.1f} us/sweep (whole solve); per sweep "
                  f"{st['bytes_sent']} B sent, {st['bytes_recv']} B received, {st['messages']} messages")
    cs.destroy()
    return 0


if __name__ == "__main__":
    sys.exit(main())
