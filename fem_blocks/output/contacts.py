"""ParaView output of the contact points: a vertex cloud per frame in `contacts.pvd`.

Point data: reaction (force of the antagonist on the candidate, global frame, N), r_N, r_T (local, N),
normal, gap (joint-corrected gap g - g0 at the end of the step, m), status (0 open, 1 stick, 2 slip),
interface (interface/law id), area (tributary area, m²), and the interface-law state: law (code), damage
(1 - β for Frémond–Cangémi, 1 - intact for brittle laws, D for the mixed-mode law, 0 for elastic and dry
joints), opening u_N and slip u_T (jumps since the reference state, m), dissipated (J)."""
from __future__ import annotations

import os

import numpy as np

from .pvd import PvdSeries
from .vtu import write_vtu


class ContactsWriter:
    def __init__(self, contact, directory: str, append: bool = False, basename: str = "contacts",
                 keep_until_time: float | None = None):
        self.contact, self.dir, self.base = contact, directory, basename
        os.makedirs(directory, exist_ok=True)
        pvd = os.path.join(directory, f"{basename}.pvd")
        self.series = PvdSeries.open_existing(pvd, keep_until_time) if append and os.path.exists(pvd) \
            else PvdSeries(pvd)
        self.frame = len(self.series.entries)

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
            from ..laws import MIXED, S_BETA, S_DISS, S_UN, S_UP, S_UT
            law = c.law
            damage = np.where(law == MIXED, st[:, S_BETA], np.where(law >= 2, 1.0 - st[:, S_BETA], 0.0))
            data.update(law=law.astype(np.int64), damage=damage, opening=st[:, S_UN].copy(),
                        slip=st[:, S_UT].copy(), dissipated=st[:, S_DISS].copy(), crushing=st[:, S_UP].copy())
        return x, data

    def write(self, time: float) -> str:
        x, data = self.arrays()
        name = f"{self.base}_{self.frame:06d}.vtu"
        write_vtu(os.path.join(self.dir, name), x, [("vertex", np.arange(len(x)))], point_data=data or None)
        self.series.add(time, name)
        self.frame += 1
        return name
