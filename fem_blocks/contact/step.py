"""Contact stage of a time step: detection -> G blocks -> Delassus -> NLGS -> velocity correction.

Per step [t_i, t_{i+1}] (docs/method.md §3–§5), with impulses P = h r as unknowns:

    v = v_free + W_del P,   v_free = G u_free,   W_del = sum_bodies G W_k G^T,
    gt = g - g0 (thick joints),   gbar = gt_i + h (1 - theta) v_N,i,
    Signorini on the shifted normal velocity  v_N + gs / (h theta) >= 0  ⊥  P_N >= 0,
    gs = max(gbar, 0) + (h / hn) min(gbar, 0)   (hn = sim.h_nominal; gs = gbar unless h is a sub-step),
    Coulomb |P_T| <= mu P_N (implicit, on v_T).

A sub-step h = hn / 2^k (the runner's "refine"/"adaptive") would clear an existing penetration p = -gbar at the
speed p / (h theta), 2^k times the nominal step's, and create kinetic energy growing as (p / h)^2; the sub-step
clears it at the nominal rate instead (the fraction h / hn of it per sub-step), so sub-stepping never pushes a
penetrated contact out faster than the step it replaces (docs/method.md §3).

So the NLGS local problem is `u = W_del P + q` with `q = v_free + (gs/(h theta), 0)`: at the end
of the step the θ-rule position update gives gt_{i+1} = gbar + h theta v_N >= gbar - gs, = 0 for gbar >= 0 and
(1 - h/hn) gbar for a penetration (frozen geometry). Then u_{i+1} = u_free + W H P (one batched solve per block type).

Geometry: "frozen" (small displacements; detection, frames, G and W_del once in the reference
configuration; gaps follow the displacement jumps gt = gt_ref + (G q)_N) or "updated" (re-detection
from the current configuration every `redetect_every` steps, reactions carried over by contact key;
`reference = "as_built"`: each contact of the initial set carries its initial gap as an offset with its key,
gt = g - g0 - g_built, g_built = (g - g0) at t = 0, 0 for a contact detected later (nominal);
the steps in between keep the pairs and recompute points, frames, gaps and G from the current positions by
detection_2d.update_geometry (2D) / detection_3d.update_geometry (3D)).

Warm start of the solver (`[contact] predictor`; the impulses P_i = h_i r_i of the last steps, same contacts):

    "previous"      P0 = P_i                                         (the last step's impulses as they are)
    "scaled"        P0 = h r_i                                       (the same forces over the new step h)
    "extrapolated"  P0 = h [r_i + (h / h_i) (r_i - r_{i-1})]         (forces linear in time over the last two steps;
                                                                      "scaled" where r_{i-1} is not known)

Dimension d = sim.dim: the same step in 2D (detection, kinematics, delassus: local (n, t)) and 3D
(detection_3d, kinematics_3d: local (n, t, s), 3x3 Delassus blocks); impulses P (nc, d), law state
(nc, NSTATE) in 2D, (nc, NSTATE + 1) in 3D (the extra column is the second tangential jump u_S).
3D: every interface law with NLGS (nlgs.solve_cohesive on 3x3 blocks, laws.commit_step), or Coulomb with
the global Newton (solver/newton.py); the 3D Newton for interface laws is not written yet (InputError).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import InputError
from ..specs import ContactOptions, InterfaceSpec  # noqa: F401 (the engine's spec classes; defined in specs.py)
from . import detection_2d as det
from . import detection_3d as det3
from . import kinematics_2d as kin
from . import kinematics_3d as kin3
from .matching import contact_ids, match
from .result import OUT_FIELDS, OUT_PREFIX, ContactResult
from .scene import ContactScene

STATUS_NAMES = ("open", "stick", "slip")


class _SharedLinear:
    """N > 1 ranks: Newton's J Δr = -F (J in W's block pattern) on a PETSc block matrix with the rows of each rank's
    contacts, factored by MUMPS (distributed/linear.DistBlockSolver). Built at its first solve (a Gauss–Seidel step
    whose Newton fallback never fires builds nothing) and kept, with MUMPS's symbolic analysis, while W's block
    pattern stays the same; any ownership gives the same solution, so a kept solver serves a new contact set of the
    same pattern."""

    def __init__(self, comm):
        self.comm, self.solver, self.pattern = comm, None, None
        self.W, self.owner = None, None

    def bind(self, W, owner):
        """The Delassus operator of the next solves and a function giving the contacts' ranks."""
        self.W, self.owner = W, owner

    def solve(self, Jb, rhs):
        W = self.W
        if self.solver is None or not (np.array_equal(self.pattern[0], W.indptr)
                                       and np.array_equal(self.pattern[1], W.indices)):
            from ..distributed.linear import DistBlockSolver
            if self.solver is not None:
                self.solver.destroy()
            self.solver = DistBlockSolver(W.indptr, W.indices, W.dim, self.owner(), self.comm)
            self.pattern = (W.indptr.copy(), W.indices.copy())
        return self.solver.solve(Jb, rhs)

    def destroy(self):
        if self.solver is not None:
            self.solver.destroy()
        self.solver = None


class ContactStep:
    """The `contact` hook of `dynamics.Simulation` (solve -> ContactResult / on_step_change). Keeps what the next
    step needs (contact set, G, Delassus operator, warm start P, law state); reads the simulation, writes nothing
    into it."""

    def __init__(self, interfaces, body_groups, options: ContactOptions | None = None, body_names=None,
                 body_parent=None):
        self.interfaces = list(interfaces)
        # split bricks: contacts between two bodies with the same parent id >= 0 use the pair's "crack" interface
        self.body_parent = (-np.ones(len(body_groups), dtype=np.int64) if body_parent is None
                            else np.asarray(body_parent, dtype=np.int64))
        self.opts = options or ContactOptions()
        self.group_names = sorted(set(body_groups))
        gid = {g: i for i, g in enumerate(self.group_names)}
        self.body_group = np.array([gid[g] for g in body_groups], dtype=np.int64)
        self.body_names = body_names
        for itf in self.interfaces:
            for g in itf.groups:
                if g not in gid:
                    raise InputError(f"interfaces.{itf.name}.groups: group {g!r} has no body; expected one of "
                                     f"{self.group_names}")
        self.scene = None
        self.cs = None
        self.P = None  # impulses of the last step (nc, 2)
        self.h_last = None  # its step h; the step before: impulses P_prev (same contacts) and h_prev (predictor)
        self.P_prev, self.h_prev = None, None
        self.W_dirty = True
        self._rigid_W_restored = None  # 3D resume: rigid W of the checkpoint, used at the next Delassus build
        self.g_built = None  # updated geometry: per contact, the as-built offset (initial g - g0; 0 = nominal)
        self.n_unconverged = 0
        self.steps = 0
        self.friction_total = 0.0  # frictional dissipation of every step so far [J] (contact/friction.py)
        self.timers = dict(detection=0.0, delassus=0.0, nlgs=0.0, correction=0.0, local=0.0)
        self.comm = None  # MPI ranks sharing the contact solve (use_comm); None: this process alone
        self.body_owner = None  # N > 1 ranks: the rank of each body (distributed/graph.partition_graph)
        self.rebalanced = 0  # N > 1 ranks, updated geometry: new partitions kept (`_rebalance`) by this process
        self._colours = None  # order = "colours": the colour solver of the current Delassus operator
        self._plan = None  # order = "colours": the colours and sweep order of the next Delassus operator (_delassus)
        self._local = None  # N > 1 ranks in colour order: this rank's contacts (_RankContacts), else None
        self._linear = None  # N > 1 ranks, Newton: the shared linear solve (_SharedLinear)

    # ------------------------------------------------------------------ set-up
    def on_step_change(self, sim):
        """New (h, theta): the simulation rebuilt its groups (new state arrays and step operators)."""
        self.mark_W_dirty()
        if self.scene is not None:
            self.scene._group_index()

    def set_options(self, opts: ContactOptions):
        """Take new solver options (a stage's tol/max_sweeps: ContactOptions.for_stage) from the next step on."""
        self._take_options(self._on_ranks(opts))

    def _take_options(self, opts: ContactOptions):
        """The colour order keeps only W's coupling blocks (`_delassus`): W is rebuilt when the order changes to or
        from it."""
        if (opts.order == "colours") != (self.opts.order == "colours"):
            self.W_dirty = True
        self.opts = opts

    def use_comm(self, comm):
        """Share the contact solve among the MPI ranks of `comm` (every rank runs the same model and steps; the
        Gauss–Seidel sweeps are split by contact owner, distributed/colour.py). On N > 1 ranks a Gauss–Seidel
        solver sweeps in colour order (`order = "colours"`, the same iterates on any N); the Newton solver, the
        fallback and the coarse correction run on every rank alike, the Newton iterations' linear solves shared
        (distributed/linear.py: the same iterates within the linear solver's rounding)."""
        self.comm = comm if comm is not None and comm.Get_size() > 1 else None
        self._take_options(self._on_ranks(self.opts))

    def _on_ranks(self, opts: ContactOptions) -> ContactOptions:
        if (getattr(self, "comm", None) is not None and opts.solver == "nlgs" and opts.fallback == "none"
                and opts.coarse == "none" and opts.order != "colours"):
            return dataclasses.replace(opts, order="colours")
        return opts

    def _owner(self) -> np.ndarray:
        """N > 1 ranks: the rank of each contact, that of its candidate body (bodies partitioned by PT-Scotch on the
        body-contact graph at the first step, `_partition`, again at a re-detection that unbalances the ranks,
        `_rebalance`, or restored from the checkpoint)."""
        if self.body_owner is None or len(self.body_owner) != self.scene.nb:
            n, p, size = len(self.cs.gap), self.comm.Get_rank(), self.comm.Get_size()
            self.body_owner = self._partition(np.arange(n * p // size, n * (p + 1) // size))  # (a share of the set
            # every rank holds whole before the first partition)
        return self.body_owner[self.cs.cand_body]

    def _given(self) -> np.ndarray:
        """This rank's own contacts (numbers in the current contact set, increasing: candidate body its own): the
        step's rows of a new set (`_new_rows`), and the contacts it counts in the collective counts and graph of a
        partition, so that every contact is counted by one rank."""
        return np.flatnonzero(self.body_owner[self.cs.cand_body] == self.comm.Get_rank())

    def _partition(self, rows) -> np.ndarray:
        """COLLECTIVE: the rank of each body, PETSc MatPartitioning (PT-Scotch) of the body-contact graph of the
        current contact set (distributed/graph.py: edges weighted by their contacts, bodies by 1 + their contacts as
        candidate), so that the ranks own about as many contacts each. rows: the contacts this rank gives to the
        graph, each contact given by one rank (`partition_contact_graph`: no rank needs the whole set)."""
        from ..distributed.graph import partition_contact_graph
        cs = self.cs
        return partition_contact_graph(self.scene.nb, cs.cand_body[rows], cs.ant_body[rows], self.comm)

    def _rank_counts(self, owner, rows) -> np.ndarray:
        """COLLECTIVE: the number of contacts each rank owns under the body partition `owner`, counted from the
        contacts `rows` this rank gives (`_given`) and summed over the ranks (one all-reduce of `size` integers)."""
        from mpi4py import MPI
        c = np.bincount(owner[self.cs.cand_body[rows]], minlength=self.comm.Get_size()).astype(np.int64)
        return self.comm.allreduce(c, op=MPI.SUM)

    def _rebalance(self) -> bool:
        """COLLECTIVE (N > 1 ranks in colour order, updated geometry, at a re-detection, the new contact set in
        self.cs and the old partition's `_local` still in place): if the rank that would own most of the new
        contacts owns more than `rebalance` × their mean per rank, partition the bodies again (`_partition`) and
        keep the new partition if its busiest rank owns fewer contacts; True if kept (the caller moves the
        per-contact rows to their new owners), else False. The counts are the ranks' own contacts summed (each
        contact counted by its owner), the same on every rank, and so is the decision."""
        size = self.comm.Get_size()
        rows = self._given()
        counts = self._rank_counts(self.body_owner, rows)
        busiest = counts.max(initial=0)
        if not busiest * size > self.opts.rebalance * counts.sum():
            return False
        new = self._partition(rows)
        if self._rank_counts(new, rows).max(initial=0) >= busiest:
            return False  # (PT-Scotch did no better: the partition in use is kept)
        self.body_owner = new
        self.rebalanced += 1
        return True

    def body_partition(self):
        """(comm, mine): on N > 1 ranks in colour order, once the bodies are partitioned (`_owner`, at the first step
        or a restore), the ranks' communicator and the mask (nb,) of this rank's bodies; else None. The simulation
        adds its own bodies' terms in its sums over bodies (dynamics.py)."""
        if self._local is None:
            return None
        return self.comm, self.body_owner == self.comm.Get_rank()

    def stepped_bodies(self):
        """N > 1 ranks in colour order with frozen geometry, once the contact set is split: the mask (nb,) of the
        bodies this rank steps, B = its own bodies, the bodies of its own contacts (`_rank_contacts`) and the rigid
        bodies (the same array object while the contact set stays); else None (every body stepped: updated
        geometry detects on every body's position). dynamics.py, "Bodies stepped per rank"."""
        if self._local is None or self.opts.geometry != "frozen":
            return None
        return self._local.stepped

    def _split(self) -> bool:
        """N > 1 ranks in colour order: each rank holds its part of the contact set only (its contacts and their
        neighbours, `_rank_contacts`), their G blocks, and the Delassus rows and per-contact arrays of its own
        contacts (docs/scaling.md "Phase B1", "Phase B2")."""
        return self.comm is not None and self.opts.order == "colours"

    def _rank_contacts(self):
        """COLLECTIVE: this rank's part of the contact set (N > 1 ranks, colour order), from the current set (the
        whole set: the first detection, a checkpoint; or the contacts a split detection found, `_detect`). With O the
        bodies of this rank and A the contacts it owns (candidate body in O): B = O ∪ the bodies of A, and L = the
        contacts with a body in B. L holds every contact coupled to one of A (W_αβ needs a shared body) and every
        contact acting on a body of O (its impulse reaches that body); it is the contact set the rank keeps.
        Returns (the _RankContacts of L, A and L as numbers in the current set)."""
        cs, p, nb = self.cs, self.comm.Get_rank(), self.scene.nb
        owner = self._owner()
        own = np.flatnonzero(owner == p)
        mine = self.body_owner == p
        near = mine.copy()
        near[cs.cand_body[own]] = True
        near[cs.ant_body[own]] = True
        L = np.flatnonzero(near[cs.cand_body] | near[cs.ant_body])
        stepped = near.copy()
        stepped[self.scene.rigid] = True
        from ..distributed.sweep import OwnRowsGather
        ids = contact_ids(cs.key[L], cs.ant_body[L], nb)
        own_pos = np.searchsorted(L, own)
        counts = np.array(self.comm.allgather(own.size), dtype=np.int64)
        number = self._numbers(ids, own_pos, owner[L], counts)
        loc = _RankContacts(own_pos, np.repeat(mine, self.scene.W_size), stepped,
                            OwnRowsGather(self.comm, ids[own_pos]), ids, number, int(counts.sum()))
        return loc, own, L

    def _numbers(self, ids, own_pos, owner, counts) -> np.ndarray:
        """COLLECTIVE: the global numbers of the contacts `ids` (increasing; this rank's own at own_pos, the others
        owned by the ranks `owner`): every rank's own contacts numbered in rank order, each rank's in increasing id
        (rank p's are start_p .. start_p + counts[p] - 1, the layout of the distributed vectors of the impulses). The
        numbers of contacts owned elsewhere are asked of their owners by id (one Alltoall of the counts, two
        Alltoallv: the ids, then the numbers); RuntimeError on every rank if an owner does not hold one."""
        from ..distributed.sweep import exchange
        comm, p, size = self.comm, self.comm.Get_rank(), self.comm.Get_size()
        start = int(counts[:p].sum())
        number = np.empty(ids.size, dtype=np.int64)
        number[own_pos] = start + np.arange(own_pos.size)
        other = np.ones(ids.size, dtype=bool)
        other[own_pos] = False
        other = np.flatnonzero(other)
        other = other[np.argsort(owner[other], kind="stable")]
        scounts = np.bincount(owner[other], minlength=size)
        asked, rcounts = exchange(comm, ids[other], scounts)
        pos = _lookup(ids[own_pos], asked)
        got, _ = exchange(comm, np.where(pos >= 0, start + pos, -1), rcounts, rcounts=scounts)  # (the reply)
        number[other] = got
        self._fail_together(bool(np.any(got < 0)), "a contact of this rank's set is not among its owner's contacts")
        return number

    def _build_G(self, centers, new_set: bool):
        """The G blocks of the contact set. new_set: the contact set was detected or restored; on N > 1 ranks in
        colour order this rank's part is then found (`_rank_contacts`), the step's per-contact arrays cut to its own
        contacts' rows (`_own_rows`) and the contact set to its contacts L: what the rank keeps. Between
        re-detections (updated geometry) the pairs and their order stay, and so does the part. Returns the own
        contacts as numbers in the set before the cut (None: every contact kept)."""
        s = self.scene
        own = None
        if new_set:
            if self._local is not None:
                self._local.destroy()
            self._local = None
            if self._split():
                self._local, own, L = self._rank_contacts()
                self._own_rows(own)
                if L.size != len(self.cs.gap):
                    self.cs = self.cs.subset(L)
        self.G = self._kin.build_G(self.cs, s.kind, s.rot, centers, s.bnode_index_flat, s.bnode_offset)
        return own

    # the step's arrays with one row per contact: N > 1 ranks in colour order, of this rank's own contacts only
    # (`_own_rows`); else of every contact
    ROWS = ("P", "P_prev", "state", "law", "par", "mu", "gap_ref", "g_built")

    def _own_rows(self, own):
        """N > 1 ranks in colour order: cut the step's per-contact arrays (ROWS) of every contact of the current set
        (the first contact set, made before the partition; a checkpoint) to the rows of this rank's own contacts
        `own` (numbers in that set, increasing); arrays already of those rows (a later re-detection's, `_new_rows`;
        a snapshot of this run, taken on the same ranks) stay. (When the set holds only the own contacts both are
        the same.) Each contact's values are then computed, solved and committed by its owner alone."""
        for name in self.ROWS:
            setattr(self, name, self._to_own(name, getattr(self, name, None), own))

    def _to_own(self, name: str, a, own):
        """Per-contact rows `a` (named `name`) as those of the own contacts `own` (numbers in the current set): the
        rows of every contact of the set cut, the own rows (or None) as they are."""
        n = len(self.cs.gap)
        if a is None or len(a) == own.size:
            return a
        if len(a) != n:
            raise RuntimeError(f"contact step: {name} has {len(a)} rows, neither the {n} contacts nor the "
                               f"{own.size} of this rank")
        return np.ascontiguousarray(a[own])

    def _record_rows(self) -> dict:
        """The rows a step's record holds (contact/result.py): those of every contact, or on N > 1 ranks in colour
        order this rank's own, with the gather of every rank's (distributed/sweep.OwnRowsGather of the own contacts'
        ids: a record keeps the gather of its own contact set)."""
        if self._local is None:
            return {}
        return dict(rows=self._local.own, gather=self._local.gather)

    def _totals(self, friction=None) -> list:
        """[Σ S_DISS of the committed law states (+ Σ friction, the step's frictional work per contact, when given)]
        over every contact [J], each an exact sum rounded once (distributed/exact.py: the same double whatever the
        order and the split of the terms). N > 1 ranks in colour order: each rank adds its own rows, one Allreduce
        of the accumulators (2 × 560 bytes) gives every rank one process's sums, bitwise."""
        from ..distributed.exact import exact_sums
        from ..laws import S_DISS
        terms = [self.state[:, S_DISS]] + ([friction] if friction is not None else [])
        return exact_sums(terms, self.comm if self._local is not None else None)

    def law_codes(self, cs) -> np.ndarray:
        """The law code of every contact of the current contact set `cs` (its interfaces' laws)."""
        return self._codes[cs.interface]

    def _impulse(self, P: np.ndarray) -> np.ndarray:
        """H P, the contact impulses on the bodies (flat W-numbered vector), P the impulses of the step's rows. N > 1
        ranks in colour order: the impulses of the contacts L not owned come from their owners (`_L_impulses`, a
        PETSc scatter); each rank sums the impulses on its own bodies from its contacts L (all that act on them, in
        increasing contact number, as one process does), and an all-reduce of the vectors, zero elsewhere, gives
        every rank the same bits."""
        s, K = self.scene, self._kin
        if self._local is None:
            return K.accumulate_impulse(self.G, P, s.n_udof, s.U_offset)
        from mpi4py import MPI
        imp = K.accumulate_impulse(self.G, self._L_impulses(P), s.n_udof, s.U_offset)
        imp[~self._local.dofs] = 0.0
        self.comm.Allreduce(MPI.IN_PLACE, imp, op=MPI.SUM)
        return imp

    def _L_impulses(self, P_own: np.ndarray) -> np.ndarray:
        """The impulses (len(L), d) of this rank's contacts L from those of its own contacts: the others' from their
        owners by one PETSc scatter (built once per contact set: a distributed vector of every rank's own rows, in
        the global numbering `_RankContacts.number`, scattered to the rows of L that another rank owns)."""
        from petsc4py import PETSc
        loc, d = self._local, self.dim
        if loc.scatter is None:
            other = np.setdiff1d(np.arange(loc.ids.size), loc.own, assume_unique=True)
            pc = PETSc.Comm(self.comm)
            vec = PETSc.Vec().createMPI((d * loc.own.size, d * loc.n), bsize=d, comm=pc)
            gvec = PETSc.Vec().createSeq(d * other.size, bsize=d, comm=PETSc.COMM_SELF)
            isf = PETSc.IS().createBlock(d, loc.number[other].astype(PETSc.IntType), comm=PETSc.COMM_SELF)
            ist = PETSc.IS().createBlock(d, np.arange(other.size, dtype=PETSc.IntType), comm=PETSc.COMM_SELF)
            loc.scatter = (PETSc.Scatter().create(vec, isf, gvec, ist), vec, gvec, other)
            isf.destroy()
            ist.destroy()
        sc, vec, gvec, other = loc.scatter
        out = np.empty((loc.ids.size, d))
        out[loc.own] = P_own
        vec.placeArray(np.ascontiguousarray(P_own, dtype=np.float64).ravel())
        try:
            sc.scatter(vec, gvec)
        finally:
            vec.resetArray()
        out[other] = gvec.getArray().reshape(-1, d)
        return out

    def _linear_solver(self):
        """N > 1 ranks and a Newton solver: the distributed solve of J Δr = -F on the Delassus operator's pattern
        (_SharedLinear: built at the first Newton iteration, kept while W's block pattern does not change)."""
        if self.comm is None or not (self.opts.solver == "newton" or self.opts.fallback == "newton"):
            return None
        if self._linear is None:
            self._linear = _SharedLinear(self.comm)
        self._linear.bind(self.Wdel, self._owner)
        return self._linear

    def _check_replicas(self, bx=None):
        """N > 1 ranks: every rank built its own copy of the model; their contact sets and Delassus operators must
        agree (nodes whose BLAS or CPU differ can give different bits). When every rank holds the whole contact set
        and W (not in colour order): the contact count, a checksum of the gaps, W's block count and a checksum of a
        sample of its blocks. In colour order each rank holds its own part of both: the number of contacts of the
        whole set and a checksum of a sample of the positions bx its detection and G read (`_geometry`'s, when the
        step detected or updated the geometry). RankMismatchError on every rank if they differ."""
        import zlib
        from ..errors import RankMismatchError
        if self._local is not None:
            mine = (self._local.n,)
            if bx is not None:
                mine += (zlib.crc32(np.ascontiguousarray(bx[::max(1, len(bx) // 4096)]).tobytes()),)
        else:
            W = self.Wdel
            step = max(1, W.blocks.shape[0] // 4096)
            mine = (len(self.cs.gap), zlib.crc32(np.ascontiguousarray(self.cs.gap).tobytes()), W.n, W.indices.size,
                    zlib.crc32(np.ascontiguousarray(W.blocks[::step]).tobytes()))
        every = self.comm.allgather(mine)
        if any(x != every[0] for x in every):
            bad = [p for p, x in enumerate(every) if x != every[0]]
            raise RankMismatchError(f"the MPI ranks' copies of the model differ at step {self.steps + 1} (contacts, "
                                    f"Delassus blocks, checksums: rank 0 {every[0]}, ranks {bad} otherwise): run on "
                                    "nodes of one kind (same CPU, same BLAS), e.g. with OPENBLAS_CORETYPE set")

    def close(self):
        """Release the PETSc objects of a run on N > 1 ranks (collective: every rank calls it at the end). A step
        after it assembles W again: the colour solver that goes held W's arrays, their column numbers made its own
        (ColourSolver.from_sweep_rows)."""
        for obj in (self._colours, self._linear, self._local):
            if obj is not None:
                obj.destroy()
        if self._colours is not None:
            self.W_dirty = True
        self._colours = self._linear = None

    def _colour_solver(self):
        """order = "colours": the colour solver of the current Delassus operator (rebuilt with it), whose rows
        `_delassus` assembled in the sweep order of `_plan`; on N > 1 ranks each contact is owned by the rank of its
        candidate body. W's arrays become the solver's (ColourSolver.from_sweep_rows: nothing else reads them in
        colour order; `Wdel` then only identifies the operator the solver was built for). Updated geometry
        assembles W at every step, mostly for the same contacts: the new solver takes over the previous one's
        scatters and layout when the structure is the same (from_sweep_rows' `previous`: the same solver, bit for
        bit)."""
        if self.opts.order != "colours":
            return None
        if self._colours is not None and self._colours.W is self.Wdel:
            return self._colours
        from ..distributed.colour import ColourSolver
        if self._plan is None:
            raise RuntimeError("contact step: no sweep plan for the Delassus operator (W assembled outside _delassus)")
        prev, loc = self._colours, self._local
        n = len(self.cs.gap) if loc is None else loc.n
        columns = np.arange(n, dtype=np.int64) if loc is None else loc.number
        self._colours = ColourSolver.from_sweep_rows(self.Wdel, self._plan, columns, n,
                                                     self.comm if loc is not None else None,
                                                     previous=prev if self.opts.geometry == "updated" else None)
        self._plan = None
        if prev is not None:
            prev.destroy()  # (nothing left to release if the new solver took it over)
        return self._colours

    def mark_W_dirty(self):
        """The Delassus operator must be rebuilt (new h, drivers changed): rigid W from the current orientation."""
        self.W_dirty = True
        self._rigid_W_restored = None

    def _table(self):
        gid = {g: i for i, g in enumerate(self.group_names)}
        table = det.build_table(self.interfaces, gid)
        if self.dim == 2:
            return table
        for k, itf in enumerate(self.interfaces):  # 3D: no overlap placement; the default stays "positions"
            if itf.placement == "overlap":
                raise InputError(f"interfaces.{itf.name}.placement = 'overlap': expected 'positions' or 'nodes' "
                                 f"in 3D")
            if itf.placement is None:
                table.placement[k] = 0
        return det3.InterfaceTable.from_2d(table)

    def _detect(self, bx):
        """The contact set at positions bx. On N > 1 ranks in colour order once the bodies are partitioned: each rank
        detects the contacts whose candidate body is within two rings of body neighbours of its own bodies (the
        detections' `bodies`: bitwise the whole detection's rows of those contacts, in its order), a superset of the
        contacts L it keeps (`_candidates`; cut by `_build_G`): no rank detects or holds the whole set."""
        s = self.scene
        args = (bx, s.bnode_body, s.bnode_local) + ((s.bedges, s.bedge_body) if self.dim == 2 else
                                                    (s.bfaces, s.bface_body)) + (s.kind, self.body_group, self.table)
        if not self._parted():
            cs = self._det.detect(*args)
        else:  # (an error found by one rank, e.g. a node facing too many bodies, raised on every rank alike)
            cs, err = None, None
            try:
                cs = self._det.detect(*args, bodies=self._candidates(bx))
            except InputError as e:
                err = str(e)
            first = next((e for e in self.comm.allgather(err) if e is not None), None)
            if first is not None:
                raise InputError(first)
        if self.dim == 2:
            cs.area = cs.area * self.body_thickness[cs.cand_body]  # tributary length x thickness
        return cs

    def _parted(self) -> bool:
        """N > 1 ranks in colour order with the bodies partitioned: each rank detects and holds its part of the
        contact set."""
        return self._split() and self.body_owner is not None and len(self.body_owner) == self.scene.nb

    def _first_partition(self, bx):
        """COLLECTIVE, the first step on N > 1 ranks in colour order: the bodies' partition without the whole contact
        set on any rank. The bodies are first split into contiguous blocks of numbers (a provisional partition), each
        rank detects its part of the contact set for its block (`_detect`), and the body graph is assembled from the
        contacts each rank owns under it (`_partition`): the graph of the whole set, each contact given once."""
        size = self.comm.Get_size()
        self.body_owner = (np.arange(self.scene.nb) * size // max(self.scene.nb, 1)).astype(np.int64)
        self.cs = self._detect(bx)
        self.body_owner = self._partition(self._given())

    def _candidates(self, bx) -> np.ndarray:
        """(nb,) bool: the candidate bodies of the contacts this rank's part L can hold (`_rank_contacts`): its own
        bodies O, their neighbours (the bodies of its own contacts: B ⊆ N(O)) and theirs (a contact with a body in B
        has its candidate in N(B) ⊆ N(N(O))); neighbours are the bodies whose boxes, enlarged by the search distance
        g0 + alert, overlap (broadphase.body_pairs: the 2D detection's own body pairs, and more than the 3D one's)."""
        from .broadphase import body_pairs, near_bodies
        t, s = self.table, self.scene
        reach = float(np.max(t.g0 + t.alert)) if len(t.g0) else 0.0
        pairs = body_pairs(bx - reach, bx + reach, s.bnode_body, s.nb)
        return near_bodies(pairs, near_bodies(pairs, self.body_owner == self.comm.Get_rank()))

    def _delassus(self, W_flat, W_offset, W_size):
        """W of the contact set. In colour order only the blocks that couple are assembled (delassus.assemble's
        couplings): the rows the colour solver sweeps, held once, assembled directly in its sweep order (`_plan`,
        colours read from the bodies: distributed/colour.sweep_plan); on N > 1 ranks the rows of this rank's own
        contacts only, columns the contacts L."""
        from .. import delassus
        if self.opts.order != "colours":
            return delassus.assemble(self.G, W_flat, W_offset, W_size, self.scene.nb)
        from ..distributed.colour import body_pair_keys, moving_bodies, sweep_plan
        cs, loc, nb = self.cs, self._local, self.scene.nb
        moving = moving_bodies(W_flat, W_offset, W_size)
        if loc is None:
            self._plan = sweep_plan(body_pair_keys(cs.cand_body, cs.ant_body, nb), cs.cand_body, cs.ant_body, moving)
        else:  # (the contacts L only: a group's key gives its candidate body, whose rank owns the group)
            cand, ant, owner = cs.cand_body, cs.ant_body, self.body_owner
            self._plan = sweep_plan(body_pair_keys(cand, ant, nb), cand, ant, moving, own=loc.own,
                                    owner_of=lambda g: owner[g // nb], comm=self.comm)
        return delassus.assemble(self.G, W_flat, W_offset, W_size, self.scene.nb, rows=self._plan.rows,
                                 couplings=True)

    def _initial_state(self):
        """Committed law state of new contacts (the step's rows): 2D (n, NSTATE); 3D one more column, S_US = NSTATE
        (u_S)."""
        from ..laws import initial_state
        return initial_state(self.law, self.dim)

    def _assign_laws(self, rows=None):
        """Per-contact law code, parameters (per unit area) and friction from the contact's interface: of every
        contact, or of the contacts `rows` (this rank's own, increasing: the step's rows on N > 1 ranks in colour
        order). Whether any contact of the set is cohesive is read from the interfaces of these contacts (on N > 1
        ranks in colour order, COLLECTIVE: of every rank's, all-reduced)."""
        cs = self.cs
        self._assign_cracks()
        from ..laws import pack
        laws = [pack(itf.law, itf.law_values) for itf in self.interfaces]
        codes = np.array([c for c, _ in laws], dtype=np.int64)
        pars = np.array([p for _, p in laws])
        self._codes = codes  # (per interface: the law code of every contact is codes[cs.interface], law_codes)
        mine = cs.interface if rows is None else cs.interface[rows]
        self.law = codes[mine]
        self.par = np.ascontiguousarray(pars[mine])
        self.mu = self.par[:, 0].copy()
        from ..laws import P_FC
        used = np.bincount(mine, minlength=len(self.interfaces)) > 0
        if self._split():  # (COLLECTIVE: the interfaces of the whole set, of which a rank may hold a part)
            from mpi4py import MPI
            every = np.empty(used.size, dtype=np.int64)
            self.comm.Allreduce(used.astype(np.int64), every, op=MPI.MAX)
            used = every > 0
        self.cohesive = bool(np.any(used & ((codes != 0) | (pars[:, P_FC] > 0))))  # caps: cohesive kernels
        if self.opts.coarse != "none" and self.cohesive:
            bad = next(itf for itf, (c, p) in zip(self.interfaces, laws) if c != 0 or p[P_FC] > 0)
            raise InputError(f"interfaces.{bad.name}.law = {bad.law!r}: contact.coarse = {self.opts.coarse!r} handles "
                             "the Coulomb law without crushing cap only; expected contact.coarse = 'none'")
        self._coarse = None  # built at the next solve from the new contact set
        if self.dim == 3 and self.cohesive and self.opts.solver == "newton":
            bad = next(itf for itf, (c, p) in zip(self.interfaces, laws) if c != 0 or p[P_FC] > 0)
            raise InputError(f"interfaces.{bad.name}.law = {bad.law!r}: the 3D Newton solver handles the Coulomb law "
                             f"without crushing cap only; expected contact.solver = 'nlgs' for 3D interface laws")

    def _assign_cracks(self):
        """Contacts between the two halves of one split brick take the crack interface of their group pair."""
        cs = self.cs
        gid = {g: i for i, g in enumerate(self.group_names)}
        for k, itf in enumerate(self.interfaces):
            if itf.orientation != "crack" or len(cs.gap) == 0:
                continue
            ga, gb = (gid[g] for g in itf.groups)
            pa, pb = self.body_parent[cs.cand_body], self.body_parent[cs.ant_body]
            g1, g2 = self.body_group[cs.cand_body], self.body_group[cs.ant_body]
            same = (pa >= 0) & (pa == pb) & (((g1 == ga) & (g2 == gb)) | ((g1 == gb) & (g2 == ga)))
            cs.interface[same] = k

    def _geometry(self, sim, first: bool):
        s = self.scene
        updated = self.opts.geometry == "updated"
        if updated:
            s.refresh_frames()  # co-rotational bodies: G in the frames of the step's start (docs/method.md §7)
        redetect = first or (updated and self.steps % self.opts.redetect_every == 0)
        bx = None  # the positions of this step's geometry (updated geometry and every re-detection)
        if redetect:
            ref = first and not updated
            bx = s.positions(reference=ref)
            old, oldP, old_built, old_local = self.cs, self.P, self.g_built, self._local
            old_state = getattr(self, "state", None)
            self.P_prev = None  # (a new contact set: no extrapolation across a re-detection)
            if first and self._split() and not self._parted():
                self._first_partition(bx)
            self.cs = self._detect(bx)
            self._check_initial_penetration(first, bx)
            carry = old is not None and oldP is not None and self._total(len(self.cs.gap)) > 0
            moved = carry and old_local is not None and self._rebalance()  # (a new partition: body_owner replaced)
            if moved:  # (the contacts of the rank's new bodies: detected again for the new partition)
                self.cs = self._detect(bx)
            nc = len(self.cs.gap)
            rows = self._new_rows()  # the step's rows of the new set: its own contacts, or None (every contact)
            self._assign_laws(rows)
            take = (lambda x: x) if rows is None else (lambda x: x[rows])
            n = nc if rows is None else rows.size
            self.P = np.zeros((n, self.dim))
            st = self._initial_state()
            built = np.zeros(n)  # updated geometry: as-built gap offsets g_built (0 = nominal)
            if carry:  # each row continues the old contact matched to it (same candidate point and antagonist body)
                olds = [oldP, old_state] + ([old_built] if old_built is not None else [])
                if old_local is None:  # the old rows of every contact
                    src = take(match(old, self.cs))
                else:  # the old rows of the old own contacts, matched by contact id
                    new_ids = contact_ids(take(self.cs.key), take(self.cs.ant_body), s.nb)
                    olds, src = self._carry_rows(old, old_local, olds, new_ids, moved or rows is None)
                ok = src >= 0
                for new, o in zip([self.P, st, built], olds):
                    new[ok] = o[src[ok]]
            self.state = st
            if ref:  # frozen geometry: reference gaps; "as_built" joints are closed in the initial configuration
                self.gap_ref = take(self.cs.gap - self.cs.g0)
                self.gap_ref[take(self._as_built()[self.cs.interface])] = 0.0
            elif updated:  # the initial set's as-built contacts keep their initial g - g0 as an offset
                if first:
                    ab = take(self._as_built()[self.cs.interface]) if nc else np.zeros(0, dtype=bool)
                    built[ab] = take(self.cs.gap - self.cs.g0)[ab]
                self.g_built = built
        elif updated:  # between re-detections: same pairs, current points, frames and gaps
            bx = s.positions()
            if len(self.cs.gap):
                self.cs = self._det.update_geometry(self.cs, bx, s.bedges if self.dim == 2 else s.bfaces)
        if redetect or updated:
            self._build_G(s.centers(reference=redetect and first and not updated), new_set=redetect)
            self.mark_W_dirty()
        if self.W_dirty:
            from time import perf_counter
            c = perf_counter()
            W_flat, W_offset, W_size = s.W_blocks(self._rigid_W_restored)
            self._rigid_W_restored = None
            self.Wdel = self._delassus(W_flat, W_offset, W_size)
            self.W_dirty = False
            if self.comm is not None:
                self._check_replicas(bx)
            self.timers["delassus"] += perf_counter() - c

    def _new_rows(self):
        """The step's rows of a new contact set: N > 1 ranks in colour order with the bodies partitioned, this rank's
        own contacts (candidate body its own; increasing, as `_rank_contacts` finds them); else None (every contact,
        cut at `_own_rows` once the partition is made)."""
        return self._given() if self._parted() else None

    def _total(self, n: int) -> int:
        """The number of contacts of the whole set, from this rank's `n`: n itself when every rank holds the whole
        set; once a split detection gave each rank its part, the ranks' own contacts summed (COLLECTIVE)."""
        if not self._parted():
            return n
        from mpi4py import MPI
        return int(self.comm.allreduce(int(self._given().size), op=MPI.SUM))

    def _fail_together(self, bad: bool, message: str):
        """COLLECTIVE: RuntimeError("contact step: " + message) on every rank if any rank found `bad` (a check of
        the ranks' agreement: one rank raising alone would leave the others waiting in the next collective)."""
        from mpi4py import MPI
        if self.comm.allreduce(int(bad), op=MPI.MAX):
            raise RuntimeError(f"contact step: {message} (found by a rank)")

    def _carry_rows(self, old, old_local, olds, new_ids, elsewhere: bool):
        """The old rows `olds` (arrays of the old own contacts' rows, held by their owners, `old_local`, old set
        `old`) that the new rows continue: new row i continues the old contact with its id new_ids[i]. Returns
        (arrays, src): new row i continues arrays[k][src[i]] (src -1: a new contact).
        elsewhere False (no new partition): a contact continues one with the same candidate point, so of the same
        candidate body and owner: the old own rows as they are, looked up by id.
        elsewhere True, COLLECTIVE: a new partition (the old rows go to the new owners of their candidate bodies: one
        Alltoall of the counts, one Alltoallv of the ids, one of the rows packed; a rank receives the rows of its new
        own contacts' bodies, never the whole set's), or no rows of its own now (the new set whole on every rank: a
        stage leaving colour order; every old row gathered, in the whole set's order)."""
        ids = old_local.gather.ids
        if not elsewhere:
            return olds, _lookup(ids, new_ids)
        from ..distributed.sweep import exchange
        comm = self.comm
        if not self._split():
            every = old_local.gather(ids.reshape(-1, 1))[:, 0]
            return [old_local.gather(x) for x in olds], _lookup(every, new_ids)
        size = comm.Get_size()
        dest = self.body_owner[old.cand_body[old_local.own]]  # the new owner of each old own contact
        o = np.argsort(dest, kind="stable")
        scounts = np.bincount(dest, minlength=size)
        got, rcounts = exchange(comm, ids[o], scounts)
        flat = [np.asarray(x, dtype=np.float64).reshape(len(x), int(np.prod(np.shape(x)[1:]))) for x in olds]
        width = [f.shape[1] for f in flat]
        rbuf, _ = exchange(comm, np.hstack(flat)[o] if flat else np.zeros((len(o), 0)), scounts, rcounts)
        k = np.argsort(got, kind="stable")  # (the rows received, by id: from several ranks, interleaved)
        got, rbuf = got[k], rbuf[k]
        out, at = [], 0
        for x, c in zip(olds, width):
            out.append(rbuf[:, at:at + c].reshape((got.size,) + np.shape(x)[1:]))
            at += c
        return out, _lookup(got, new_ids)

    def _check_initial_penetration(self, first, bx):
        """Bodies overlapping at the start (boundaries crossing deeper than the alert distance) are a
        geometry error, as are contact points already penetrating by more than the alert distance."""
        if not first:
            return
        names = self.body_names or [str(i) for i in range(self.scene.nb)]
        alert = min(itf.alert for itf in self.interfaces)
        s = self.scene
        ov = det.find_overlap(bx, s.bnode_body, s.bedges, s.bedge_body, alert) if self.dim == 2 else None
        if ov is not None:
            raise InputError(f"bodies {names[ov[0]]} and {names[ov[1]]} overlap at the start by {ov[2]:.3g} m "
                             f"(more than the alert distance {alert:.3g} m)")
        cs = self.cs
        gt = cs.gap - cs.g0
        alerts = np.array([itf.alert for itf in self.interfaces])[cs.interface]
        bad = np.flatnonzero((gt < -alerts) & ~self._as_built()[cs.interface])
        found = None
        if bad.size:  # (the deepest, the first in the set's order among equals)
            a = bad[np.argmin(gt[bad])]
            found = (float(gt[a]), int(contact_ids(cs.key[a:a + 1], cs.ant_body[a:a + 1], s.nb)[0]),
                     f"bodies {names[cs.cand_body[a]]} and {names[cs.ant_body[a]]} overlap at the start by "
                     f"{-gt[a]:.3g} m (more than the alert distance {alerts[a]:.3g} m)")
        if self._parted():  # (each rank its part of the set: the deepest of every rank's, by contact id among equals)
            from ..distributed.root import least_found
            found = least_found(self.comm, found)
        if found is not None:
            raise InputError(found[2])

    def _as_built(self) -> np.ndarray:
        """Per interface: joints closed as built (frozen: reference gap 0; updated: the initial set's contacts carry
        their initial g - g0 as the offset g_built)."""
        return np.array([itf.reference == "as_built" for itf in self.interfaces], dtype=bool)

    def initial_contacts(self, sim) -> dict:
        """Contact points per interface in the initial configuration (interface name -> count), with the checks of
        a run's first step (bodies overlapping, points penetrating deeper than the alert distance): what
        `fem-blocks check` reports. The step is left unset (a run sets itself up at its first step)."""
        try:
            self._setup(sim)
            bx = self.scene.positions(reference=True)
            self.cs = self._detect(bx)
            self._check_initial_penetration(True, bx)
            self._assign_laws()
            n = (np.bincount(self.cs.interface, minlength=len(self.interfaces)) if len(self.cs.gap)
                 else np.zeros(len(self.interfaces), dtype=int))
        finally:
            self.scene, self.cs = None, None
        return {itf.name: int(k) for itf, k in zip(self.interfaces, n)}

    def _setup(self, sim):
        self.dim = sim.dim
        self._det, self._kin = (det, kin) if self.dim == 2 else (det3, kin3)
        self._cs_cls = det.ContactSet if self.dim == 2 else det3.ContactSet
        if self.dim == 3 and self.opts.coarse != "none":
            raise InputError(f"contact.coarse = {self.opts.coarse!r}: the interface coarse space is 2D only; expected "
                             "'none' in 3D")
        if self.dim == 3 and self.opts.solver == "newton":
            from ..solver import newton
            if not hasattr(newton, "alart_curnier_3d"):
                raise InputError("contact.solver = 'newton': this build has no 3D Newton solver; expected 'nlgs'")
        self.scene = ContactScene(sim, self.body_group)
        self.table = self._table()
        self.body_thickness = (np.array([b.type.material.thickness if b.kind == 0 else b.thickness
                                         for b in sim.bodies]) if self.dim == 2 else None)

    # ------------------------------------------------------------------ geometry queries (writers, figures)
    def contact_points(self, cs, reference: bool = False) -> np.ndarray:
        """(nc, 2) positions of the candidate points of 2D contact set `cs` in the current (or reference)
        configuration of the bodies (ContactScene.contact_points)."""
        return self.scene.contact_points(cs, reference)

    def joint_lengths(self, cs) -> np.ndarray:
        """(nc,) tributary joint length of each 2D contact: area / thickness of the candidate body [m]."""
        return cs.area / self.body_thickness[cs.cand_body]

    # ------------------------------------------------------------------ checkpoint
    @property
    def _CS(self):
        return tuple(f.name for f in dataclasses.fields(self._cs_cls))

    # the checkpoint entries with one row per contact (the others: counters, the partition, 3D's rigid W); the
    # last step's outputs ("contact.out.*", ContactResult.export) are per contact too
    PER_CONTACT = ("contact.P", "contact.state", "contact.law", "contact.P_prev", "contact.gap_ref",
                   "contact.g_built")

    @classmethod
    def per_contact_keys(cls, keys) -> list:
        """The entries of `keys` (a checkpoint's) with one row per contact of the contact set."""
        return [k for k in keys if k in cls.PER_CONTACT or k.startswith(("contact.cs.", OUT_PREFIX))]

    def export_state(self) -> dict:
        """Arrays that determine the rest of the run: contact set, G blocks, reference gaps, impulses (warm
        start), law states and counters (the shuffled order's seed is `seed + steps`). The last step's outputs
        (ContactResult.export, "contact.out.*") are exported by the simulation that keeps the record."""
        d = {"contact.steps": np.int64(self.steps), "contact.n_unconverged": np.int64(self.n_unconverged),
             "contact.friction_total": np.float64(self.friction_total)}
        if self.cs is None:
            return d
        for k in self._CS:
            d[f"contact.cs.{k}"] = getattr(self.cs, k)  # (N > 1 ranks in colour order: this rank's part of the set)
        d["contact.n_contacts"] = np.int64(len(self.cs.gap) if self._local is None else self._local.n)
        d["contact.P"], d["contact.state"], d["contact.law"] = self.P, self.state, self.law
        if self.h_last is not None:  # the predictor's history
            d["contact.h_last"] = np.float64(self.h_last)
            if self.P_prev is not None:
                d["contact.P_prev"], d["contact.h_prev"] = self.P_prev, np.float64(self.h_prev)
        if self.body_owner is not None:  # N > 1 ranks: the partition in use (PT-Scotch's differs from run to run)
            d["contact.body_owner"] = self.body_owner
        if getattr(self, "gap_ref", None) is not None:
            d["contact.gap_ref"] = self.gap_ref
        if self.g_built is not None:
            d["contact.g_built"] = self.g_built
        if self.dim == 3 and self.scene is not None and len(self.scene.rigid) and self.scene.rigid_W:
            # 3D: the rigid W of the last Delassus assembly depends on the orientation then (frozen geometry keeps
            # it until the next rebuild), so it is part of the state
            d["contact.rigid_W"] = np.array([self.scene.rigid_W[i] for i in self.scene.rigid])
            d["contact.W_dirty"] = np.bool_(self.W_dirty)
        return d

    def restore_state(self, sim, d: dict) -> ContactResult | None:
        """Inverse of `export_state`, for a Simulation built from the same case. Returns the record of the
        checkpointed step (contact set, impulses, law state and the "contact.out.*" outputs; statistics and
        velocity corrections are not checkpointed: they were applied), or None before the first contact step."""
        self.steps = int(d["contact.steps"])
        self.n_unconverged = int(d["contact.n_unconverged"])
        self.friction_total = float(d.get("contact.friction_total", 0.0))  # (0 from a checkpoint that predates it)
        if "contact.cs.gap" not in d:
            return None
        self._setup(sim)
        self.cs = self._cs_cls(**{k: np.array(d[f"contact.cs.{k}"]) for k in self._CS})
        if len(self.cs.cand_body) and max(self.cs.cand_body.max(), self.cs.ant_body.max()) >= self.scene.nb:
            raise InputError("checkpoint: contacts refer to bodies this model does not have")
        self._assign_laws()
        self.P, self.state = np.array(d["contact.P"]), np.array(d["contact.state"])
        self.h_last = float(d["contact.h_last"]) if "contact.h_last" in d else None
        self.P_prev = np.array(d["contact.P_prev"]) if "contact.P_prev" in d else None
        self.h_prev = float(d["contact.h_prev"]) if "contact.h_prev" in d else None
        self.gap_ref = np.array(d["contact.gap_ref"]) if "contact.gap_ref" in d else None
        self.g_built = (np.array(d["contact.g_built"]) if "contact.g_built" in d
                        else np.zeros(len(self.cs.gap)) if self.opts.geometry == "updated" else None)
        owner = np.array(d["contact.body_owner"]) if "contact.body_owner" in d else None
        self.body_owner = (owner if owner is not None and self.comm is not None and len(owner) == self.scene.nb
                           and owner.max(initial=0) < self.comm.Get_size() else None)  # else partitioned again
        # G: frozen geometry, from the reference placement as at the first step (the frames of the scene, never
        # refreshed); updated geometry rebuilds it at the next step
        own = self._build_G(self.scene.centers(reference=self.opts.geometry == "frozen"), new_set=True)
        self.W_dirty = True  # rebuilt at the next step (new scene); 3D: with the rigid W in use at the export
        self._rigid_W_restored = (np.array(d["contact.rigid_W"]) if "contact.rigid_W" in d
                                  and not bool(d["contact.W_dirty"]) else None)
        out = {k: np.array(d[OUT_PREFIX + k]) for k in OUT_FIELDS if OUT_PREFIX + k in d}
        if own is not None:  # (the record of a rank's own rows: a checkpoint's whole arrays cut to them)
            out = {k: (x if len(x) == own.size else np.ascontiguousarray(x[own])) for k, x in out.items()}
        return ContactResult(self.dim, {}, cs=self.cs, P=self.P.copy(), law=self.law.copy(), state=self.state.copy(),
                             friction_total=self.friction_total, dissipated=self._totals()[0],
                             **self._record_rows(), **out)

    # ------------------------------------------------------------------ the step
    def warm_start(self, h: float) -> np.ndarray:
        """The solver's starting impulses (nc, d) for a step h: `opts.predictor` (module docstring)."""
        mode = self.opts.predictor
        if mode == "previous" or self.h_last is None or self.P is None:
            return self.P
        r = self.P / self.h_last
        if mode == "extrapolated" and self.P_prev is not None and self.P_prev.shape == self.P.shape \
                and self.h_prev is not None:
            r = r + (h / self.h_last) * (r - self.P_prev / self.h_prev)
        return h * r

    def solve(self, sim, t0, t1) -> ContactResult:
        """One contact step over [t0, t1] from the free velocities of `sim` (read only): detection/geometry,
        local problem, solver, law commit. Returns the step's ContactResult (statistics, impulses, gaps, status,
        law state, velocity corrections); the simulation applies the corrections."""
        from time import perf_counter
        from ..solver import ContactProblem, InterfaceLaws, solve
        tm = self.timers
        c0 = perf_counter()
        first = self.scene is None
        if first:
            self._setup(sim)
        self._geometry(sim, first)
        c1 = perf_counter()
        tm["detection"] += c1 - c0  # includes the Delassus assembly when geometry or h changed
        s, cs, d = self.scene, self.cs, self.dim
        h, th = sim.h, sim.theta
        loc = self._local
        nc = len(cs.gap) if loc is None else loc.n  # (the whole set's, on every rank)
        self.steps += 1
        if nc == 0:
            gc, rc, ri = s.corrections(np.zeros(s.n_udof), sim.stepped_columns())
            return ContactResult(d, dict(contacts=0, active=0, sweeps=0, change=0.0, residual=0.0, converged=True,
                                         solver="none", message="no contact"), cs=cs, P=self.P.copy(),
                                 law=self.law.copy(), state=self.state.copy(), group_corr=gc, rigid_corr=rc,
                                 rigid_impulse=ri, friction=np.zeros(0), friction_total=self.friction_total,
                                 **self._record_rows())
        stepped = sim.stepped_columns()  # (the bodies the simulation steps: the others' entries are not read)
        ufree = s.gather("ufree", stepped)
        K = self._kin
        colours = self._colour_solver()
        # the step's contacts: every contact, or on N > 1 ranks in colour order this rank's own contacts (the rows of
        # the step's arrays, ROWS); `own` picks them from arrays of the contact set's rows (and G's, the same)
        own = (lambda x: x) if loc is None else (lambda x: np.ascontiguousarray(x[loc.own]))
        # v_free = G u_free, v_i = G u_i and (frozen geometry) the normal jump (G q)_N
        vfree = own(K.local_velocity(self.G, ufree, s.U_offset))
        vi = own(K.local_velocity(self.G, s.gather("u", stepped), s.U_offset))
        if self.opts.geometry == "frozen":
            gt = self.gap_ref + own(K.local_velocity(self.G, s.gather("q", stepped), s.U_offset))[:, 0]
        else:
            gt = own(cs.gap) - own(cs.g0) - self.g_built  # as-built contacts of the initial set: g - g0 - g_built
        area = own(cs.area)
        from ..laws import S_UP
        gt = gt - self.state[:, S_UP]  # crushed joints: the contact surface moved by the plastic closure u_p <= 0
        gbar = gt + h * (1 - th) * vi[:, 0]
        # a sub-step of a nominal step hn (sim.set_step(..., nominal=hn)) clears an existing penetration (gbar < 0)
        # at the nominal rate: the shifted gap gs = max(gbar, 0) + (h / hn) min(gbar, 0) (= gbar when h = hn)
        pen = np.minimum(gbar, 0.0)
        hn = getattr(sim, "h_nominal", None) or h
        gs = (gbar - pen) + pen * (h / hn)
        q = vfree.copy()
        q[:, 0] += gs / (h * th)
        c2 = perf_counter()
        tm["local"] += c2 - c1
        laws = None
        if self.cohesive:
            from ..laws import NSTATE, S_UN, S_UT
            ueff = self.state[:, [S_UN, S_UT] + ([NSTATE] if d == 3 else [])] + h * (1 - th) * vi
            ueff[:, 0] -= gs  # u = u_eff + h theta v_shifted (v_shifted = v_N + gs/(h theta))
            laws = InterfaceLaws(self.law, self.par, self.state, ueff, area, h, th)
        coarse = None
        if self.opts.coarse == "interfaces":
            if self._coarse is None:
                from ..solver.coarse import InterfaceCoarse
                self._coarse = InterfaceCoarse.from_contacts(cs, self.opts.coarse_every)
            coarse = self._coarse
        # (N > 1 ranks in colour order: the problem's rows are the own contacts', and so are the solution's)
        res = solve(ContactProblem(self.Wdel, q.ravel(), self.mu, laws=laws, own_rows=loc is not None),
                    dataclasses.replace(self.opts, seed=self.opts.seed + self.steps), r0=self.warm_start(h).ravel(),
                    coarse=coarse, colours=colours, linear=self._linear_solver())
        if self.cohesive:
            from ..laws import commit_step  # crushing at the cap, then the laws' commit (any dimension)
            commit_step(self.law, self.par, self.state, res.trial, ueff, res.r, res.u, area, h, th)
        else:
            from ..laws import NSTATE, S_UN, S_UT
            vs = res.u.reshape(-1, d)
            self.state[:, S_UN] += h * ((1 - th) * vi[:, 0] + th * (vs[:, 0] - gs / (h * th)))
            ut_cols = [S_UT] + ([NSTATE] if d == 3 else [])  # 3D: S_US = NSTATE
            self.state[:, ut_cols] += h * ((1 - th) * vi[:, 1:] + th * vs[:, 1:])
        c3 = perf_counter()
        tm["nlgs"] += c3 - c2
        P = res.r.reshape(-1, d)
        self.P_prev, self.h_prev, self.h_last = self.P, self.h_last, h
        self.P = P
        v = res.u.reshape(-1, d)
        from .friction import friction_work  # -r̃_T · Δu_T per contact, from the committed state
        friction = friction_work(self.law, self.par, self.state, P, v, vi, area, h, th)
        status = np.zeros(len(P), dtype=np.int64)  # 0 open, 1 stick, 2 slip
        closed = P[:, 0] > 0
        status[closed] = 1
        status[closed & (np.linalg.norm(P[:, 1:], axis=1) >= self.mu * P[:, 0] * (1 - 1e-9))
               & (np.linalg.norm(v[:, 1:], axis=1) > 1e-12)] = 2
        # the totals over every contact (exact sums: N > 1 ranks in colour order add their own rows and all-reduce
        # the accumulators; the counts summed)
        dissipated, friction_step = self._totals(friction)
        self.friction_total += friction_step
        counts = np.array([np.count_nonzero(status), np.count_nonzero(status == 2)], dtype=np.int64)
        if loc is not None:
            from mpi4py import MPI
            self.comm.Allreduce(MPI.IN_PLACE, counts, op=MPI.SUM)
        imp = self._impulse(P)
        gc, rc, ri = s.corrections(imp, sim.stepped_columns())  # (the bodies the simulation steps)
        tm["correction"] += perf_counter() - c3
        if not res.converged:
            self.n_unconverged += 1
        stats = dict(contacts=nc, active=int(counts[0]), slip=int(counts[1]), sweeps=int(res.sweeps),
                     change=float(res.change), residual=float(res.residual), converged=bool(res.converged),
                     solver=res.solver, message=str(res.message))
        if not res.converged and self.opts.on_nonconvergence == "fail":
            from ..errors import ConvergenceError
            raise ConvergenceError(f"step {sim.step_count + 1} (t = {t1:.6g} s): {stats['solver']} did not "
                                   f"converge in "
                                   f"{res.sweeps} sweeps (change {res.change:.3g}, residual {res.residual:.3g})")
        # v is the shifted normal velocity v_N + gs / (h theta): g~_{i+1} = gbar + h theta v_N
        return ContactResult(d, stats, cs=cs, P=P.copy(), r=P / h, v=v, gt_end=h * th * v[:, 0] + (gbar - gs),
                             status=status, law=self.law.copy(), state=self.state.copy(), group_corr=gc,
                             rigid_corr=rc, rigid_impulse=ri, friction=friction, friction_total=self.friction_total,
                             dissipated=dissipated, **self._record_rows())


def _lookup(sorted_ids, ids) -> np.ndarray:
    """The position of each of `ids` in `sorted_ids` (increasing, distinct), -1 where it is not there."""
    pos = np.searchsorted(sorted_ids, ids)
    if not len(sorted_ids):
        return np.full(len(ids), -1, dtype=np.int64)
    pos = np.minimum(pos, len(sorted_ids) - 1)
    return np.where(sorted_ids[pos] == ids, pos, -1).astype(np.int64)


@dataclasses.dataclass
class _RankContacts:
    """A rank's part of the contact set (N > 1 ranks in colour order, ContactStep._rank_contacts), whose contacts L
    are the contact set it keeps (`ContactStep.cs`, in the whole set's order: increasing id): own the positions of
    its own contacts in it, dofs the mask of its bodies' dofs in the flat W numbering; stepped the mask of the
    bodies it steps (its bodies, those of its own contacts, the rigid bodies); gather the gather of every rank's own
    rows in the whole set's order (the records', sweep.OwnRowsGather, which holds the own contacts' ids); ids the
    contact ids of L (contact/matching.contact_ids); number their global numbers (every rank's own contacts in rank
    order, `ContactStep._numbers`: the impulses' distributed vectors and the colour solver's columns); n the
    number of contacts of the whole set."""
    own: np.ndarray
    dofs: np.ndarray
    stepped: np.ndarray  # the bodies this rank steps (ContactStep.stepped_bodies): B and the rigid bodies
    gather: object
    ids: np.ndarray
    number: np.ndarray
    n: int
    scatter: tuple = None  # the PETSc scatter of the impulses of L's contacts owned elsewhere (_L_impulses)

    def destroy(self):
        """Release the PETSc objects (collective, as their creation)."""
        if self.scatter is not None:
            sc, vec, gvec, _ = self.scatter
            for obj in (sc, vec, gvec):
                obj.destroy()
            self.scatter = None
