"""ParaView output of the contact points: a vertex cloud per frame in `contacts.pvd`.

Point data: reaction (force of the antagonist on the candidate, global frame, N), r_N, r_T (local, N),
normal, gap (joint-corrected gap g - g0 at the end of the step, m), status (0 open, 1 stick, 2 slip),
interface (interface/law id), area (tributary area, m²), and the interface-law state: law (code), damage
(1 - β for Frémond–Cangémi, 1 - intact for brittle laws, D for the mixed-mode law, 0 for elastic and dry
joints), opening u_N and slip u_T (jumps since the reference state, m), dissipated (J). One writer for 2D and 3D
(`ContactsWriter(directory, dim)`, `.write(time, result)` with a contact.result.ContactResult); 3D adds the
second tangent s and r_local. With `joints` (output.joints.JointsWriter, `[output] joints_paraview`) each frame
also writes the joint resultants to `joints.pvd`. On N > 1 MPI ranks (`comm`) each rank writes the piece of its
record's rows (its own contacts: ContactResult.rows) and rank 0 the .pvtu of each frame (output/pvd.py)."""
from __future__ import annotations

import numpy as np

from .pvd import SeriesWriter


def law_state_fields(law: np.ndarray, state: np.ndarray) -> dict:
    """Point fields of the interface-law state (laws.py columns), the same in 2D and 3D: law (code), damage
    (1 - β for Frémond–Cangémi and brittle laws, D for the mixed-mode law, 0 for elastic and dry joints),
    opening u_N, slip (u_T in 2D; its norm ‖(u_T, u_S)‖ in 3D, state rows of NSTATE3 columns), dissipated
    energy, crushing (plastic normal jump)."""
    from ..laws import MIXED, NSTATE3, S_BETA, S_DISS, S_UN, S_UP, S_US, S_UT
    law = np.asarray(law)
    damage = np.where(law == MIXED, state[:, S_BETA], np.where(law >= 2, 1.0 - state[:, S_BETA], 0.0))
    slip = np.hypot(state[:, S_UT], state[:, S_US]) if state.shape[1] == NSTATE3 else state[:, S_UT].copy()
    return dict(law=law.astype(np.int64), damage=damage, opening=state[:, S_UN].copy(),
                slip=slip, dissipated=state[:, S_DISS].copy(), crushing=state[:, S_UP].copy())


class ContactsWriter(SeriesWriter):
    """Contact points of a dimension-`dim` run as a vertex cloud per frame in `<basename>.pvd`.

    `write(time, result)` writes one frame of a contact.result.ContactResult (an empty frame for None or a record
    without contacts). Points: `locate(cs)` (nc, dim), e.g. ContactStep.contact_points (2D: the candidate points
    in the current configuration); by default the candidate points cs.point of the contact set. Point data
    (arrays): 2D reaction = r_N n + r_T t, r_N, r_T; 3D reaction = r_N n + r_t t + r_s s, r_local (r_N, r_t, r_s),
    r_N, r_T = |(r_t, r_s)|, t, s; both: normal, gap (result.gt_end; cs.gap - cs.g0 when the record has none),
    status (-1 when the record has none), interface, area and, with a law state, law_state_fields."""

    def __init__(self, directory: str, dim: int, locate=None, append: bool = False, basename: str = "contacts",
                 keep_until_time: float | None = None, joints=None, comm=None):
        if dim not in (2, 3):
            from ..errors import InputError
            raise InputError(f"ContactsWriter: dim = {dim!r}: expected 2 or 3")
        self.dim, self.locate = dim, locate
        self.joints = joints  # output.joints.JointsWriter or None: the joint resultants, a frame with each frame
        super().__init__(directory, basename, append, keep_until_time, comm=comm)

    def arrays(self, result):
        """(points (nc, dim), point data) of the rows of `result` (every contact's, or a rank's: `result.rows`);
        (empty, {}) without contacts."""
        d = self.dim
        rows = None if result is None else result.rows
        if result is None or result.r is None or len(result.r) == 0 or \
                len(result.r) != (result.n_contacts if rows is None else len(rows)):
            return np.zeros((0, d)), {}
        cs = result.cs if rows is None else result.cs.subset(rows)
        nc = len(cs.gap)
        x = np.asarray(cs.point if self.locate is None else self.locate(cs), dtype=float).reshape(nc, d)
        r = np.asarray(result.r, dtype=float).reshape(nc, d)
        gap = cs.gap - cs.g0 if result.gt_end is None else result.gt_end
        status = np.full(nc, -1) if result.status is None else result.status
        if d == 2:
            data = {"reaction": r[:, :1] * cs.n + r[:, 1:] * cs.t, "r_N": r[:, 0].copy(), "r_T": r[:, 1].copy()}
        else:
            data = {"reaction": r[:, :1] * cs.n + r[:, 1:2] * cs.t + r[:, 2:] * cs.s, "r_local": r.copy(),
                    "r_N": r[:, 0].copy(), "r_T": np.hypot(r[:, 1], r[:, 2])}
        data["normal"] = cs.n.copy()
        if d == 3:
            data.update(t=cs.t.copy(), s=cs.s.copy())
        data.update(gap=np.asarray(gap, dtype=float).reshape(nc),
                    status=np.asarray(status).astype(np.int64), interface=np.asarray(cs.interface).astype(np.int64),
                    area=np.asarray(cs.area, float).copy())
        if result.state is not None and len(result.state) == nc:
            law = np.zeros(nc, np.int64) if result.law is None else result.law
            data.update(law_state_fields(law, np.asarray(result.state)))
        return x, data

    def write(self, time: float, result) -> str:
        """One frame of `result` (N ranks: every rank, each its record's rows; a rank without contacts writes no
        piece). The joints (`joints`, one process) take the record of every contact."""
        x, data = self.arrays(result)
        if self.joints is not None:
            self.joints.write(time, result)
        if self.comm is None:
            return self.write_frame(time, x, [("vertex", np.arange(len(x)))], point_data=data)
        from mpi4py import MPI
        anyone = self.comm.allreduce(len(x), op=MPI.MAX) > 0
        if len(x) or (not anyone and self.comm.Get_rank() == 0):  # (a frame without contacts: rank 0's empty piece)
            return self.write_frame(time, x, [("vertex", np.arange(len(x)))], point_data=data)
        return self.write_frame(time, None, None)
