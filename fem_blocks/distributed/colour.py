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

The time stepper reads the group graph from the bodies instead, before W is assembled (`sweep_plan`): the groups of
two contacts are coupled when the contacts share a body whose W_b ≠ 0 (`group_couplings`, `moving_bodies`), since
W_αβ = Σ_{shared bodies b} G^α_b W_b G^βᵀ_b. That graph holds every nonzero block's pair, so its colours keep the
contacts of one colour and different groups uncoupled; it equals the graph of W's nonzero blocks unless a block
between contacts sharing a moving body is exactly zero (by chance, or a contact whose side on that body touches
only dofs that W_b does not move): then it separates more groups, and the sweep is still the Gauss–Seidel sweep in
the order of its colours, the same on any N (docs/scaling.md "Rows assembled in sweep order"). Knowing the sweep
order first, the contact step assembles the rows of W directly in it (delassus.assemble's `rows`) and no permutation
of W's rows is needed (`ColourSolver.from_sweep_rows`).

Distribution (comm with N > 1 ranks; distributed/sweep.py). Rank p owns the contacts `owner == p` (the time stepper:
the rank of the contact's candidate body, distributed/partition.py; with groups, one group's contacts must have one
owner) and holds their rows of W (without the blocks of zeros, `coupling_rows`, as the serial sweep; column order of
the global row kept, so every v_α is summed exactly as serially), q_α, μ_α, the law data and the impulses of its
contacts and of the *ghost* contacts its rows couple to. The rows come from the whole W (`ColourSolver`) or are
assembled by the rank itself in its sweep order (`ColourSolver.from_sweep_rows`, the time stepper: each rank colours
its own groups from the bodies of its contacts, distributed/greedy.py, the colours of the whole group graph without
gathering it). After colour c, one PETSc scatter carries the new impulses of colour c to the ranks that hold them as
ghosts (neighbour ranks only). The iterates are the serial ones, bitwise, for any N and any ownership.

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
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..linalg import BlockCSR, matvec_bcsr
from ..solver import nlgs
from ..solver.parallel import colour_contacts, pair_colouring
from ..solver.problem import SolverResult
from .exact import exact_sums, largest

MAX_OUTER = 100      # interface laws: most staggered passes (solver/nlgs.solve_cohesive's max_outer)
X_TOL = 1e-12        # interface laws: the internal variables have stopped changing


def body_pair_keys(cand, ant, nb: int) -> np.ndarray:
    """The group key of each contact: cand * nb + ant, one per (candidate, antagonist) body pair, increasing in
    (candidate, antagonist) order, the same on every rank without the contact set (the group's candidate body is
    key // nb)."""
    return np.asarray(cand, dtype=np.int64) * int(nb) + np.asarray(ant, dtype=np.int64)


def body_pair_groups(cand, ant, nb: int) -> tuple[np.ndarray, int]:
    """(group of each contact, number of groups): contacts grouped by (candidate, antagonist) body pair, groups
    numbered 0, 1, ... in increasing (candidate, antagonist) order (the ranks of their `body_pair_keys`)."""
    keys, group = np.unique(body_pair_keys(cand, ant, nb), return_inverse=True)
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


def moving_bodies(W_flat, W_offset, W_size) -> np.ndarray:
    """(nb,) bool: the bodies whose dense W_b (delassus.assemble's blocks per body: W_size[b]² entries at
    W_offset[b] of W_flat) has a nonzero entry. A body held in every dof (a fixed foundation) has W_b = 0: the
    contacts it carries are not coupled through it."""
    nz = np.flatnonzero(np.asarray(W_flat))
    lo = np.asarray(W_offset, dtype=np.int64)
    return np.searchsorted(nz, lo + np.asarray(W_size, dtype=np.int64) ** 2) > np.searchsorted(nz, lo)


def group_couplings(group, cand, ant, moving, own_groups=None) -> tuple[np.ndarray, np.ndarray]:
    """Edges (ga, gb) of the group graph read from the bodies: the groups of two contacts are coupled when the
    contacts share a moving body (`moving_bodies`), since W_αβ = Σ_{shared bodies b} G^α_b W_b G^βᵀ_b is zero
    when every shared body has W_b = 0. group, cand, ant: per contact (one array entry each; group: any integer
    keys, e.g. `body_pair_keys`, numbered densely here in their order); own_groups (increasing): only the edges
    whose ga is one of them (a rank's own groups), else every edge. Each edge once per moving body the two groups
    share, both directions, self-pairs included (the colourings ignore them); the edges are given in `group`'s keys."""
    ids, dense = np.unique(np.asarray(group, dtype=np.int64), return_inverse=True)
    moving = np.asarray(moving, dtype=bool)
    body = np.concatenate([np.asarray(cand, dtype=np.int64), np.asarray(ant, dtype=np.int64)])
    g = np.concatenate([dense, dense]).astype(np.int64)
    keep = moving[body]
    ng = max(int(ids.size), 1)
    code = np.unique(body[keep] * ng + g[keep])  # the distinct (body, group) pairs, grouped by body
    eb, eg = code // ng, code % ng
    start = np.searchsorted(eb, eb)              # first pair of the same body
    count = np.searchsorted(eb, eb, side="right") - start
    src = np.arange(eg.size) if own_groups is None else np.flatnonzero(np.isin(ids[eg], own_groups))
    rep = count[src]
    k = np.arange(int(rep.sum()), dtype=np.int64) - np.repeat(np.cumsum(rep) - rep, rep)
    return ids[np.repeat(eg[src], rep)], ids[eg[np.repeat(start[src], rep) + k]]


@dataclass
class SweepPlan:
    """The colours of a rank's contacts and the order it sweeps them, known before W is assembled (`sweep_plan`):
    the contact step assembles the rows of W directly in that order (delassus.assemble's `rows`)."""
    rows: np.ndarray     # positions, among the contacts given, of this rank's own contacts in sweep order
    colour: np.ndarray   # colour of every contact given (-1: its group is not coupled to an own group)
    n_colours: int       # over every rank
    rounds: int          # rounds of the distributed greedy colouring (0 on one process)


def sweep_plan(group, cand, ant, moving, own=None, owner_of=None, comm=None) -> SweepPlan:
    """Colours and sweep order from the contacts' bodies (the time stepper, before it assembles W): contacts grouped
    by body pair (group: the key of each contact's group, `body_pair_keys`: the same on every rank, read from the
    contact's bodies alone), groups coupled when they share a moving body (`group_couplings`), coloured greedily in
    increasing key (`colour_group_graph` on one process; on N > 1 ranks `greedy.greedy_colours`, each rank
    colouring its own groups: the same colours). The sweep order: own contacts by colour, increasing within a colour
    (stable sort of their positions). own: positions of this rank's contacts among those given (None: all, one
    process); owner_of(g): the rank owning each group of the array g of keys (N > 1).

    The colours are those of `colour_groups` on the assembled W unless a block between contacts sharing a moving
    body is exactly zero (then these separate more groups): the group graph read from the bodies holds every
    nonzero block, so contacts of one colour and different groups stay uncoupled."""
    group = np.asarray(group, dtype=np.int64)
    n = group.size
    own = np.arange(n, dtype=np.int64) if own is None else np.asarray(own, dtype=np.int64)
    colour = -np.ones(n, dtype=np.int64)
    rounds = 0
    if comm is None or comm.Get_size() == 1:
        if n:
            ids, dense = np.unique(group, return_inverse=True)  # (the keys numbered 0, 1, ... in their order)
            ga, gb = group_couplings(dense, cand, ant, moving)
            colour = colour_group_graph(ids.size, ga, gb)[dense]
        n_colours = int(colour.max()) + 1 if n else 0
    else:
        from mpi4py import MPI
        from .greedy import greedy_colours
        mine = np.unique(group[own])
        ga, gb = group_couplings(group, cand, ant, moving, own_groups=mine)
        ids, col, rounds = greedy_colours(mine, ga, gb, owner_of, comm)
        pos = np.minimum(np.searchsorted(ids, group), max(ids.size - 1, 0))
        known = ids[pos] == group if ids.size else np.zeros(n, dtype=bool)
        colour[known] = col[pos[known]]
        n_colours = comm.allreduce(int(col.max()) + 1 if col.size else 0, op=MPI.MAX)
    rows = own[np.argsort(colour[own], kind="stable")]
    return SweepPlan(rows.astype(np.int64), colour, int(n_colours), int(rounds))


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


class ColourSolver:
    """The colour-order NLGS for one Delassus operator W (set up once per W; collective when `comm` has N > 1
    ranks). Two ways in:

    * `ColourSolver(W, contact_owner, comm, bodies)`: the whole W in contact order (the file driver, tests), its
      colours read from W's nonzero blocks: contact_owner (nc,) the rank of each contact (N > 1); comm an mpi4py
      communicator or None (serial); bodies (cand, ant, nb) the contacts' body pairs and the number of bodies
      (colours of body-pair groups, `colour_groups`; every group must have one owner), or None (contacts coloured
      one by one). The solver copies the rows it sweeps into sweep order (`_in_sweep_order`); W is unchanged.
    * `ColourSolver.from_sweep_rows(...)`: the time stepper's rows, assembled by the rank itself in the sweep order
      of a `SweepPlan` (colours from the bodies, before W): no permutation; the rows' arrays become the solver's.

    The solver sweeps its rows in sweep order: a colour's rows one after the other in memory."""

    def __init__(self, W: BlockCSR, contact_owner=None, comm=None, bodies=None):
        self.W = W
        self.d = W.dim
        n = self.n = W.n
        self.comm = comm if comm is not None and comm.Get_size() > 1 else None
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
            lr = LocalRows(np.arange(n, dtype=np.int64), np.zeros(0, dtype=np.int64), Wc.indptr, Wc.indices,
                           Wc.blocks, Wc.diag_pos, np.zeros(0), np.zeros(0))
            lr, c_sweep = _in_sweep_order(lr, colour, shared=Wc is W)
            self._serial(lr, c_sweep)
            return
        from .sweep import local_rows
        owner = np.asarray(contact_owner, dtype=np.int64)
        if owner.shape != (n,):
            raise InputError(f"contact_owner: expected {n} ranks (one per contact), got shape {owner.shape}")
        lr = local_rows(Wc, np.zeros(self.d * n), np.zeros(n), np.flatnonzero(owner == self.comm.Get_rank()))
        del Wc
        colour_local = colour[np.concatenate([lr.owned, lr.ghost])]
        lr, c_sweep = _in_sweep_order(lr, colour_local[:lr.owned.size], shared=False, fresh_indices=True)
        self._distribute(lr, np.concatenate([c_sweep, colour_local[lr.owned.size:]]))

    @classmethod
    def from_sweep_rows(cls, rows: BlockCSR, plan: SweepPlan, columns, n: int, comm=None,
                        previous: "ColourSolver | None" = None) -> "ColourSolver":
        """The colour solver of rows assembled in sweep order (the time stepper; collective on `comm` when it has
        N > 1 ranks). columns: the contacts (global numbers 0 .. n - 1, the same on every rank; each rank's own
        contacts numbered consecutively) of the rows' column numbers and of the plan's positions (a rank's contacts
        L, or every contact); rows: row i is the row of contact
        columns[plan.rows[i]], without off-diagonal blocks of zeros (delassus.assemble(..., rows=plan.rows,
        couplings=True)); n: the number of contacts of the whole run. The rows' arrays become the solver's (column
        numbers made local in place: own contacts in sweep order, then the ghosts, the other columns met, in the
        order of `columns`); W (`rows`) then only identifies the operator the solver was built for.

        previous: the solver of the operator before (updated geometry assembles W at every step, mostly for the
        same contacts). When the new rows have its structure — the same contacts in the same sweep order, ghosts,
        colours and block pattern (on N > 1 ranks on every rank: one all-reduce) — its PETSc scatters and layout are
        taken over with the new blocks (`_take_over`): the same solver, bit for bit, as one built from scratch.
        `previous` is then spent; otherwise it is left as it is, for its owner to destroy."""
        self = cls.__new__(cls)
        self.W, self.d, self.n = rows, rows.dim, int(n)
        self.comm = comm if comm is not None and comm.Get_size() > 1 else None
        self.colour, self.dist = None, None
        self.n_colours = int(plan.n_colours)
        self.colour_rounds = int(plan.rounds)
        columns = np.asarray(columns, dtype=np.int64)
        from .sweep import localise
        # local numbers over the positions in `columns` (own contacts in sweep order, then the other columns met),
        # W's column numbers renumbered in place; then the positions made global contact numbers
        lr = localise(plan.rows, rows.indptr, rows.indices, rows.blocks, rows.diag_pos, in_place=True)
        colour_local = np.asarray(plan.colour, dtype=np.int64)[np.concatenate([lr.owned, lr.ghost])]
        if np.any(colour_local < 0):
            raise RuntimeError("ColourSolver.from_sweep_rows: a ghost contact whose group is not coupled to an own "
                               "group (the rows and the plan's group graph disagree)")
        lr.owned, lr.ghost = columns[lr.owned], columns[lr.ghost]
        if self._take_over(previous, lr, colour_local):
            return self
        if self.comm is None:
            if lr.ghost.size or lr.owned.size != self.n:
                raise InputError(f"from_sweep_rows: on one process the rows of all {self.n} contacts, got "
                                 f"{lr.owned.size} rows and {lr.ghost.size} other columns")
            self._serial(lr, colour_local)
        else:
            self._distribute(lr, colour_local)
        self._give_rows(rows)  # (W's own arrays already, its column numbers made local in place)
        return self

    def _serial(self, lr, c_sweep):
        """One process: the rows `lr` in sweep order (sweep.LocalRows, every contact, no ghost), their colours."""
        self.owned = np.arange(lr.owned.size, dtype=np.int64)
        self.ghost = np.zeros(0, dtype=np.int64)
        self._sweep = lr.owned
        self._back = lr.owned  # sweep position -> position in `owned`
        self.rows = (lr.indptr, lr.indices, lr.blocks, lr.diag_pos)
        self._colour_local = np.asarray(c_sweep, dtype=np.int64)
        self.order = [np.ascontiguousarray(np.flatnonzero(c_sweep == c), dtype=np.int64)
                      for c in range(self.n_colours)]
        self.r = np.zeros(self.d * lr.owned.size)

    def _distribute(self, lr, colour_local):
        """N > 1 ranks: this rank's rows `lr` in sweep order (sweep.LocalRows: owned contacts in sweep order, then
        the ghosts), the colours of its owned then ghost contacts; the PETSc scatters (sweep.DistSweep) and the layout
        of the Allgatherv of the owned rows (`gather`)."""
        from .sweep import DistSweep
        self.dist = None
        self._sweep, self.ghost = lr.owned, lr.ghost
        self.owned = np.sort(lr.owned)
        self._back = np.searchsorted(self.owned, self._sweep)  # sweep position -> position in `owned`
        self.rows = (lr.indptr, lr.indices, lr.blocks, lr.diag_pos)
        self._colour_local = np.asarray(colour_local, dtype=np.int64)
        self.dist = DistSweep(lr, colour_local, self.n_colours, self.comm)
        self.order = self.dist.order
        self.r = self.dist.r  # owned then ghost impulses; the owned part is the PETSc vector's array
        self._layout = None  # the gather's (every rank's owned contacts, their counts): made by the first `gather`

    def _take_over(self, previous, lr, colour_local) -> bool:
        """Become `previous` with the blocks of `lr` (`from_sweep_rows`'s previous) if both have the same structure:
        the same run size, contacts in sweep order, ghosts, colours and rows' pattern (on N > 1 ranks on every rank:
        one all-reduce); False, and nothing done, if not. The solver then keeps the previous index arrays (equal)
        and W's blocks; W's arrays become these."""
        same = (previous is not None and getattr(previous, "rows", None) is not None
                and previous.comm is self.comm and previous.n == self.n
                and previous.n_colours == self.n_colours and previous.d == self.d)
        if same:
            ip, ix, _, dp = previous.rows
            same = all(np.array_equal(a, b) for a, b in (
                (previous._sweep, lr.owned), (previous.ghost, lr.ghost), (previous._colour_local, colour_local),
                (ip, lr.indptr), (dp, lr.diag_pos), (ix, lr.indices)))
        if self.comm is not None:
            from mpi4py import MPI
            same = bool(self.comm.allreduce(int(same), op=MPI.MIN))
        if not same:
            return False
        self.__dict__.update({k: v for k, v in previous.__dict__.items() if k not in ("W", "colour_rounds")})
        ip, ix, _, dp = previous.rows
        self.rows = (ip, ix, lr.blocks, dp)
        previous.dist = previous.rows = None  # (spent: its scatters and arrays are this solver's)
        self._give_rows(self.W)
        return True

    def _give_rows(self, W: BlockCSR):
        """W's arrays become the solver's rows (in sweep order, local column numbers), so that W keeps no array of
        its own beside them. W then only identifies the operator the solver was built for."""
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
        """COLLECTIVE: the owned rows' values (n_own, width) of every rank, as one (n, width) array in contact order,
        on every rank (one Allgatherv). Its layout, every rank's owned contact numbers (n integers on every rank),
        is gathered at the first call only: the time stepper, whose ranks keep their own rows, never makes it."""
        if self.comm is None:
            return x_own.reshape(-1, width).copy()
        from .sweep import gather_rows
        if self._layout is None:
            self._layout = (np.concatenate(self.comm.allgather(self.owned)),
                            np.array(self.comm.allgather(self.owned.size), dtype=np.int64))
        return gather_rows(self.comm, *self._layout, np.asarray(x_own).reshape(-1, width))

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
