"""Checkpoints: the full state of a run in one .npz, written atomically (temporary file, fsync, rename).

Contents: time, step, stage index, the displacements and velocities of every deformable block (type frame)
and rigid body, driver reactions, and for the contact layer the contact keys, impulses (warm start) and
every law's internal variables (β / damage, jumps u_N, u_T, dissipated energy). `read_checkpoint` returns
the arrays; resuming a run from them belongs to the runner.
"""
from __future__ import annotations

import io
import os

import numpy as np

from .atomic import atomic_write_bytes


def state_arrays(sim, stage: int = 0, case_hash: str = "") -> dict:
    out = {"time": np.float64(sim.time), "step": np.int64(sim.step_count), "stage": np.int64(stage),
           "case_hash": np.array(case_hash)}
    for i, b in enumerate(sim.bodies):
        out[f"body{i}_q"] = np.array(b.q)
        out[f"body{i}_u"] = np.array(b.u)
        if b.kind == 1:
            out[f"body{i}_reaction"] = np.array(b.reaction)
    c = sim.contact
    if c is not None and getattr(c, "cs", None) is not None:
        out["contact_key"] = c.cs.key
        out["contact_ant_body"] = c.cs.ant_body
        out["contact_P"] = c.P
        out["contact_state"] = c.state
        out["contact_law"] = c.law
    return out


def write_checkpoint(path: str, sim, stage: int = 0, case_hash: str = "") -> None:
    buf = io.BytesIO()
    np.savez(buf, **state_arrays(sim, stage, case_hash))
    atomic_write_bytes(path, buf.getvalue())


def read_checkpoint(path: str) -> dict:
    with np.load(os.fspath(path), allow_pickle=False) as z:
        return {k: z[k] for k in z.files}
