"""Run a case: build the model, integrate the load stages, write outputs as the run goes.

Outputs in DIR: `paraview/blocks.pvd` (+ one .vtu per frame), `history.csv` (one row per step:
time, step, stage, energies, rigid displacements and driver reactions), `summary.json`.
"""
from __future__ import annotations

import os
import sys
import time as _time

import numpy as np

from . import __version__
from .case import Case
from .dynamics import Simulation
from .model import Model, build_model
from .output.history import HistoryWriter
from .output.checkpoint import write_checkpoint
from .output.contacts import ContactsWriter
from .output.paraview import BodiesWriter
from .output.summary import write_summary

DOFS = ("x", "y", "rz")


class Progress:
    """One status line (stage, step, time, energy, force) on stderr; periodic lines when not a tty."""

    def __init__(self, enabled: bool = True, stream=None):
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.tty = self.stream.isatty()
        self.last = 0.0

    def update(self, text: str, force: bool = False):
        if not self.enabled:
            return
        now = _time.monotonic()
        if not force and now - self.last < (0.2 if self.tty else 5.0):
            return
        self.last = now
        if self.tty:
            self.stream.write("\r" + text[:150].ljust(150))
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def close(self):
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()


def history_columns(model: Model) -> list[str]:
    cols = ["step", "time", "stage", "kinetic", "elastic", "gravity_potential", "external_work",
            "total_energy", "max_velocity"]
    for i, b in enumerate(model.bodies):
        if b.kind == 1:
            name = model.names[i]
            cols += [f"{name}.u{d}" for d in DOFS]
            cols += [f"{name}.R{DOFS[k]}" for k in sorted(b.drivers)]
    if model.contact is not None:
        cols += ["contacts", "closed", "slip", "sweeps", "change", "residual", "converged"]
    return cols


def history_row(model: Model, info, stage_index: int) -> dict:
    row = dict(step=info.step, time=info.time, stage=stage_index, kinetic=info.kinetic, elastic=info.elastic,
               gravity_potential=info.gravity_potential, external_work=info.external_work,
               total_energy=info.total_energy, max_velocity=info.max_velocity)
    for i, b in enumerate(model.bodies):
        if b.kind == 1:
            name = model.names[i]
            for k, d in enumerate(DOFS):
                row[f"{name}.u{d}"] = b.q[k]
            for k in sorted(b.drivers):
                row[f"{name}.R{DOFS[k]}"] = b.reaction[k]
    if model.contact is not None:
        c = info.contact or {}
        row.update(contacts=c.get("contacts", 0), closed=c.get("active", 0), slip=c.get("slip", 0),
                   sweeps=c.get("sweeps", 0), change=c.get("change", 0.0), residual=c.get("residual", 0.0),
                   converged=int(c.get("converged", True)))
    return row


def run_case(case: Case, out_dir: str, progress: bool = True) -> dict:
    """Run every stage of `case`, writing outputs in `out_dir`; returns the summary dict."""
    t_start = _time.perf_counter()
    os.makedirs(out_dir, exist_ok=True)
    model = build_model(case)
    t_setup = _time.perf_counter() - t_start
    st0 = case.stages[0]
    sim = Simulation(model.bodies, h=st0.h, theta=st0.theta, gravity=model.gravity,
                     velocity_reset=st0.velocity_reset, contact=model.contact)
    pv = BodiesWriter(sim, os.path.join(out_dir, "paraview"), stress=case.output["stress"]) \
        if case.output["paraview"] else None
    pc = ContactsWriter(model.contact, os.path.join(out_dir, "paraview")) \
        if case.output["paraview"] and model.contact is not None else None
    ckpt_every = case.output.get("checkpoint_every", 0)
    cstats = dict(steps=0, sweeps=0, max_sweeps=0, unconverged=0, max_residual=0.0, max_change=0.0)
    hist = HistoryWriter(os.path.join(out_dir, "history.csv"), history_columns(model), flush_every=50)
    bar = Progress(progress)
    info = sim.info()
    hist.write(history_row(model, info, 0))
    if pv:
        pv.write(sim.time)
    if pc:
        pc.write(sim.time)
    n_frames = 1
    e0 = info.total_energy
    stages_done = []
    try:
        for si, st in enumerate(case.stages):
            sim.set_step(st.h, st.theta)
            sim.velocity_reset = st.velocity_reset
            n_steps = max(1, int(round(st.duration / st.h)))
            t_stage = _time.perf_counter()
            unconv0 = cstats["unconverged"]
            stopped = None
            for k in range(1, n_steps + 1):
                info = sim.step()
                hist.write(history_row(model, info, si))
                c = info.contact
                if c:
                    cstats["steps"] += 1
                    cstats["sweeps"] += c["sweeps"]
                    cstats["max_sweeps"] = max(cstats["max_sweeps"], c["sweeps"])
                    cstats["unconverged"] += 0 if c["converged"] else 1
                    cstats["max_residual"] = max(cstats["max_residual"], c["residual"])
                    cstats["max_change"] = max(cstats["max_change"], c["change"])
                if not np.isfinite(info.total_energy):
                    raise FloatingPointError(f"stage {st.name!r}, step {k}: the state became NaN/Inf")
                at_eq = (st.stop_at_equilibrium and k >= st.min_steps
                         and info.max_velocity <= st.equilibrium_velocity)
                last = k == n_steps or at_eq
                if pv and (k % st.output_every == 0 or last):
                    pv.write(sim.time)
                    if pc:
                        pc.write(sim.time)
                    n_frames += 1
                extra = f" sweeps {c['sweeps']}" if c else ""
                bar.update(f"[{si + 1}/{len(case.stages)} {st.name}] step {k}/{n_steps} t = {sim.time:.6g} s "
                           f"E = {info.total_energy:.6g} J vmax = {info.max_velocity:.3g} m/s{extra}", force=last)
                if ckpt_every and (sim.step_count % ckpt_every == 0 or last):
                    write_checkpoint(os.path.join(out_dir, "checkpoint.npz"), sim, si)
                if at_eq:
                    stopped = f"equilibrium (max velocity {info.max_velocity:.3g} m/s) after {k} steps"
                    break
            n_unconv = cstats["unconverged"] - unconv0
            if n_unconv:
                print(f"fem-blocks: warning: stage {st.name!r}: {n_unconv} of {k} steps reached the NLGS sweep "
                      f"limit without converging (see the 'converged' column of history.csv)", file=sys.stderr)
            stages_done.append(dict(name=st.name, steps=k, h=st.h, theta=st.theta, stopped=stopped or "duration",
                                    unconverged_steps=n_unconv, wall_time=_time.perf_counter() - t_stage))
    finally:
        hist.close()
        bar.close()
    summary = dict(case=os.path.abspath(case.source), name=case.name, fem_blocks=__version__,
                   n_bodies=len(model.bodies),
                   n_deformable=sum(b.kind == 0 for b in model.bodies),
                   n_rigid=sum(b.kind == 1 for b in model.bodies),
                   n_block_types=len(model.block_types),
                   n_dofs=int(sum(bt.ndof * sum(1 for b in model.bodies if b.kind == 0 and b.type is bt)
                                  for bt in model.block_types.values())),
                   stages=stages_done, final_time=sim.time, steps=sim.step_count,
                   final_energy=dict(kinetic=info.kinetic, elastic=info.elastic,
                                     gravity_potential=info.gravity_potential, total=info.total_energy,
                                     initial_total=e0, external_work=info.external_work),
                   frames=n_frames, setup_time=t_setup, contact=cstats if model.contact is not None else None, wall_time=_time.perf_counter() - t_start,
                   outputs=dict(paraview=os.path.join("paraview", "blocks.pvd") if pv else None,
                                contacts=os.path.join("paraview", "contacts.pvd") if pc else None,
                                history="history.csv"))
    write_summary(os.path.join(out_dir, "summary.json"), summary)
    return summary
