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
from .bodies import Driver
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
            cols += [f"{name}.R{d}" for d in DOFS]  # 0 on free dofs; stages may drive or free dofs
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
            for k, d in enumerate(DOFS):
                row[f"{name}.R{d}"] = b.reaction[k]
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
    cv = case.output.get("curve")
    curve_body = model.bodies[model.index(cv["body"])] if cv else None
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
            changed = False
            for bname, dofs in st.drivers.items():
                b = model.bodies[model.index(bname)]
                for dof, spec in dofs.items():
                    b.set_driver(dof, None if spec is None else Driver(*spec, name=f"stages[{si}].drivers.{bname}"))
                    changed = True
            for bname, dofs in st.forces.items():
                b = model.bodies[model.index(bname)]
                for dof, force_hist in dofs.items():
                    b.set_force(dof, force_hist)
                    changed = True
            if changed and model.contact is not None:
                model.contact.W_dirty = True  # rigid W (driven dofs) changed
            sim.set_step(st.h, st.theta)
            sim.velocity_reset = st.velocity_reset
            if model.contact is not None:
                o = model.contact.opts
                o.tol = st.tol if st.tol is not None else case.contact.get("tol", o.tol)
                o.max_sweeps = st.max_sweeps if st.max_sweeps is not None else case.contact.get("max_sweeps",
                                                                                              o.max_sweeps)
            stop_body = {}
            for key, ref in (("disp", st.stop_displacement), ("peak", st.stop_after_peak)):
                if ref is not None:
                    stop_body[key] = (model.bodies[model.index(ref[0])], DOFS.index(ref[1])) + tuple(ref[2:])
            peak_force = 0.0
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
                reason = None
                if "disp" in stop_body:
                    b, d, val = stop_body["disp"]
                    if abs(b.q[d]) >= val * (1 - 1e-12):
                        reason = f"target displacement {val:g} reached after {k} steps"
                if "peak" in stop_body:
                    b, d, drop, min_steps = stop_body["peak"]
                    f = abs(b.reaction[d])
                    peak_force = max(peak_force, f)
                    if k >= min_steps and peak_force > 0 and f < (1 - drop) * peak_force:
                        reason = f"force dropped by {drop:.0%} after its peak {peak_force:.6g} N ({k} steps)"
                last = k == n_steps or at_eq or reason is not None
                if pv and (k % st.output_every == 0 or last):
                    pv.write(sim.time)
                    if pc:
                        pc.write(sim.time)
                    n_frames += 1
                extra = f" sweeps {c['sweeps']}" if c else ""
                if curve_body is not None:
                    extra += f" F{cv['force']} = {curve_body.reaction[DOFS.index(cv['force'])] / 1e3:.4g} kN"
                bar.update(f"[{si + 1}/{len(case.stages)} {st.name}] step {k}/{n_steps} t = {sim.time:.6g} s "
                           f"E = {info.total_energy:.6g} J vmax = {info.max_velocity:.3g} m/s{extra}", force=last)
                if ckpt_every and (sim.step_count % ckpt_every == 0 or last):
                    write_checkpoint(os.path.join(out_dir, "checkpoint.npz"), sim, si)
                if at_eq:
                    stopped = f"equilibrium (max velocity {info.max_velocity:.3g} m/s) after {k} steps"
                    break
                if reason is not None:
                    stopped = reason
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
    if model.contact is not None and getattr(model.contact, "state", None) is not None:
        from .laws import S_DISS
        summary["dissipated_energy_J"] = float(model.contact.state[:, S_DISS].sum())
    summary.update(_figures(case, sim, model, out_dir))
    write_summary(os.path.join(out_dir, "summary.json"), summary)
    return summary


def _figures(case, sim, model, out_dir) -> dict:
    """force_displacement.png and crack_pattern.png, and the curve's peak figures for summary.json."""
    from .output.figures import write_crack_pattern, write_curve
    from .output.history import read_history
    out = {}
    if case.output.get("crack_pattern", True) and any(b.kind == 0 for b in model.bodies):
        write_crack_pattern(os.path.join(out_dir, "crack_pattern.png"), sim, model.contact, title=case.name)
        out["crack_pattern"] = "crack_pattern.png"
    cv = case.output.get("curve")
    if cv:
        hist = read_history(os.path.join(out_dir, "history.csv"))
        body, fk, dk = cv["body"], f"R{cv['force']}", f"u{cv['displacement']}"
        if f"{body}.{fk}" not in hist:
            return out
        write_curve(os.path.join(out_dir, "force_displacement.png"), hist, body, fk, dk, title=case.name)
        F = np.abs(hist[f"{body}.{fk}"])
        D = np.abs(hist[f"{body}.{dk}"])
        k = int(np.argmax(F))
        out["peak_force_kN"] = float(F[k] / 1e3)
        out["displacement_at_peak_mm"] = float(D[k] * 1e3)
        other = [c for c in hist if c.startswith(f"{body}.R") and c != f"{body}.{fk}"]
        out["other_reactions_at_peak_kN"] = {c: float(hist[c][k] / 1e3) for c in other}
        sel = (F > 0) & (F <= 0.4 * F[k]) & (D > 0)
        out["initial_stiffness_kN_per_mm"] = float(np.polyfit(D[sel] * 1e3, F[sel] / 1e3, 1)[0]) \
            if sel.sum() >= 3 else None
        if cv["force"] == "x":
            out["peak_horizontal_force_kN"] = out["peak_force_kN"]
            out["vertical_force_at_peak_kN"] = float(hist.get(f"{body}.Ry", np.zeros_like(F))[k] / 1e3) \
                if f"{body}.Ry" in hist else None
        out["force_displacement"] = "force_displacement.png"
    return out
