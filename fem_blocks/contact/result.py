"""The record of one contact step: what `ContactStep.solve` produces and every other module reads.

Data flow of a time step (docs/architecture.md "One step"): `Simulation.step` computes the free velocities,
`ContactStep.solve(sim, t0, t1)` returns a `ContactResult`, the simulation applies its velocity corrections

    u_{i+1} = u_free + W H P          (per body group: `group_corr`; per rigid body: `rigid_corr`)

and keeps it as `sim.last_contact`; writers, run checks and figures read `sim.last_contact`. The record owns its
arrays (copies: the contact step mutates its warm start and law state in place at the next step); `cs` is the
contact set the step was solved on, shared with the step but never modified after its detection.

Per contact (nc rows, local frame (n, t) in 2D, (n, t, s) in 3D, docs/method.md §3–§5):
P impulses (nc, d) [N s], r = P / h reactions [N], v the shifted local velocity at the end of the step
(normal v_N + gs / (h theta), contact/step.py), gt_end = gbar + h theta v_N the joint-corrected gap g - g0 at the
end of the step [m],
status 0 open / 1 stick / 2 slip, law codes and the committed law state (laws.py columns), the step's frictional
dissipation per contact `friction` = -r̃_T · Δu_T [J] and its running total `friction_total` (contact/friction.py);
`dissipated` the law states' dissipated energy Σ_α S_DISS [J] (decohesion and crushing) over every contact.

Rows: on N > 1 MPI ranks in colour order (contact/step.py ContactStep._own_rows) a rank's record holds the rows of
its own contacts only (`rows`: their numbers in the contact set `cs`, which is the rank's part of the whole set);
`whole()` gathers every contact's rows and contact set rows, in the whole set's order (collective: every rank calls
it together). The statistics, `friction_total` and `dissipated` are of every contact on every rank.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

OUT_FIELDS = ("gt_end", "v", "r", "status")  # checkpointed under "contact.out.<name>" (the last step's outputs)
OUT_PREFIX = "contact.out."  # the prefix of those checkpoint entries


@dataclass
class ContactResult:
    dim: int
    stats: dict                 # contacts, active, slip, sweeps, change, residual, converged, solver, message
    cs: object = None           # ContactSet (detection_2d / detection_3d) solved on (None: no contact detected yet)
    P: np.ndarray = None        # (nc, d) impulses
    r: np.ndarray = None        # (nc, d) reactions P / h
    v: np.ndarray = None        # (nc, d) shifted local velocities at the end of the step
    gt_end: np.ndarray = None   # (nc,) g - g0 at the end of the step
    status: np.ndarray = None   # (nc,) 0 open, 1 stick, 2 slip
    law: np.ndarray = None      # (nc,) law codes
    state: np.ndarray = None    # (nc, NSTATE | NSTATE + 1) committed law state
    # per Simulation group: the (ndof, k) correction of its stepped columns (Simulation.stepped_columns), or None
    group_corr: list = field(default_factory=list)
    rigid_corr: np.ndarray = None     # (n_rigid, rigid ndof) velocity correction W p, in sim.rigid order
    rigid_impulse: np.ndarray = None  # (n_rigid, rigid ndof) contact impulse p on each rigid body
    friction: np.ndarray = None       # (nc,) frictional dissipation of this step per contact [J] (contact/friction.py)
    friction_total: float = 0.0       # frictional dissipation of every step of the contact step so far [J]
    dissipated: float = 0.0           # Σ over every contact of the law state's S_DISS [J] (decohesion, crushing)
    rows: np.ndarray = None           # None: the rows of every contact; else the contacts (numbers in cs) held here
    gather: object = None             # rows given: gather(x) -> every contact's rows of x (collective; Allgatherv)

    @property
    def n_contacts(self) -> int:
        return 0 if self.cs is None else len(self.cs.gap)

    def has_contacts(self) -> bool:
        """True when the record holds per-contact arrays for a non-empty contact set."""
        return self.n_contacts > 0 and self.r is not None and len(self.r) == self.n_contacts

    def whole(self) -> "ContactResult":
        """The record with the rows of every contact: itself when it holds them; else (a rank's rows, N > 1 ranks)
        the per-contact arrays and the contact set's rows of the held contacts gathered (two gathers: the integer
        and the floating-point arrays, distributed/sweep.gather_fields), in the whole set's order. COLLECTIVE in
        that case: every rank calls it together."""
        if self.rows is None:
            return self
        from ..distributed.sweep import gather_fields
        names = [k for k in ("P", "r", "v", "gt_end", "status", "law", "state", "friction")
                 if getattr(self, k) is not None]
        part = self.cs.subset(self.rows)
        fields = {f"cs.{k}": v for k, v in part.__dict__.items()}
        fields.update({k: getattr(self, k) for k in names})
        every = gather_fields(self.gather, fields)
        cs = type(part)(**{k: every[f"cs.{k}"] for k in part.__dict__})
        return replace(self, cs=cs, rows=None, gather=None, **{k: every[k] for k in names})

    def export(self) -> dict:
        """The per-contact outputs for a checkpoint ("contact.out.<name>"; a rank's rows on N > 1 ranks: its piece)."""
        return {OUT_PREFIX + k: getattr(self, k) for k in OUT_FIELDS if getattr(self, k) is not None}
