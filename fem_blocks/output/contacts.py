"""ParaView output of the contact points: a vertex cloud per frame in `contacts.pvd`.

Point data: reaction (force of the antagonist on the candidate, global frame, N), r_N, r_T (local, N),
normal, gap (joint-corrected gap g - g0 at the end of the step, m), status (0 open, 1 stick, 2 slip),
interface (interface/law id), area (tributary area, m²), and the interface-law state: law (code), damage
(1 - β for Frémond–Cangémi, 1 - intact for brittle laws, D for the mixed-mode law, 0 for elastic and dry
joints), opening u_N and slip u_T (jumps since the reference state, m), dissipated (J).
`ContactsWriter3D`: the same for 3D contact sets (local frame (n, t, s))."""
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
    def __init__(self, contact, directory: str, append: bool = False, basename: str = "contacts",
                 keep_until_time: float | None = None):
        self.contact = contact
        super().__init__(directory, basename, append, keep_until_time)

    def arrays(self):
        c = self.contact
        cs = getattr(c, "cs", None)
        if cs is None or len(cs.gap) == 0 or getattr(c, "r", None) is None or len(c.r) != len(cs.gap):
            return np.zeros((0, 2)), {}
        s = c.scene
        bx = s.positions()
        b = cs.cand_body
        idx = s.bx_start[b][:, None] + s.bnode_index_flat[s.bnode_offset[b][:, None] + cs.cand_nodes]
        x = cs.cand_w[:, :1] * bx[idx[:, 0]] + cs.cand_w[:, 1:] * bx[idx[:, 1]]
        r = c.r
        data = {"reaction": r[:, :1] * cs.n + r[:, 1:] * cs.t, "r_N": r[:, 0].copy(), "r_T": r[:, 1].copy(),
                "normal": cs.n.copy(), "gap": np.asarray(c.gt_end, dtype=float),
                "status": np.asarray(c.status, dtype=np.int64), "interface": cs.interface.astype(np.int64),
                "area": cs.area.copy()}
        st = getattr(c, "state", None)
        if st is not None and len(st) == len(cs.gap):
            data.update(law_state_fields(c.law, st))
        return x, data

    def write(self, time: float) -> str:
        x, data = self.arrays()
        return self.write_frame(time, x, [("vertex", np.arange(len(x)))], point_data=data)


class ContactsWriter3D(SeriesWriter):
    """3D contact points (detection_3d.ContactSet) as a vertex cloud per frame in `contacts.pvd`.

    Point data: reaction = r_N n + r_t t + r_s s (force of the antagonist on the candidate, global frame, N),
    r_local (r_N, r_t, r_s), r_N, r_T = |(r_t, r_s)|, normal n, t, s, gap (joint-corrected gap, default
    cs.gap - cs.g0, m), status (0 open, 1 stick, 2 slip; -1 when not given), interface, area (m²), and with a
    law state the fields of `law_state_fields`. Points: the candidate points cs.point.

    With `contact` (a 3D contact.step.ContactStep), `write(time)` takes everything from it (as the 2D
    ContactsWriter: its contact set, impulses/reactions r, law codes, states, status and end-of-step gaps)."""

    def __init__(self, directory: str, append: bool = False, basename: str = "contacts",
                 keep_until_time: float | None = None, contact=None):
        self.contact = contact
        super().__init__(directory, basename, append, keep_until_time)

    @staticmethod
    def arrays(cs, r, law=None, state=None, status=None, gap=None):
        nc = len(cs.gap)
        r = np.asarray(r, dtype=float).reshape(nc, 3)
        data = {"reaction": r[:, :1] * cs.n + r[:, 1:2] * cs.t + r[:, 2:] * cs.s, "r_local": r.copy(),
                "r_N": r[:, 0].copy(), "r_T": np.hypot(r[:, 1], r[:, 2]), "normal": cs.n.copy(),
                "t": cs.t.copy(), "s": cs.s.copy(),
                "gap": np.asarray(cs.gap - cs.g0 if gap is None else gap, dtype=float).reshape(nc),
                "status": (np.full(nc, -1) if status is None else np.asarray(status)).astype(np.int64),
                "interface": np.asarray(cs.interface).astype(np.int64), "area": np.asarray(cs.area, float).copy()}
        if state is not None:
            data.update(law_state_fields(np.zeros(nc, np.int64) if law is None else law, np.asarray(state)))
        return np.asarray(cs.point, dtype=float).reshape(nc, 3), data

    def write(self, time: float, cs=None, r=None, law=None, state=None, status=None, gap=None) -> str:
        """One frame: contact set `cs`, local reactions r (nc, 3) = (r_N, r_t, r_s) [N], optional law codes
        and states (nc, laws.NSTATE), status (nc,), gap (nc,); without cs, the current state of `contact`."""
        if cs is None:
            c = self.contact
            cs = getattr(c, "cs", None)
            r = getattr(c, "r", None)
            if cs is None or r is None or len(cs.gap) == 0 or len(r) != len(cs.gap):
                return self.write_frame(time, np.zeros((0, 3)), [("vertex", np.arange(0))], point_data={})
            gt = getattr(c, "gt_end", None)
            st = getattr(c, "state", None)
            law, state = c.law, (st if st is not None and len(st) == len(cs.gap) else None)
            status = getattr(c, "status", None)
            gap = np.asarray(gt, dtype=float) if gt is not None and len(gt) == len(cs.gap) else None
        x, data = self.arrays(cs, r, law, state, status, gap)
        return self.write_frame(time, x, [("vertex", np.arange(len(x)))], point_data=data)
