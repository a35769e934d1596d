"""Moreau–Jean theta-method time stepping for deformable blocks and rigid bodies (docs/method.md §2), in 2D or 3D
(dimension d from the bodies: DeformableBody/RigidBody or DeformableBody3D/RigidBody3D, not mixed).

Per step [t_i, t_{i+1}], for every deformable body (type frame, clamped dofs eliminated):

    Mhat u_free = M u_i - h(1-theta) C u_i - h K q_i - h^2 theta(1-theta) K u_i + h F_theta,
    F_theta = (1-theta) F(t_i) + theta F(t_{i+1}),

one back-substitution per body, batched over all instances sharing a step operator (one
multi-right-hand-side solve per block type). Rigid bodies: u_free = u_i + h M^-1 F_theta on free
dofs, the prescribed velocity on driven dofs. Contacts (if any) add u_{i+1} = u_free + W H (h r), the
corrections of the ContactResult that the contact step returns (group_corr, rigid_corr; applied here); then

    q_{i+1} = q_i + h [(1-theta) u_i + theta u_{i+1}].

3D rigid bodies (dofs (v, ω) at the centre of mass, global frame): M = diag(m, m, m) ⊕ I, I = Rot I0 Rotᵀ in
the orientation at the start of the step, the free velocity on the free dofs

    u_free,f = u_i,f + h M_ff^-1 (F_theta - (0, ω_i × I ω_i))_f        (explicit gyroscopic moment),

and the orientation is updated by the rotation vector Δφ = h [(1-theta) ω_i + theta ω_{i+1}]:
Rot <- exp([Δφ]x) Rot (RigidBody3D.rotate).

Static step (stage key `static = true`, theta = 1): the same step with M = 0 and C = 0, so that
h^2 K u_{i+1} = -h K q_i + h F + H P, i.e. K q_{i+1} = F_{i+1} + H P / h: equilibrium at the end of the step with no
inertia (no dependence on h at a given displacement per step). Mhat = h^2 K must be invertible: every deformable
body clamped against all its rigid motions, every rigid body driven on all its dofs (`Simulation.static_obstacles`);
a body held only by contacts has no W = Mhat^-1 and is rejected (InputError). Rigid driver reactions then carry no
m (u_{i+1} - u_i) / h term, and the inertial parts below are 0.

Quasi-static option "velocity reset" (thesis §7.1.2.d): u_i := 0 on free dofs at the start of
every step. Reaction of the drivers on a driven rigid dof (what a load cell reads):

    R_drv = m (u_{i+1} - u_i) / h - F_theta - (H r)   (force applied by the driver on the body).

Inertial part of the driver reactions (docs/case-files.md "Quasi-static stages: inertia in the reactions"). The
step is the exact equilibrium of the inertia forces f_I = M (u_{i+1} - u_i) / h (u_i after a velocity reset) with
the internal, applied, contact and driver forces; dotted with the step's displacement dq = h((1-theta) u_i +
theta u_{i+1}) it gives the work identity  sum_k R_k dq_k = W_I + (elastic, damping, applied, contact work),

    W_I = sum over all bodies and dofs of dq . M (u_{i+1} - u_i) / h        (work of the inertia forces).

W_I is attributed to the driven dofs that move in the step, in proportion to |R_k dq_k|:

    I_k = W_I w_k / (sum_j w_j) / dq_k,   w_k = |R_k dq_k|,   I_k = 0 where sum_j w_j = 0 or dof k does not move:
    |dq_k| (rotations: |dq_k| x the body's radius) < MOVE_TOL x the largest displacement increment of the model
    in the step (a driver that stands still, up to rounding, while something else moves, e.g. settles under
    gravity, is not the cause of that motion),

stored as `body.reaction_inertia` (0 on free dofs). With one moving driven dof, I_k = W_I / dq_k is exactly the
part of R_k that the inertia forces produce through the step's displacement field (virtual work with dq as the
virtual field): for a rigid block of mass m pushed from rest by dq in a step, I = m dq / h^2.

Sums over bodies (the energies of `info`, the step's external work, driver work and W_I): each is

    S = fsum over bodies b of s_b,

s_b the body's term from its own arrays only (elementwise products, then its column of dofs added row by row,
`column_sums`; a rigid body's few dofs by np.dot) and the sum exact, rounded once (distributed/exact.py: math.fsum
of the terms, bitwise). So S is the same double whatever the grouping of the bodies (block types, members' order)
and, on N > 1 ranks with the bodies partitioned (the contact step's `body_partition`), whatever the partition: each
rank adds the terms of its own bodies and one Allreduce of the exact accumulators gives every rank S.

Bodies stepped per rank (N > 1 ranks in colour order, frozen geometry: the contact step's `stepped_bodies`). A
rank steps only the bodies it reads: B_p = its own bodies, the bodies of its own contacts (their local velocities),
the rigid bodies, and the bodies the outputs read at every step (`share_bodies`: those of the gauges, rotation
columns, stop conditions and curve). Each such body's step is the serial one, bitwise: its free velocity from its own
state (a column of the batched solve: PETSc's LU solves each column alone, linalg.Factor; block types factored
otherwise are stepped whole), its correction W H P from the impulses on it, all-reduced (contact/step.py
`_impulse`). The other bodies' q, u (and free velocities and loads) are set to NaN on this rank when the set is
taken (`_narrow`): any reader of a body this
rank does not step gets NaN, never a stale value; `collect_bodies` gives rank 0 every body's state from its owner
(the figures at the end of a run).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import corotational
from .bodies import DeformableBody, DeformableBody3D, RigidBody, RigidBody3D, check_step
from .distributed.exact import exact_sums, largest
from .errors import InputError

_BODY_KEY = "sim.body"  # a body's checkpoint entries: "sim.body<i>.<name>" (Simulation.export_state)


def column_sums(X: np.ndarray) -> np.ndarray:
    """Σ_i X[i, j] for each column j (a body of a group), its rows added one by one in order: each column's sum is
    the same double whatever the other columns (NumPy's reductions pick their order from the array's shape and
    layout, so a body's sum would depend on the bodies beside it). The same additions two ways, for speed: a loop
    over the rows for many columns, np.add.accumulate (sequential by definition) for a few."""
    n, k = X.shape
    if n == 0:
        return np.zeros(k)
    if k < 128:
        return np.add.accumulate(X, axis=0)[-1]
    out = X[0].copy()
    for row in X[1:]:
        out += row
    return out


def columns(A: np.ndarray, c) -> np.ndarray:
    """The columns c of a group's (ndof, k) array (its members' positions from `Simulation.own_bodies`; None: all),
    C-ordered (NumPy's A[:, c] is Fortran-ordered: the products and sparse products after it would run strided)."""
    return A if c is None else A.take(c, axis=1)


def _joined(terms: list) -> np.ndarray:
    """The per-body terms of a sum, as one array (empty: no term)."""
    return np.concatenate([np.ravel(t) for t in terms]) if terms else np.zeros(0)


def _dot_last(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Σ_j A[..., j] x[..., j], the terms added in order of j (per body, as `column_sums`)."""
    out = np.zeros(np.broadcast_shapes(A.shape, x.shape)[:-1])
    for j in range(A.shape[-1]):
        out += A[..., j] * x[..., j]
    return out


def body_of_key(key: str) -> int | None:
    """The body i of a checkpoint entry "sim.body<i>.<name>" (Simulation.export_state), None for any other entry."""
    if not key.startswith(_BODY_KEY):
        return None
    head = key[len(_BODY_KEY):].split(".", 1)[0]
    return int(head) if head.isdigit() else None

MOVE_TOL = 1e-3  # a driven dof "moves" in a step if its increment is >= MOVE_TOL x the model's largest increment


@dataclass
class StepInfo:
    step: int
    time: float
    kinetic: float
    elastic: float
    gravity_potential: float
    external_work: float
    max_velocity: float
    contact: dict = field(default_factory=dict)

    @property
    def total_energy(self) -> float:
        return self.kinetic + self.elastic + self.gravity_potential


class _Group:
    """Deformable bodies sharing one StepOperator; state stored as (ndof, k) arrays (type frame, or the body frame
    of a co-rotational group). A framed group (co-rotational kinematics, docs/method.md §7) also holds the frames
    R (k, d, d), position (k, d) and, 2D, the unwrapped angles phi (k,) since placement, R = R0 rot(phi); the
    bodies' R, position (and angle) are views into them."""

    def __init__(self, op, btype, members, bodies, framed: bool = False):
        self.op, self.type, self.members = op, btype, np.asarray(members, dtype=np.int64)
        k = len(members)
        self.Q = np.zeros((btype.ndof, k))
        self.U = np.zeros((btype.ndof, k))
        for j, b in enumerate(members):
            body = bodies[b]
            self.Q[:, j], self.U[:, j] = body.q, body.u
            body.q, body.u = self.Q[:, j], self.U[:, j]  # views: bodies see the group state
        self.clamped = op.clamped
        self.traction_bodies = [j for j, b in enumerate(members) if bodies[b].tractions]
        self.framed = bool(framed)
        if self.framed:
            mb = [bodies[b] for b in members]
            self.R = np.stack([b.R for b in mb])
            self.pos = np.stack([b.position for b in mb])
            self.R0 = np.stack([b.R0 for b in mb])
            self.pos0 = np.stack([b.position0 for b in mb])
            d = self.R.shape[1]
            self.phi = (np.array([0.0 if b._phi is None else float(b._phi[0]) for b in mb]) if d == 2 else None)
            for j, body in enumerate(mb):
                body.attach_frame(self.R[j], self.pos[j], self.phi[j:j + 1] if d == 2 else None)


class Simulation:
    """Time integration of a set of bodies (and, through `contact`, their interfaces).

    Parameters: bodies (DeformableBody / RigidBody in 2D, DeformableBody3D / RigidBody3D in 3D), h,
    theta in [0.5, 1], gravity vector (default (0, -9.81) in 2D, (0, 0, -9.81) in 3D), velocity_reset
    (quasi-static), contact: an optional object with `solve(sim, t0, t1)` that returns a
    contact.result.ContactResult (contact/step.py ContactStep); `step` applies its velocity corrections and keeps
    it as `last_contact`. corotational: every unclamped deformable body carries a frame (finite rotation plus small
    deformation, docs/method.md §7); None = automatic: True when the contact step's geometry is "updated"
    (`contact.opts.geometry`), else False. Clamped bodies keep the linear kinematics.
    """

    def __init__(self, bodies, h: float, theta: float = 0.5, gravity=None,
                 velocity_reset: bool = False, contact=None, t0: float = 0.0, static: bool = False,
                 corotational: bool | None = None):
        check_step(h, theta)
        if not bodies:
            raise InputError("bodies: expected at least one body")
        self.bodies = list(bodies)
        kinds = {2: (DeformableBody, RigidBody), 3: (DeformableBody3D, RigidBody3D)}
        self.dim = 3 if isinstance(self.bodies[0], kinds[3]) else 2
        for b in self.bodies:
            if not isinstance(b, kinds[self.dim]):
                names = " or ".join(c.__name__ for c in kinds[self.dim])
                raise InputError(f"bodies: {b!r} is not a {names} (all bodies of a simulation share the dimension "
                                 f"{self.dim} of the first one)")
        d = self.dim
        gravity = ((0.0, -9.81) if d == 2 else (0.0, 0.0, -9.81)) if gravity is None else gravity
        if np.size(gravity) != d or not np.all(np.isfinite(np.asarray(gravity, dtype=float))):
            raise InputError(f"gravity = {gravity!r}: expected {d} finite components [m/s^2]")
        self.g = np.asarray(gravity, dtype=float).reshape(d)
        self.rigid_ndof = 3 if d == 2 else 6
        self.velocity_reset = bool(velocity_reset)
        self.time, self.step_count = float(t0), 0
        self.external_work = 0.0
        self.driver_work = 0.0  # work of the drivers on driven rigid dofs: sum R_drv . dq
        self.inertia_work = 0.0  # work of the inertia forces in the last step (W_I, module docstring)
        self.contact = contact
        self.last_contact = None  # ContactResult of the last step (contact/result.py), read by writers and checks
        self.deformable = [i for i, b in enumerate(self.bodies) if b.kind == 0]
        self.rigid = [i for i, b in enumerate(self.bodies) if b.kind == 1]
        geometry = getattr(getattr(contact, "opts", None), "geometry", None)
        if corotational is None:
            corotational = geometry == "updated"
        elif corotational and contact is not None and geometry != "updated":
            raise InputError(f"corotational kinematics with contact.geometry = {geometry!r}: expected 'updated' (a "
                             "frozen contact geometry is the small-rotation reference configuration)")
        self.corotational = bool(corotational)
        self.shared = np.zeros(0, dtype=np.int64)  # bodies stepped on every rank (share_bodies)
        self._stepped_key, self._stepped = None, None  # stepped_columns' cache
        self._narrowed = None  # the key of the stepped set whose other bodies are NaN (_narrow)
        self.h, self.theta, self.static = None, None, False
        self.h_nominal = None  # set_step: the nominal step of which h is a sub-step (h itself by default)
        self.set_step(h, theta, static)

    # -------------------------------------------------------------- set-up
    def static_obstacles(self) -> list:
        """Why a static step (M = 0) is not well-posed for these bodies and drivers: [(body index, reason)]
        (empty: admissible)."""
        out = []
        names = ("x", "y", "rz") if self.dim == 2 else ("x", "y", "z", "rx", "ry", "rz")
        for i, b in enumerate(self.bodies):
            if b.kind == 0 and not b.type.clamps_fix_rigid_modes(b.clamped):
                out.append((i, "its clamps leave a rigid motion free (K is singular without the mass term)"))
            elif b.kind == 1 and not b.driven.all():
                free = ", ".join(n for n, d in zip(names, b.driven) if not d)
                out.append((i, f"its dofs {free} are not driven (a free rigid dof has only its mass)"))
        return out

    def set_step(self, h: float, theta: float, static: bool | None = None, nominal: float | None = None):
        """(Re)build the step operators for (h, theta, static); shared per block type and clamp set. static=True
        needs theta = 1 and no `static_obstacles` (InputError otherwise); None keeps the current choice.
        `nominal`: the step h is a sub-step of a nominal step (the runner's "refine"/"adaptive" policies): the contact
        step then clears an existing penetration at the nominal step's rate, not the sub-step's (contact/step.py);
        default h itself."""
        check_step(h, theta)
        self.h_nominal = float(h if nominal is None else max(nominal, h))
        static = self.static if static is None else bool(static)
        if static:
            if theta != 1.0:
                raise InputError(f"theta = {theta:g} with a static step: expected theta = 1")
            bad = self.static_obstacles()
            if bad:
                i, why = bad[0]
                raise InputError(f"static step: body {i} cannot be in equilibrium without inertia: {why}; expected "
                                 "every deformable body clamped against rigid motion and every rigid dof driven")
        if (h, theta, static) == (self.h, self.theta, self.static):
            return
        self.h, self.theta, self.static = float(h), float(theta), static
        groups: dict[int, list] = {}
        ops = {}
        for i in self.deformable:
            b = self.bodies[i]
            b.detach_frame()  # the new groups take copies of the frames (and of q, u)
            op = b.type.step_operator(self.h, self.theta, b.clamped, static)
            groups.setdefault(id(op), []).append(i)
            ops[id(op)] = (op, b.type)
        self._stepped_key = self._narrowed = None  # (new group arrays: the stepped set is taken again)
        self.groups = [_Group(ops[k][0], ops[k][1], members, self.bodies,
                              framed=self.corotational and not ops[k][0].clamped.any())
                       for k, members in groups.items()]
        for gr in self.groups:
            if gr.framed:
                self._frame_gravity(gr)
            else:
                gr.Fg = np.column_stack([self.bodies[b].type.gravity_load(self.bodies[b].R.T @ self.g)
                                         for b in gr.members])
        if self.contact is not None:
            self.contact.on_step_change(self)

    # -------------------------------------------------------------- loads
    def _group_load(self, gr: _Group, t: float, s=None) -> np.ndarray:
        """The applied load F(t) (gravity, tractions) of the group's bodies of columns s (None: every member)."""
        F = gr.Fg.copy() if s is None else gr.Fg.take(s, axis=1)
        for j in gr.traction_bodies:
            k = j if s is None else int(np.searchsorted(s, j))  # (its column in F)
            if s is not None and (k == len(s) or s[k] != j):
                continue
            body = self.bodies[gr.members[j]]
            for tr in body.tractions:
                F[:, k] += tr.history(t) * body.type.traction_load(tr.tag, body.R.T @ np.asarray(tr.value, float))
        return F

    # -------------------------------------------------------------- co-rotational frames (docs/method.md §7)
    def _frame_gravity(self, gr: _Group):
        """Gravity of a framed group in its body frames: F_g = G (Rᵀ g) per body (G: MassProperties.G)."""
        gr.Fg = gr.type.mass_properties.G @ np.einsum("kji,j->ik", gr.R, self.g)

    def _frame_start(self, gr: _Group):
        """Start of the step of a framed group (corotational.start): centroids, relative positions, I(r), v̄_i, ω_i,
        gravity in the frames of step i; keeps gr.Ueff = u_i - h ω_i × (u_i - v̄_i)."""
        gr.Ueff = corotational.start(gr, self.h)
        self._frame_gravity(gr)

    def _frame_update(self, gr: _Group, Unew: np.ndarray):
        """End of the step of a framed group (corotational.update, docs/method.md §7): frames turned by
        Δφ = h((1-θ)ω_i + θω_{i+1}), q, u re-based in the new frames."""
        corotational.update(gr, Unew, self.h, self.theta)

    # -------------------------------------------------------------- one step
    def free_velocities(self, t0: float, t1: float):
        """Free velocity of every body (no contact impulse) over [t0, t1]; stores it on the groups. Framed groups
        (co-rotational) add the inertial term of their turning frames, -h M (ω_i × (u_i - v̄_i)) (docs/method.md
        §7)."""
        h, th = self.h, self.theta
        self._narrow()
        for gr, s in zip(self.groups, self.stepped_columns()):
            if self.velocity_reset:
                if s is None:
                    gr.U[:] = 0.0
                else:
                    gr.U[:, s] = 0.0
            bt = gr.type
            if gr.framed:
                self._frame_start(gr)
            F = (1 - th) * self._group_load(gr, t0, s) + th * self._group_load(gr, t1, s)  # (the stepped bodies')
            Q, U = columns(gr.Q, s), columns(gr.U, s)
            KQ = bt.K @ Q
            if gr.framed:
                rhs = bt.M @ gr.Ueff - h * KQ + h * F
            else:
                rhs = (-h * KQ + h * F) if self.static else (bt.M @ U - h * KQ + h * F)
            if th != 1.0:
                rhs -= h * h * th * (1 - th) * (bt.K @ U)
            if bt.C.nnz and th != 1.0 and not self.static:
                rhs -= h * (1 - th) * (bt.C @ U)
            rhs[gr.clamped, :] = 0.0
            uf = gr.op.solve(rhs)
            uf[gr.clamped, :] = 0.0
            if s is None:
                gr.Ufree, gr.Ftheta = uf, F
            else:  # (the other columns: NaN since _narrow)
                gr.Ufree[:, s], gr.Ftheta[:, s] = uf, F
        for i in self.rigid:
            b = self.bodies[i]
            if self.velocity_reset:
                b.u[~b.driven] = 0.0
            b.Ftheta = (1 - th) * b.applied_force(t0, self.g) + th * b.applied_force(t1, self.g)
            uf = b.u + h * self._rigid_accel(b)
            b.drive(uf, t0, t1, h, th)  # drivers (and a pivot's translation velocity: bodies._DrivenDofs)
            b.ufree = uf

    def _rigid_accel(self, b) -> np.ndarray:
        """M^-1 F_theta on the free dofs (2D: diagonal M; 3D: M_ff^-1 (F_theta - (0, ω × I ω))_f), 0 on driven."""
        if self.dim == 2:
            return np.divide(b.Ftheta, b.mass, out=np.zeros(3), where=b.mass > 0)
        F = b.Ftheta.copy()
        w = b.u[3:]
        F[3:] -= np.cross(w, b.inertia @ w)
        return b.W @ F

    def _rigid_mass_times(self, b, v) -> np.ndarray:
        return b.mass * v if self.dim == 2 else b.mass_matrix @ v

    def _rigid_gravity_force(self, b) -> np.ndarray:
        f = np.zeros(self.rigid_ndof)
        f[:self.dim] = (b.mass[0] if self.dim == 2 else b.mass) * self.g
        return f

    def _move_rigid(self, b, dq, t1):
        """q += dq (3D: translation, then the orientation rotated by Δφ = dq[3:]); displacement drivers set q[k]
        (3D rotation dofs: the remaining rotation about axis k is applied)."""
        if self.dim == 2:
            b.q += dq
        else:
            b.q[:3] += dq[:3]
            b.rotate(dq[3:])
        for k, drv in b.drivers.items():
            if drv.kind == "displacement":
                if self.dim == 3 and k >= 3:
                    e = np.zeros(3)
                    e[k - 3] = drv.history(t1) - b.q[k]
                    b.rotate(e)
                b.q[k] = drv.history(t1)
        b.hold_pivot()  # a rotation driver with a pivot: the pivot's material point stays at p

    def step(self) -> StepInfo:
        h, th = self.h, self.theta
        t0, t1 = self.time, self.time + h
        self.free_velocities(t0, t1)
        res = None
        if self.contact is not None:
            res = self.contact.solve(self, t0, t1)  # ContactResult: corrections W H (h r), impulses, ...
        gcorr = res.group_corr if res is not None else [None] * len(self.groups)
        cols, mine, comm = self.own_bodies()
        self._narrow()  # (the first step: the contact step took its set of bodies during this step)
        work, wdrv, winert = [], [], []  # the own bodies' terms (module docstring, "Sums over bodies")
        dmax = 0.0
        for gr, Ucorr, c, s in zip(self.groups, gcorr, cols, self.stepped_columns()):
            # the stepped bodies' columns (s: all, or the rank's B_p; the correction holds the same columns)
            U0, Uf = columns(gr.U, s), columns(gr.Ufree, s)
            Unew = Uf if Ucorr is None else Uf + Ucorr
            dQ = h * ((1 - th) * U0 + th * Unew)
            c = c if s is None or c is None else np.searchsorted(s, c)  # the own bodies among them (own ⊂ B_p)
            dQc = columns(dQ, c)
            dmax = max(dmax, float(np.max(np.abs(dQc), initial=0.0)))
            if not self.static:
                dU = columns(Unew, c) - columns(U0, c)
                winert.append(column_sums(dQc * (gr.type.M @ dU)) / h)
            F, Fg = (columns(A, s) for A in (gr.Ftheta, gr.Fg))
            work.append(column_sums(columns(F, c) * dQc) - column_sums(columns(Fg, c) * dQc))
            if gr.framed:
                self._frame_update(gr, Unew)
            elif s is None:
                gr.Q += dQ
                gr.U[:] = Unew
            else:
                gr.Q[:, s] += dQ
                gr.U[:, s] = Unew
        drv_moves = []
        for k, i in enumerate(self.rigid):
            b = self.bodies[i]
            unew = b.ufree if res is None else b.ufree + res.rigid_corr[k]
            cimp = np.zeros(self.rigid_ndof) if res is None else res.rigid_impulse[k]
            inert = np.zeros(self.rigid_ndof) if self.static else self._rigid_mass_times(b, unew - b.u) / h
            react = inert - b.Ftheta - cimp / h
            b.reaction = np.where(b.driven, react, 0.0)
            dq = h * ((1 - th) * b.u + th * unew)
            size = np.abs(dq) * self._dof_lengths(b)  # translations [m], rotations x radius [m]
            dmax = max(dmax, float(size.max()))
            drv_moves.append((b, np.where(b.driven, dq, 0.0), size))
            if mine[i]:
                gforce = self._rigid_gravity_force(b)
                winert.append([np.dot(dq, inert)])
                work.append([np.dot(np.where(b.driven, 0.0, b.Ftheta - gforce), dq)])
                wdrv.append([np.dot(b.reaction, dq)])
            self._move_rigid(b, dq, t1)
            b.u[:] = unew
        work, wdrv, winert = exact_sums([_joined(x) for x in (work, wdrv, winert)], comm)
        self._attribute_inertia(winert, drv_moves, largest(dmax, comm))
        self.time, self.step_count = t1, self.step_count + 1
        self.external_work += work
        self.driver_work += wdrv
        if res is not None:
            self.last_contact = res
        return self.info(res.stats if res is not None else {})

    def _dof_lengths(self, b) -> np.ndarray:
        """Length per dof of a rigid body that turns a dof increment into a displacement: 1 for translations, the
        largest distance of its vertices from the centre of mass for rotations."""
        pts = b.vertices_rel if self.dim == 2 else b.points_rel
        r = float(np.max(np.linalg.norm(pts, axis=1)))
        return np.r_[np.ones(self.dim), np.full(self.rigid_ndof - self.dim, r)]

    def _attribute_inertia(self, winert: float, drv_moves: list, dmax: float) -> None:
        """body.reaction_inertia = I_k on the driven dofs (module docstring): the inertia work W_I of the step split
        over the moving driven dofs in proportion to |R_k dq_k|, divided by dq_k."""
        self.inertia_work = winert
        moves = [(dq != 0.0) & (size >= MOVE_TOL * dmax) for _, dq, size in drv_moves]
        wts = [np.where(mv, np.abs(b.reaction * dq), 0.0) for (b, dq, _), mv in zip(drv_moves, moves)]
        total = float(sum(w.sum() for w in wts))
        for (b, dq, _), w, mv in zip(drv_moves, wts, moves):
            b.reaction_inertia = np.zeros_like(b.reaction)
            if total > 0.0:
                b.reaction_inertia[mv] = winert * w[mv] / total / dq[mv]

    # -------------------------------------------------------------- checkpoint
    def export_state(self) -> dict:
        """Arrays that determine the rest of the run (with the case): time, counters, work, q, u, reactions."""
        d = {"sim.time": np.float64(self.time), "sim.step": np.int64(self.step_count),
             "sim.external_work": np.float64(self.external_work), "sim.driver_work": np.float64(self.driver_work),
             "sim.h": np.float64(self.h), "sim.theta": np.float64(self.theta)}
        for i, b in enumerate(self.bodies):
            key = f"{_BODY_KEY}{i}."
            d[key + "q"] = np.array(b.q)
            d[key + "u"] = np.array(b.u)
            if b.kind == 0 and b.framed:  # co-rotational frame (and, 2D, its unwrapped angle)
                d[key + "R"] = np.array(b.R)
                d[key + "position"] = np.array(b.position)
                if self.dim == 2:
                    d[key + "phi"] = np.array(b._phi)
            if b.kind == 1:
                d[key + "reaction"] = np.array(b.reaction)
                if self.dim == 3:
                    d[key + "orientation"] = np.array(b.orientation)
        if self.last_contact is not None:
            d.update(self.last_contact.export())
        return d

    def restore_state(self, d: dict) -> None:
        """Inverse of `export_state` (in place: the groups' arrays keep their identity); with a contact step and its
        arrays in `d` (ContactStep.export_state), restores it too and keeps the record it returns as
        `last_contact`."""
        for i, b in enumerate(self.bodies):
            rigid = ("reaction",) + (("orientation",) if self.dim == 3 else ()) if b.kind == 1 else ()
            frame = (("R", "position") + (("_phi",) if self.dim == 2 else ())) if b.kind == 0 and b.framed else ()
            for name in ("q", "u") + rigid + frame:
                key = f"{_BODY_KEY}{i}.{name.lstrip('_')}"
                if key not in d or np.shape(d[key]) != np.shape(getattr(b, name)):
                    raise InputError(f"checkpoint: {key}: missing or of another shape than body {i} of this model "
                                     f"(expected {np.shape(getattr(b, name))})")
                getattr(b, name)[...] = d[key]
        self._narrowed = None  # (the restored state may hold every body: _narrow sets the others to NaN again)
        self.time = float(d["sim.time"])
        self.step_count = int(d["sim.step"])
        self.external_work = float(d["sim.external_work"])
        self.driver_work = float(d["sim.driver_work"])
        if self.contact is not None and "contact.steps" in d:
            self.last_contact = self.contact.restore_state(self, d)

    # -------------------------------------------------------------- the bodies a rank steps
    def share_bodies(self, ids) -> None:
        """Step the bodies `ids` (indices) on every rank, whatever the partition: the bodies the outputs read at every
        step on every rank (module docstring, "Bodies stepped per rank")."""
        self.shared = np.unique(np.asarray(list(ids), dtype=np.int64))
        self._stepped_key = None

    def stepped_columns(self) -> list:
        """Per group the columns of the bodies this process steps (None: every member): on N > 1 ranks with the
        contact step's `stepped_bodies()` (frozen geometry, colour order) those of its mask, the shared bodies
        (`share_bodies`) added; None for a group whose factor does not solve each column alone
        (`linalg.Factor.columnwise`) or with every member in the set. The contact step's corrections take the same
        columns (contact/scene.py)."""
        part = getattr(self.contact, "stepped_bodies", lambda: None)()
        if part is None:
            return [None] * len(self.groups)
        key = self._stepped_key  # (the contact step's mask itself, held: a new mask is a new set)
        if key is None or key[0] is not part or key[1] != self.shared.tobytes():
            key = (part, self.shared.tobytes())
            mask = part.copy()
            mask[self.shared] = True
            out = []
            for gr in self.groups:
                s = np.flatnonzero(mask[gr.members])
                out.append(None if gr.framed or not gr.op.factor.columnwise or s.size == len(gr.members) else s)
            self._stepped_key, self._stepped = key, out
        return self._stepped

    def _narrow(self) -> None:
        """Set q, u, the free velocities and loads of the bodies this process does not step to NaN, once per stepped
        set (again after a restore or a new set of groups; module docstring)."""
        cols = self.stepped_columns()
        key = self._stepped_key
        if key is None or key is self._narrowed:
            return
        for gr, s in zip(self.groups, cols):
            if s is None:
                continue
            off = np.setdiff1d(np.arange(len(gr.members)), s, assume_unique=True)
            for name in ("Ufree", "Ftheta"):  # (set by free_velocities: of every member before the first narrowing)
                if getattr(gr, name, None) is None or getattr(gr, name).shape != gr.U.shape:
                    setattr(gr, name, np.zeros_like(gr.U))
            for A in (gr.Q, gr.U, gr.Ufree, gr.Ftheta):
                A[:, off] = np.nan
        self._narrowed = key

    def collect_bodies(self) -> None:
        """On N > 1 ranks with the bodies stepped per rank: rank 0 receives q and u of every body from the rank that
        owns it (one gather; collective), so that it holds the whole state (the figures at the end of a run); else
        nothing to do."""
        part = getattr(self.contact, "stepped_bodies", lambda: None)()
        cols, mine, comm = self.own_bodies()
        if part is None or comm is None:
            return
        sent = [(g, c, columns(gr.Q, c), columns(gr.U, c))  # (the own columns of the groups stepped per rank)
                for g, (gr, c, s) in enumerate(zip(self.groups, cols, self.stepped_columns())) if s is not None]
        got = comm.gather(sent, root=0)
        for rank_part in got or []:
            for g, c, Q, U in rank_part:
                self.groups[g].Q[:, c] = Q
                self.groups[g].U[:, c] = U

    # -------------------------------------------------------------- diagnostics
    def own_bodies(self):
        """The bodies this process reads in the sums over bodies (module docstring), the maxima of `step` and
        `max_velocity` and the runner's per-step checks of the bodies: (per group the columns of its members
        (None: all), the mask (nb,) of those bodies, the communicator that combines every rank's part). On N > 1
        ranks with the bodies partitioned (the contact step's `body_partition()`), this rank's bodies and the
        ranks' communicator; else every body and None."""
        part = getattr(self.contact, "body_partition", lambda: None)()
        if part is None:
            return [None] * len(self.groups), np.ones(len(self.bodies), dtype=bool), None
        comm, mine = part
        return [np.flatnonzero(mine[gr.members]) for gr in self.groups], mine, comm

    def energies(self):
        """(kinetic, elastic, gravity potential) = (1/2 u.Mu, 1/2 q.Kq, -F_g.q) summed over bodies, each an exact
        sum of per-body terms (module docstring, "Sums over bodies"; collective on N > 1 ranks with the bodies
        partitioned); kinetic = 0 in a static step (the model has no inertia; u = dq/h is a pseudo-velocity)."""
        cols, mine, comm = self.own_bodies()
        kin, ela, pot = [], [], []
        for gr, c in zip(self.groups, cols):
            U, Q = columns(gr.U, c), columns(gr.Q, c)
            if not self.static:
                kin.append(0.5 * column_sums(U * (gr.type.M @ U)))
            ela.append(0.5 * column_sums(Q * (gr.type.K @ Q)))
            if gr.framed:  # -Σ m_a g·(x_a - x_a,ref), global: -g·(R Σ m (X + q) + m p - R0 Σ m X - m p0)
                mp = gr.type.mass_properties
                n, dd = mp.r0.shape
                X = gr.type.mesh.points
                sY = np.stack([column_sums(mp.m[:, None] * (X[:, i, None] + Q[i::dd])) for i in range(dd)], axis=1)
                sX = mp.mass * mp.Xbar
                R, R0, pos, pos0 = (A if c is None else A[c] for A in (gr.R, gr.R0, gr.pos, gr.pos0))
                dx = _dot_last(R, sY[:, None, :]) + mp.mass * pos - _dot_last(R0, sX) - mp.mass * pos0
                pot.append(-_dot_last(dx, self.g))
            else:
                pot.append(-column_sums(columns(gr.Fg, c) * Q))
        for i in self.rigid:
            if mine[i]:
                b = self.bodies[i]
                if not self.static:
                    kin.append([0.5 * np.dot(b.u, self._rigid_mass_times(b, b.u))])
                pot.append([-np.dot(self._rigid_gravity_force(b), b.q)])
        return tuple(exact_sums([_joined(x) for x in (kin, ela, pot)], comm))

    def rotations(self) -> np.ndarray:
        """Rotation of every body since its placement, batched per group (`body.rotation()` of each deformable body,
        up to rounding; the best-fit small rotation of q by BlockType.rotation_weights, one product per group; 3D
        framed bodies call body.rotation(), one log map each): 2D (nb,) angles [rad] (framed: unwrapped frame angle +
        the best-fit small rotation of q; rigid: q[2]); 3D (nb, 3) rotation vectors (deformable: of R exp([θ_q]x) R0ᵀ;
        rigid: of the orientation)."""
        from .bodies import rotation_vector
        d = self.dim
        out = np.zeros(len(self.bodies)) if d == 2 else np.zeros((len(self.bodies), 3))
        for gr in self.groups:
            th = np.einsum("kd,dn->nk", gr.type.rotation_weights(), gr.Q)  # best-fit small rotation of q, per body
            if d == 2:
                out[gr.members] = th[:, 0] + (gr.phi if gr.framed else 0.0)
            else:
                for j, b in enumerate(gr.members):
                    out[b] = self.bodies[b].rotation() if gr.framed else self.bodies[b].R0 @ th[j]
        for i in self.rigid:
            b = self.bodies[i]
            out[i] = b.q[2] if d == 2 else rotation_vector(b.orientation)
        return out

    def max_velocity(self) -> float:
        """The largest speed [m/s] of a node of a deformable body and of a rigid body's centre (rigid bodies with a
        free translation dof): over the own bodies (`own_bodies`), and on N > 1 ranks with the bodies partitioned the
        largest of the ranks' (`exact.largest`: one Allgather, NaN if any rank's is NaN; a maximum is exact, so one
        process's value)."""
        cols, mine, comm = self.own_bodies()
        vals, d = [0.0], self.dim
        for gr, c in zip(self.groups, cols):
            U = columns(gr.U, c)
            if U.size:
                vals.append(float(np.max(np.linalg.norm(U.reshape(-1, d, U.shape[1]), axis=1))))
        for i in self.rigid:
            b = self.bodies[i]
            if mine[i] and not b.driven[:d].all():
                vals.append(float(np.linalg.norm(b.u[:d])))
        return largest(float(np.max(vals)), comm)  # (np.max: a NaN velocity stays NaN; Python's max drops it)

    def info(self, cinfo=None) -> StepInfo:
        kin, ela, pot = self.energies()
        return StepInfo(self.step_count, self.time, kin, ela, pot, self.external_work,
                        self.max_velocity(), cinfo or {})
