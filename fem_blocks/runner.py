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
from .errors import InputError
from .bodies import Driver
from .dynamics import Simulation, column_sums, columns
from .expand import expand
from .model import Model, build_model
from .output.history import HistoryWriter
from .output.checkpoint import write_checkpoint
from .output.contacts import ContactsWriter
from .output.paraview import BodiesWriter, BodiesWriter3D
from .output.summary import write_summary
from .specs import ChecksSpec, OutputSpec, default_of
from .distributed.root import on_root

DOFS = ("x", "y", "rz")  # 2D; model.dofs gives the dofs of the model's dimension (3D: x, y, z, rx, ry, rz)


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


SMALL_ROTATION = 0.01  # rad: the bound of linear kinematics (docs/validation.md "Rotating blocks"; _RotationWatch)


def rotation_bodies(case: Case, model: Model) -> list[int]:
    """Indices (model order) of the deformable bodies that `[output] rotations` names, each entry a block name or a
    group name; InputError naming the case file and the key for an entry that matches no deformable block (the
    names are matched here, after expand, since generated blocks have no name before)."""
    out = set()
    for nm in case.output.get("rotations") or []:
        hit = [i for i, (n, g, b) in enumerate(zip(model.names, model.groups, model.bodies))
               if b.kind == 0 and nm in (n, g)]
        if not hit:
            rigid = any(b.kind == 1 and nm in (n, g) for n, g, b in zip(model.names, model.groups, model.bodies))
            groups = sorted({g for g, b in zip(model.groups, model.bodies) if b.kind == 0})
            raise InputError(f"{case.source}: output.rotations: {nm!r}: expected the name of a deformable block or "
                             f"of a group of blocks ({', '.join(map(repr, groups))}, ...)"
                             + ("; a rigid body's rotation is already the history column NAME.urz" if rigid else ""))
        out.update(hit)
    return sorted(out)


def _rotation_stop(case: Case, model: Model, si: int, ref: tuple) -> tuple:
    """[stages.stop_at_rotation] (body, relative_to, value) -> (body, reference body or None, value), the bodies
    (blocks or rigid bodies) found by name here, after expand (generated blocks have no name before); InputError
    naming the case file and the key for a name that matches no body."""
    out = []
    for key, nm in (("body", ref[0]), ("relative_to", ref[1])):
        if nm is not None and nm not in model.names:
            raise InputError(f"{case.source}: stages[{si}].stop_at_rotation.{key} = {nm!r}: expected the name of a "
                             f"block or rigid body")
        out.append(None if nm is None else model.bodies[model.names.index(nm)])
    return out[0], out[1], ref[2]


def body_rotation(b, dim: int):
    """Rotation of a body since its placement: 2D the angle [rad] (counter-clockwise; deformable: body.rotation(),
    rigid: q[2]); 3D the rotation matrix (deformable: exp([w]x) of body.rotation(); rigid: its orientation)."""
    from .bodies import rotation3d
    if dim == 2:
        return float(b.rotation()) if b.kind == 0 else float(b.q[2])
    return rotation3d(b.rotation()) if b.kind == 0 else np.array(b.orientation, dtype=float)


def relative_rotation(b, ref, dim: int) -> float:
    """The angle [rad] of body b's rotation relative to body ref (since placement when ref is None): 2D
    |θ_b − θ_ref|, 3D the angle of Rot_refᵀ Rot_b (|rotation_vector|)."""
    from .bodies import rotation_vector
    rb = body_rotation(b, dim)
    if dim == 2:
        return abs(rb - (0.0 if ref is None else body_rotation(ref, dim)))
    rr = np.eye(3) if ref is None else body_rotation(ref, dim)
    return float(np.linalg.norm(rotation_vector(rr.T @ rb)))


def _rotation_record(b, ref, dim: int, t: float, angle: float) -> dict:
    """The stage record of a stop at a rotation: the time, the relative angle and both bodies' rotations since
    placement (2D angles [rad], 3D rotation vectors [rad])."""
    from .bodies import rotation_vector

    def rot(x):
        r = body_rotation(x, dim)
        return r if dim == 2 else rotation_vector(r).tolist()
    return dict(time=t, relative_angle_rad=angle, body_rotation_rad=rot(b),
                relative_to_rotation_rad=None if ref is None else rot(ref))


def joint_pairs(case: Case, model: Model) -> list[tuple[int, int]]:
    """(a, b) body indices (model order) of the `[output] joints` pairs of names; InputError naming the key for a
    name that is no body (matched after expand, as rotation_bodies)."""
    out = []
    for pair in case.output.get("joints") or []:
        for nm in pair:
            if nm not in model.names:
                raise InputError(f"{case.source}: output.joints: {nm!r}: expected the name of a block or rigid body "
                                 f"({', '.join(map(repr, model.names[:4]))}, ...)")
        out.append(tuple(model.names.index(nm) for nm in pair))
    return out


def gauge_points(case: Case, model: Model) -> list[tuple]:
    """`[output] gauges` located in their blocks' meshes: (name, body index, cell nodes, weights) each
    (output/gauges.py); InputError naming the gauge's key for a block that is not a deformable block or a point
    outside it (matched after expand, as rotation_bodies)."""
    from .output.gauges import locate
    out = []
    for g in case.output.get("gauges") or []:
        i = model.names.index(g["block"]) if g["block"] in model.names else -1
        if i < 0 or model.bodies[i].kind != 0:
            blocks = [n for n, b in zip(model.names, model.bodies) if b.kind == 0]
            raise InputError(f"{case.source}: {g['key']}.block = {g['block']!r}: expected the name of a deformable "
                             f"block ({', '.join(map(repr, blocks[:4]))}{', ...' if len(blocks) > 4 else ''})")
        b = model.bodies[i]
        mesh = b.type.mesh
        hit = locate(b.reference_points, mesh.cells, mesh.cell_type, g["point"])
        if hit is None:
            raise InputError(f"{case.source}: {g['key']}.point = {list(g['point'])} m: outside block "
                             f"{g['block']!r}; expected a point of the block in its reference position")
        out.append((g["name"], i, mesh.cells[hit[0]], hit[1]))
    return out


def read_bodies(case: Case, model: Model, rotations=(), gauges=()) -> list[int]:
    """The bodies the run reads at every step on every rank (dynamics.Simulation.share_bodies: stepped on every rank
    when the bodies are stepped per rank): those of the history's rotation columns and gauges, of the stages' stop
    conditions and of the force-displacement curve. (The joints' points come from the contacts' owners:
    joints_record.)"""
    ids = set(rotations) | {g[1] for g in gauges}
    for st in case.stages:
        names = [ref[0] for ref in (st.stop_displacement, st.stop_after_peak) if ref is not None]
        names += [nm for nm in (st.stop_rotation or (None, None))[:2] if nm is not None]
        ids.update(model.index(nm) for nm in names)
    cv = case.output.get("curve")
    if cv:
        ids.add(model.index(cv["body"]))
    return sorted(ids)


def _gauge_names(model: Model, gauges) -> list[str]:
    D = 2 if len(model.dofs) == 3 else 3
    return [f"{g[0]}.u{d}" for g in gauges for d in model.dofs[:D]]


def joints_record(model: Model, sim):
    """(the last step's record of every contact, `locate`) for the joints' resultants (output/joints.py
    record_joints): 2D `locate(cs)` gives the contacts' current candidate points (ContactStep.contact_points), on
    N > 1 ranks computed by each contact's owner (whose bodies it steps, dynamics.py "Bodies stepped per rank") and
    gathered with the record; 3D None (the contact set's points). COLLECTIVE on N > 1 ranks."""
    rec = None if sim is None else sim.last_contact
    if rec is None or len(model.dofs) != 3:
        return (None if rec is None else rec.whole()), None
    if rec.rows is None:
        return rec, model.contact.contact_points
    points = rec.gather(model.contact.contact_points(rec.cs.subset(rec.rows)))
    return rec.whole(), (lambda cs: points)


def _joint_values(model: Model, sim, joints) -> dict:
    """history.csv values of the `[output] joints` pairs at the last step (output/joints.py)."""
    from .output.joints import history_values, record_joints
    rec, locate = joints_record(model, sim)  # (N ranks: collective)
    res = record_joints(rec, locate, model.contact.joint_lengths if len(model.dofs) == 3 else None)
    return history_values(res, joints, model.names)


def _rotation_names(model: Model, i: int) -> list[str]:
    """history.csv columns of the rotation of deformable body i: NAME.rot (2D, rad), NAME.rotx/roty/rotz (3D)."""
    name = model.names[i]
    return [f"{name}.rot"] if len(model.dofs) == 3 else [f"{name}.rot{c}" for c in "xyz"]


def history_columns(model: Model, rotations=(), joints=(), gauges=()) -> list[str]:
    """The columns of history.csv; `rotations`: deformable body indices with rotation columns (rotation_bodies);
    `joints`: (a, b) body index pairs with joint-resultant columns (joint_pairs); `gauges`: gauge_points."""
    cols = ["step", "time", "stage", "h", "kinetic", "elastic", "gravity_potential", "external_work",
            "total_energy", "driver_work", "max_velocity"]
    for i, b in enumerate(model.bodies):
        if b.kind == 1:
            name = model.names[i]
            cols += [f"{name}.u{d}" for d in model.dofs]
            cols += [f"{name}.R{d}" for d in model.dofs]  # 0 on free dofs; stages may drive or free dofs
            cols += [f"{name}.I{d}" for d in model.dofs]  # inertial part of R (dynamics.py docstring)
    for i in rotations:
        cols += _rotation_names(model, i)
    cols += _gauge_names(model, gauges)
    if model.contact is not None:
        cols += ["contacts", "closed", "slip", "sweeps", "change", "residual", "converged", "dissipated",
                 "friction_dissipated"]
        if joints:
            from .output.joints import history_columns as joint_columns
            cols += joint_columns(model.names, joints)
    return cols


def history_row(model: Model, info, stage_index: int, sim=None, h=None, rotations=(), joints=(), gauges=()) -> dict:
    row = dict(step=info.step, time=info.time, stage=stage_index, h=h, kinetic=info.kinetic, elastic=info.elastic,
               gravity_potential=info.gravity_potential, external_work=info.external_work,
               total_energy=info.total_energy, driver_work=None if sim is None else sim.driver_work,
               max_velocity=info.max_velocity)
    for i, b in enumerate(model.bodies):
        if b.kind == 1:
            name = model.names[i]
            for k, d in enumerate(model.dofs):
                row[f"{name}.u{d}"] = b.q[k]
            for k, d in enumerate(model.dofs):
                row[f"{name}.R{d}"] = b.reaction[k]
            for k, d in enumerate(model.dofs):
                row[f"{name}.I{d}"] = b.reaction_inertia[k]
    for i in rotations:  # body.rotation(): rad, counter-clockwise (2D); rotation vector (3D)
        row.update(zip(_rotation_names(model, i), np.atleast_1d(model.bodies[i].rotation())))
    if gauges:  # output/gauges.py: u(x) = sum_a N_a u_a in the gauge's cell
        from .output.gauges import gauge_values
        row.update(zip(_gauge_names(model, gauges),
                       np.concatenate([gauge_values(model.bodies[i].displacement_global(), nodes, w)
                                       for _, i, nodes, w in gauges])))
    if model.contact is not None:
        c = info.contact or {}
        row.update(contacts=c.get("contacts", 0), closed=c.get("active", 0), slip=c.get("slip", 0),
                   sweeps=c.get("sweeps", 0), change=c.get("change", 0.0), residual=c.get("residual", 0.0),
                   converged=int(c.get("converged", True)), dissipated=_dissipated(sim),
                   friction_dissipated=0.0 if sim is None or sim.last_contact is None
                   else sim.last_contact.friction_total)
        if joints:
            row.update(_joint_values(model, sim, joints))
    return row


def _dissipated(sim) -> float:
    """The contacts' dissipated energy so far [J]: the sum of the law state's S_DISS (decohesion and crushing;
    friction is not in it) over every contact (ContactResult.dissipated), the history column `dissipated`."""
    res = None if sim is None else sim.last_contact
    if res is None or res.state is None:
        return 0.0
    return float(res.dissipated)


def _new_cstats() -> dict:
    """Contact-solver statistics of a run (summary.json "contact"; kept in checkpoints). steps, sweeps,
    max_sweeps, unconverged, max_residual, max_change, refined_steps: per nominal step; rows, unconverged_rows,
    worst_unconverged, unconverged_solvers: per history row (a sub-step of "refine" is a row), the steps whose
    state the run kept; failed_attempts, failed_sweeps: the attempts "refine"/"adaptive" threw away and their
    solver iterations (not in `sweeps`)."""
    return dict(steps=0, sweeps=0, max_sweeps=0, unconverged=0, max_residual=0.0, max_change=0.0, refined_steps=0,
                rows=0, unconverged_rows=0, worst_unconverged=None, unconverged_solvers=[], failed_attempts=0,
                failed_sweeps=0)


def _count_row(cstats: dict, stage_bad: dict, row: dict, c: dict, stage: str, tol: float, criterion: str) -> None:
    """Count a history row written after a contact solve `c` (ContactStep.last); an unconverged one updates the
    run's and the stage's (`stage_bad`) count, worst residual (NaN counts as the worst) and solvers."""
    cstats["rows"] += 1
    stage_bad["rows"] = stage_bad.get("rows", 0) + 1
    if c.get("converged", True):
        return
    res = float(c.get("residual", np.nan))
    rec = dict(step=int(row["step"]), time=float(row["time"]), stage=stage, residual=res,
               solver=str(c.get("solver", "NLGS")), message=str(c.get("message", "")), tolerance=tol,
               criterion=criterion)

    def worse(a, b):  # a worse than b (None: nothing yet)
        return b is None or (not np.isfinite(a["residual"]) and np.isfinite(b["residual"])) \
            or a["residual"] > b["residual"]

    cstats["unconverged_rows"] += 1
    if worse(rec, cstats["worst_unconverged"]):
        cstats["worst_unconverged"] = rec
    if rec["solver"] not in cstats["unconverged_solvers"]:
        cstats["unconverged_solvers"] = sorted(cstats["unconverged_solvers"] + [rec["solver"]])
    stage_bad["count"] = stage_bad.get("count", 0) + 1
    if worse(rec, stage_bad.get("worst")):
        stage_bad["worst"] = rec
    stage_bad.setdefault("solvers", set()).add(rec["solver"])


def _stage_warning(st, stage_bad: dict) -> str:
    w = stage_bad["worst"]
    return (f"fem-blocks: warning: stage {st.name!r}: {stage_bad['count']} of {stage_bad.get('rows', 0)} steps did "
            f"not converge ({' / '.join(sorted(stage_bad['solvers']))} solver, tolerance {w['tolerance']:g} on the "
            f"{w['criterion']}); worst residual {w['residual']:.3g} at step {w['step']} (t = {w['time']:.6g} s): "
            f"{w['message']}; see the 'converged' and 'residual' columns of history.csv")


EXIT_UNCONVERGED = 3  # exit status of a run that completed with unconverged steps ([checks] accept_unconverged)


def convergence_report(case: Case, cstats: dict, has_contact: bool = True) -> dict:
    """summary.json "convergence": the steps (history rows) whose contact solve ended above the tolerance, the
    worst residual with its step, time, stage, solver and message, the nominal steps, those done as sub-steps
    ("refine"/"adaptive") and their share, the attempts thrown away, and the exit status the CLI gives a completed
    run: EXIT_UNCONVERGED (3) when there are such steps and `[checks] accept_unconverged` is false, else 0."""
    n = int(cstats.get("unconverged_rows", 0)) if has_contact else 0
    w = cstats.get("worst_unconverged") if has_contact else None
    accept = bool(case.checks.get("accept_unconverged", default_of(ChecksSpec, "accept_unconverged")))
    nominal, sub = int(cstats.get("steps", 0)), int(cstats.get("refined_steps", 0))
    out = dict(unconverged_steps=n, solved_steps=int(cstats.get("rows", 0)) if has_contact else 0,
               nominal_steps=nominal if has_contact else 0, substepped_steps=sub if has_contact else 0,
               substepped_share=sub / nominal if has_contact and nominal else 0.0,
               failed_attempts=int(cstats.get("failed_attempts", 0)) if has_contact else 0,
               accepted=accept, exit_status=EXIT_UNCONVERGED if n and not accept else 0,
               max_residual=float(cstats.get("max_residual", 0.0)) if has_contact else None,
               worst_residual=None, worst_step=None, worst_time=None, worst_stage=None, worst_solver=None,
               worst_message=None, tolerance=None, criterion=None,
               solvers=list(cstats.get("unconverged_solvers", [])) if has_contact else [])
    if w:
        out.update(worst_residual=w["residual"], worst_step=w["step"], worst_time=w["time"], worst_stage=w["stage"],
                   worst_solver=w["solver"], worst_message=w["message"], tolerance=w["tolerance"],
                   criterion=w["criterion"])
    return out


def convergence_line(conv: dict) -> str | None:
    """The CLI's last line: the outcome of the contact solves (None for a run without contact), preceded by the
    small-rotation warning line when the run had one (`rotation_warning`, _RotationWatch)."""
    rot = None if conv is None else conv.get("rotation_warning")
    line = _convergence_line(conv)
    if rot:
        return f"fem-blocks: warning: {rot}" + (f"\n{line}" if line else "")
    return line


def _convergence_line(conv: dict) -> str | None:
    if conv is None or conv.get("max_residual") is None:
        return None
    n = conv["unconverged_steps"]
    if not n:
        return (f"fem-blocks: contact solver: all {conv['solved_steps']} steps converged (largest residual "
                f"{conv['max_residual']:.3g})")
    res = conv["worst_residual"]
    return (f"fem-blocks: {'UNCONVERGED' if not conv['accepted'] else 'unconverged (accepted)'}: {n} of "
            f"{conv['solved_steps']} steps above the tolerance ({conv['tolerance']:g} on the {conv['criterion']}, "
            f"{' / '.join(conv['solvers'])}); worst residual {res:.3g} at step {conv['worst_step']} (t = "
            f"{conv['worst_time']:.6g} s, stage {conv['worst_stage']!r}); exit status {conv['exit_status']}"
            + (" ([checks] accept_unconverged = true)" if conv["accepted"] else
               " (set [checks] accept_unconverged = true to accept)"))


class RunStopped(Exception):
    """The run stopped before its end (signal, numerical failure, solver policy); outputs and a checkpoint were
    written. `code`: exit status for the CLI (1 failure, 130 SIGINT, 143 SIGTERM)."""

    def __init__(self, message: str, code: int = 1):
        super().__init__(message)
        self.code = code


class _Signals:
    """SIGINT/SIGTERM set a flag; the runner finishes the current step, writes a checkpoint and stops."""

    def __init__(self):
        self.received = None
        self.old = {}

    def __enter__(self):
        import signal
        import threading
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self.old[sig] = signal.signal(sig, self._handler)
        return self

    def _handler(self, signum, frame):
        if self.received is not None:  # second signal: stop now
            raise KeyboardInterrupt
        self.received = signum

    def __exit__(self, *exc):
        import signal
        for sig, h in self.old.items():
            signal.signal(sig, h)
        return False


def _shift(hist, t0: float):
    """A history with its times moved by t0 (history_times = "stage": times count from the stage's start)."""
    if isinstance(hist, dict) and t0:
        return {"times": [t + t0 for t in hist["times"]], "values": list(hist["values"])}
    return hist


def _enter_stage(model: Model, sim: Simulation, case: Case, si: int, t0: float = 0.0):
    """Apply stage `si`'s drivers, forces, time step and solver options (stages accumulate in order). `t0`: the
    time the stage started; with history_times = "stage" the stage's histories are shifted by it."""
    st = case.stages[si]
    off = t0 if getattr(case, "history_times", "absolute") == "stage" else 0.0
    changed = False
    for bname, dof, kind, hist in st.changes():  # (the bodies accumulate them: specs.controls_at)
        b = model.bodies[model.index(bname)]
        if kind == "force":
            b.set_force(dof, _shift(hist, off))
        else:
            b.set_driver(dof, None if kind == "free" else Driver(kind, _shift(hist, off),
                                                                 name=f"stages[{si}].drivers.{bname}",
                                                                 pivot=getattr(st.drivers[bname][dof], "pivot", None)))
        changed = True
    if changed and model.contact is not None:
        model.contact.mark_W_dirty()  # rigid W (driven dofs) changed
    if st.static:  # the static step needs every body held without its mass (dynamics.py docstring)
        bad = sim.static_obstacles()
        if bad:
            i, why = bad[0]
            raise InputError(f"{case.source}: stages[{si}].static = true: body {model.names[i]!r}: {why}; expected "
                             f"every deformable block clamped against rigid motion and every rigid dof driven "
                             f"(otherwise use velocity_reset with a small displacement per step)")
    sim.set_step(st.h, st.theta, st.static)
    sim.velocity_reset = st.velocity_reset
    if model.contact is not None:
        model.contact.set_options(case.contact.for_stage(st))  # the runner applies the non-convergence policy


def _cut_histories(case: Case, si: int, t_end: float, stage_t0: list, stages_done: list) -> list:
    """Warnings for the driver/force histories that stop applying when stage `si` ends at t_end (it ran its full
    duration) before their last time, although they fit the stage durations (stage_history_warnings covers those
    that do not): an earlier stage stopped early and the histories' times are absolute."""
    from .case import ended_histories, history_value, nominal_stage_times, _unit_of
    nominal = nominal_stage_times(case)
    early = [d for d in stages_done if d.get("stopped", "duration") != "duration"]
    out = []
    for lab, kind, h, s, dof in ended_histories(case, si):
        stage_mode = case.history_times == "stage" and s >= 0
        off = (stage_t0[s] if s < len(stage_t0) else 0.0) if stage_mode else 0.0
        end = h["times"][-1] + off
        nominal_end = h["times"][-1] + (nominal[s][0] if stage_mode else 0.0)
        if end <= t_end + 1e-9 * max(1.0, end) or nominal_end > nominal[si][1] + 1e-9 * max(1.0, nominal_end):
            continue
        why = ("; stage " + ", ".join(f"{d['name']!r} stopped early ({d['stopped']})" for d in early)
               if early else "")
        out.append(f"{case.source}: {lab}: stage {case.stages[si].name!r} ended at t = {t_end:.6g} s, before the "
                   f"end of this history (t = {end:.6g} s): {history_value(h, t_end - off):.4g} of "
                   f"{h['values'][-1]:.4g} {_unit_of(kind, dof)} applied{why}; "
                   + (f"its times count from the start of stage {case.stages[s].name!r} (history_times = 'stage'): "
                      "lengthen the stage" if stage_mode else
                      "history times are absolute (from the start of the run): set history_times = \"stage\" to "
                      "count them from each stage's start, or lengthen the stage"))
    return out


def _policy(case: Case, st) -> str:
    return st.on_nonconvergence or case.contact.on_nonconvergence


class _Guards:
    """Numerical safety checks after every step (docs/method.md §5: a run never goes on silently from a wrong state).

    * NaN/Inf in any displacement, velocity or contact impulse;
    * penetration: -(g - g0) at a contact point with rigid compression (coulomb, brittle, fremond) or -g for the
      compliant laws (elastic, mixed: joint closed beyond its thickness), above `[checks] max_penetration`
      (default: the interface's alert distance, beyond which detection is no longer trustworthy; shallower
      penetrations of contacts missed by fast bodies are reported, not stopped, by _MissedContactWatch);
    * energy: E - E_0 - W_ext - W_drivers (which is <= 0 for θ >= 1/2: contacts, cohesive joints and the θ-method
      only dissipate or store) above `max_energy_growth` x (K_0 + E_el,0 + |V - V_0| + |W_ext| + |W_drivers|).
    """

    def __init__(self, case: Case, model: Model, names, comm=None):
        self.names, self.comm = names, comm
        self.max_pen = case.checks.get("max_penetration")
        self.growth = case.checks.get("max_energy_growth", default_of(ChecksSpec, "max_energy_growth"))
        self.model = model
        self.alert = (np.array([itf.alert for itf in model.contact.interfaces], dtype=float)
                      if model.contact is not None else None)  # per interface (detection.build_table)
        self.max_ratio = 0.0  # largest (E - E_0 - W) / scale seen: > 0 means energy created (unconverged solves)

    def check(self, sim: Simulation, info, e0: tuple) -> str | None:
        a = self._agree(self._nonfinite_body(sim))
        if a is not None:
            return f"{'displacement' if a[2] == 'q' else 'velocity'} of body {self.names[a[1]]!r} is NaN/Inf"
        c = sim.last_contact  # the record of the step (contact/result.py; N ranks: each rank its own contacts' rows)
        if c is not None and c.cs is not None and c.P is not None:  # (on every rank alike: the checks agree)
            rows, order = _held(c)
            nan = np.flatnonzero(~np.isfinite(c.P).all(axis=1))
            a = self._agree((0.0, int(order[nan[0]]), self._pair(c, rows[nan[0]])) if nan.size else None)
            if a is not None:  # (the first of every rank's)
                return f"contact impulse at contact {self._number(c, a[1])} (bodies {a[2]}) is NaN/Inf"
            gt = c.gt_end
            if gt is not None and len(gt) == len(rows):
                from .laws import ELASTIC, MIXED
                compliant = (c.law == ELASTIC) | (c.law == MIXED)
                pen = np.where(compliant, -(gt + c.cs.g0[rows]), -gt)
                lim = (np.full(len(gt), self.max_pen) if self.max_pen is not None
                       else self.alert[c.cs.interface[rows]])
                bad = pen > lim
                k = int(np.argmax(np.where(bad, pen / lim, -np.inf))) if np.any(bad) else None
                a = self._agree(None if k is None else (-float(pen[k] / lim[k]), int(order[k]),
                                                        (float(pen[k]), float(lim[k]), self._pair(c, rows[k]))))
                if a is not None:  # (the worst of every rank's)
                    return (f"penetration {a[2][0]:.3g} m at contact {self._number(c, a[1])} (bodies {a[2][2]}) "
                            f"exceeds {a[2][1]:.3g} m ([checks] max_penetration)")
        K0, El0, V0 = e0
        dE = info.total_energy - (K0 + El0 + V0) - sim.external_work - sim.driver_work
        scale = K0 + El0 + abs(info.gravity_potential - V0) + abs(sim.external_work) + abs(sim.driver_work)
        if not np.isfinite(info.total_energy):
            return "the energy is NaN/Inf"
        if scale > 0:
            self.max_ratio = max(self.max_ratio, dE / scale)
        if dE > self.growth * scale and dE > 1e-9 * max(1.0, scale):
            return (f"energy grew by {dE:.4g} J without a source (more than max_energy_growth = {self.growth:g} x "
                    f"{scale:.4g} J of energy put in): unstable or unconverged step")
        return None

    @staticmethod
    def _nonfinite_body(sim: Simulation):
        """(0, i, "q" or "u"): the first body i (by number) with a NaN/Inf displacement (q, named first) or velocity,
        among this rank's bodies (Simulation.own_bodies; every body on one process); None if there is none. One
        isfinite per group array, not per body (2 x 10⁴ small calls per step for 10⁴ bricks)."""
        cols, mine, _ = sim.own_bodies()
        found = {}
        for gr, c in zip(sim.groups, cols):
            members = gr.members if c is None else gr.members[c]
            for name, A in (("u", gr.U), ("q", gr.Q)):  # q after u: a body with both is named by q
                for i in members[~np.isfinite(columns(A, c)).all(axis=0)]:
                    found[int(i)] = name
        for i in sim.rigid:
            b = sim.bodies[i]
            if mine[i] and not (np.all(np.isfinite(b.q)) and np.all(np.isfinite(b.u))):
                found[i] = "q" if not np.all(np.isfinite(b.q)) else "u"
        return (0.0, min(found), found[min(found)]) if found else None

    def _pair(self, c, a) -> str:
        """The bodies of contact `a` (a row of the record's contact set c.cs)."""
        return f"{self.names[c.cs.cand_body[a]]} / {self.names[c.cs.ant_body[a]]}"

    def _number(self, c, at: int) -> int:
        """The number, in the whole contact set, of the contact agreed by `_agree` (its `_held` order key `at`):
        the key itself on one process; on N > 1 ranks the contacts of every rank with a smaller id, counted (one
        all-reduce, every rank calling it: they agreed on the same contact)."""
        if c.rows is None:
            return at
        from mpi4py import MPI
        return int(self.comm.allreduce(int(np.count_nonzero(c.gather.ids < at)), op=MPI.SUM))

    def _agree(self, found):
        """What a check found on this rank's contacts, (key, contact, payload) or None, agreed by every rank: of
        those found, the one with the smallest (key, contact number), or None (key -ratio: the worst penetration,
        the first contact among equals, as one process's argmax over every contact). N > 1 ranks: one all-gather."""
        from .distributed.root import least_found
        return least_found(self.comm, found)


def _held(c):
    """(rows, order): the contacts whose rows the record c holds (numbers in c.cs) and a key per held contact that
    orders them as in the whole contact set — their numbers when the record holds every contact; on N > 1 ranks
    their contact ids (contact/matching.contact_ids, the ids of the record's gather), in the whole set's order too
    without the whole set."""
    if c.rows is None:
        rows = np.arange(len(c.cs.gap))
        return rows, rows
    return c.rows, c.gather.ids


class _MissedContactWatch:
    """Contacts missed by fast bodies (updated geometry). A contact exists for the solver only once detection finds
    the pair within g0 + alert at the start of a step (docs/method.md §6); a body that closes a gap of more than the
    alert distance in one step (relative normal speed x h > alert) goes through the alert band unseen and is found
    at the next detection already penetrating, by up to speed x h - alert; the velocity-level Signorini condition
    then pushes it out within one step, creating kinetic energy (≈ 6 J measured for a side impact at 2 mm per step
    with alert 1 mm). The penetration guard (_Guards) stops a run only beyond the alert distance.

    Check, every step of an updated-geometry run: the penetration at detection (start of the step) of every contact
    of the step, p0 = -(g - g0) (rigid compression) or -g (compliant laws, as _Guards), against
    MISSED_FRACTION = 0.1 of its interface's alert distance. A contact held from the previous step sits at p0 ≈ 0
    (its gap was solved for at the end of that step: drift ~1e-8 m, tests/test_rocking.py), so a deeper one came
    through the alert band in the last step: it travelled more than alert + p0 in one step. The run warns once
    (stderr, summary.json "warnings"), naming the interface, the bodies, the time and the depth, and suggests
    alert >= 2 (alert + p0); summary.json "missed_contacts" records the first and the deepest and the number of
    steps that had one. Frozen geometry detects once, at the start (no watch). Cost: max(g0 - g) over the contacts
    per step (0.2 ms for 1e5 contacts, load 3.7 on 2 cores), the full test only when it exceeds 0.1 x the smallest
    alert."""

    FRACTION = 0.1

    def __init__(self, model: Model, names, state: dict | None = None, comm=None):
        self.names, self.comm = names, comm
        ct = self.step = model.contact
        self.active = ct is not None and getattr(ct.opts, "geometry", "frozen") == "updated"
        self.itf_names = [i.name for i in ct.interfaces] if ct is not None else []
        self.alert = np.array([i.alert for i in ct.interfaces], dtype=float) if ct is not None else None
        self.state = state if state is not None else dict(steps=0, first=None, deepest=None)

    def check(self, sim: Simulation) -> str | None:
        """Update the record with this step's contacts; returns the warning at the first step with a missed one. N > 1
        ranks: each rank reads the contacts of its record's rows, and the deepest (the first among equals) is agreed
        by one all-gather (every rank alike)."""
        c = sim.last_contact
        if not self.active or sim.step_count <= 1 or c is None or c.cs is None or c.law is None:
            return None  # (step 1: the start's overlaps, up to the alert distance, are the case's, not missed)
        from .distributed.root import least_found
        found = least_found(self.comm if c.rows is not None else None, self._deepest(c))
        if found is None:
            return None
        _, _, i, (cand, ant), depth = found
        st = self.state
        rec = dict(interface=self.itf_names[i], bodies=[self.names[cand], self.names[ant]],
                   time=float(sim.time), step=int(sim.step_count), depth=depth, alert=float(self.alert[i]),
                   suggested_alert=float(_round_up(2 * (self.alert[i] + depth))))
        st["steps"] += 1
        if st["deepest"] is None or rec["depth"] > st["deepest"]["depth"]:
            st["deepest"] = rec
        if st["first"] is not None:
            return None
        st["first"] = rec
        return self.message()

    def _deepest(self, c):
        """(-ratio, order key, interface, (candidate, antagonist body), depth) of the held contact with the largest
        p0 / alert above FRACTION (the first among equals), or None."""
        from .laws import ELASTIC, MIXED
        rows, order = _held(c)
        cs = c.cs
        if not len(rows):
            return None
        sel = slice(None) if c.rows is None else rows  # (one process: views of every contact's arrays)
        ub = cs.g0[sel] - cs.gap[sel]  # >= p0 (g0 >= 0): the common case, nothing near the threshold, in two passes
        if float(ub.max()) <= self.FRACTION * float(self.alert.min()):
            return None
        law = self.step.law_codes(cs)[sel]
        compliant = (law == ELASTIC) | (law == MIXED)
        p0 = np.where(compliant, -cs.gap[sel], ub)
        ratio = p0 / self.alert[cs.interface[sel]]
        a = int(np.argmax(ratio))
        if ratio[a] <= self.FRACTION:
            return None
        r = rows[a]
        return (-float(ratio[a]), int(order[a]), int(cs.interface[r]), (int(cs.cand_body[r]), int(cs.ant_body[r])),
                float(p0[a]))

    def message(self) -> str | None:
        f = self.state["first"]
        if f is None:
            return None
        return (f"interface {f['interface']!r}: a contact between {f['bodies'][0]!r} and {f['bodies'][1]!r} was found "
                f"{f['depth']:.3g} m deep at t = {f['time']:.6g} s (step {f['step']}): the bodies crossed the alert "
                f"distance ({f['alert']:.3g} m) in one step, so the contact was missed and its push-out creates "
                f"energy; use alert >= {f['suggested_alert']:.3g} m on this interface (twice the distance travelled "
                f"in that step, at least alert + depth), or a smaller h (summary.json \"missed_contacts\")")


def _round_up(x: float) -> float:
    """x rounded up to 2 significant digits."""
    if x <= 0:
        return x
    e = 10.0 ** (np.floor(np.log10(x)) - 1)
    return float(np.ceil(x / e - 1e-9) * e)


class _RotationWatch:
    """The small-rotation bound of linear kinematics. Without a body frame (`[contact] geometry = "frozen"`, or no
    contact: Simulation.corotational false) a deformable block moves by x = R (X + q) + c with q small: a rigid
    rotation θ of the block is represented by a linear displacement field, which stretches it by 1/cos θ - 1 ≈ θ²/2
    (5e-5 at 0.01 rad, i.e. a strain of the order of the elastic strains of masonry under service loads), and in
    frozen geometry the contact frames and gaps stay those of the reference configuration, off by θ (a normal
    tilted by 0.01 rad turns 1 % of a normal impulse into a tangential one, the order of the other approximations
    of a small-displacement model). Past SMALL_ROTATION = 0.01 rad the answer is not to be trusted as small-rotation
    answer: the run warns once, naming the block, the time and the angle (summary.json "warnings" and "rotation",
    stderr, the CLI's last lines), and records the largest rotation reached.

    Check, every step, on the blocks without a frame (all of them in a linear-kinematics run; in a co-rotational run
    the clamped ones, `_Group.framed` false): |θ| of each block, θ = BlockType.rotation_weights() q (body.rotation()
    of a block without frame), each block's θ summed from its own column of q (dynamics.column_sums): 0.09 ms per
    step for 10³ bricks, 0.66 ms for 10⁴ (2026-11-26; docs/benchmarks.md "Small-rotation watch" for the einsum it
    replaced, 0.03 and 0.26 ms the same hour, whose sums depend on the blocks beside each one). N ranks: each rank
    checks its own blocks (Simulation.own_bodies) and one all-gather agrees on the largest (the first among equals,
    as one process) and the blocks beyond the bound."""

    def __init__(self, sim: Simulation, names, state: dict | None = None, bound: float = SMALL_ROTATION):
        self.names, self.bound = names, bound
        self.active = any(not getattr(g, "framed", False) for g in sim.groups)
        self.state = state if state is not None else dict(bound=bound, max_rad=0.0, max_block=None, max_time=None,
                                                          blocks_beyond=[], first=None)

    def check(self, sim: Simulation) -> str | None:
        """Update the record with the current rotations; returns the warning at the first step beyond the bound."""
        if not self.active:
            return None
        st = self.state
        cols, _, comm = sim.own_bodies()  # N ranks: this rank's bodies, the ranks' findings agreed below
        top, beyond = None, []  # (-|θ|, group, position in it) of the largest, first among equals; names beyond
        known = set(st["blocks_beyond"])  # (the same on every rank: only the blocks new beyond the bound travel)
        for g, (gr, c) in enumerate(zip(sim.groups, cols)):
            members = gr.members if c is None else gr.members[c]
            if getattr(gr, "framed", False) or not members.size:
                continue
            # type frame (|θ| is frame-free); each body's θ from its own column (dynamics.column_sums: the same
            # double whatever the bodies beside it, as the sums over bodies; einsum's order depends on them)
            Q = columns(gr.Q, c)
            th = [column_sums(w[:, None] * Q) for w in gr.type.rotation_weights()]
            mag = np.abs(th[0]) if len(th) == 1 else np.sqrt(th[0] * th[0] + th[1] * th[1] + th[2] * th[2])
            j = int(np.argmax(mag))
            pos = j if c is None else int(c[j])
            if top is None or -mag[j] < top[0]:
                top = (-float(mag[j]), g, pos)
            beyond += [self.names[i] for i in members[mag > self.bound] if self.names[i] not in known]
        if comm is not None:  # one all-gather: every rank's largest and blocks beyond
            every = comm.allgather((top, beyond))
            found = [t for t, _ in every if t is not None]
            top = min(found) if found else None
            beyond = [name for _, names in every for name in names]
        if top is not None and -top[0] > st["max_rad"]:
            st.update(max_rad=-top[0], max_block=self.names[sim.groups[top[1]].members[top[2]]],
                      max_time=float(sim.time))
        st["blocks_beyond"] = sorted(set(st["blocks_beyond"]).union(beyond))
        if st["first"] is not None or st["max_rad"] <= self.bound:
            return None
        st["first"] = dict(block=st["max_block"], time=float(sim.time), step=int(sim.step_count), rad=st["max_rad"])
        return self.message()

    def message(self) -> str | None:
        f = self.state["first"]
        if f is None:
            return None
        return (f"block {f['block']!r} rotated by {f['rad']:.4g} rad at t = {f['time']:.6g} s (step {f['step']}), "
                f"beyond the small-rotation bound {self.bound:g} rad of linear kinematics: its shape grows by about "
                f"θ²/2 and the frozen contact frames are off by θ; use [contact] geometry = \"updated\" (co-rotational "
                f"blocks; clamped blocks keep linear kinematics) for large rotations (summary.json \"rotation\": the "
                f"largest rotation and every block beyond the bound)")


def _snapshot(sim: Simulation, model: Model, run: dict) -> dict:
    """Copy of everything a step changes (to redo it, or to checkpoint the last good state)."""
    d = sim.export_state()
    if model.contact is not None:
        for k, v in model.contact.export_state().items():
            d[k] = v.copy() if k in ("contact.state", "contact.P") else v
    d.update(_run_arrays(run))
    return d


def _body_owner(model: Model, comm, arrays: dict | None = None) -> np.ndarray:
    """N ranks: the rank of each body, for the pieces of the checkpoint `arrays`: the partition the arrays were
    taken under (their "contact.body_owner": each rank's per-contact rows are those of that partition; a snapshot
    taken before a step that partitioned the bodies again holds the old one), else the contact step's partition
    (PT-Scotch, the contacts' owners), else (no contact solved yet, no contacts) the ParaView pieces' blocks of
    bodies."""
    from .output.paraview import piece_owner
    nb = len(model.bodies)
    kept = None if arrays is None else arrays.get("contact.body_owner")
    if kept is not None and len(kept) == nb:
        return np.asarray(kept, dtype=np.int64)
    c = model.contact
    if c is not None and c.body_owner is not None and len(c.body_owner) == nb:
        return np.asarray(c.body_owner, dtype=np.int64)
    return piece_owner(nb, comm.Get_size())


def _run_arrays(run: dict) -> dict:
    import json
    return {"run.stage": np.int64(run["stage"]), "run.k": np.int64(run["k"]),
            "run.stage_done": np.bool_(run["stage_done"]), "run.peak_force": np.float64(run["peak_force"]),
            "run.e0": np.array(run["e0"], dtype=float), "run.frames": np.int64(run["frames"]),
            "run.json": np.array(json.dumps(dict(cstats=run["cstats"], stages_done=run["stages_done"],
                                                 stage_t0=run.get("stage_t0", []),
                                                 adapt=run.get("adapt", dict(level=0, easy=0)),
                                                 rotation=run.get("rotation"),
                                                 missed_contacts=run.get("missed_contacts")))),
            "case_hash": np.array(run["case_hash"]), "fem_blocks": np.array(__version__)}


def _restore(sim: Simulation, model: Model, d: dict) -> None:
    sim.restore_state(d)  # with the contact step's arrays: restores it too (Simulation.restore_state)


def _attempt(sim: Simulation, model: Model, budget: int):
    """One sim.step(); `budget` > 0: with the contact solver's sweeps (and Newton iterations) capped at `budget` (an
    attempt that may still be halved: [contact] attempt_budget)."""
    if budget <= 0 or model.contact is None:
        return sim.step()
    import dataclasses
    full = model.contact.opts
    its = budget if full.max_iterations is None else min(budget, full.max_iterations)
    model.contact.set_options(dataclasses.replace(full, max_sweeps=min(full.max_sweeps, budget), max_iterations=its))
    try:
        return sim.step()
    finally:
        model.contact.set_options(full)


def _sweeps(info) -> int:
    return int((info.contact or {}).get("sweeps", 0))


def _failed(run: dict, sweeps: int) -> None:
    """Count an attempt (a step, or the sub-steps of one level of "refine") whose state is thrown away, and its
    solver iterations (summary.json "contact": failed_attempts, failed_sweeps)."""
    c = run["cstats"]
    c["failed_attempts"] = c.get("failed_attempts", 0) + 1
    c["failed_sweeps"] = c.get("failed_sweeps", 0) + int(sweeps)


def _step(sim: Simulation, model: Model, run: dict, policy: str, max_level: int, make_row, write_row,
          budget: int = 0, grow_after: int = 4) -> tuple:
    """One nominal step h; with policy "refine", a step whose contact solve did not converge is redone as 2, 4, ...
    2^max_level sub-steps (sub-step rows go to the history with their h and the state at the end of each sub-step;
    `make_row(info, h)` builds a row from the current state, `write_row(row)` writes it); "adaptive": `_step_adaptive`.
    `budget` > 0: every attempt that may still be halved stops after `budget` sweeps / Newton iterations (the last
    level has the full max_sweeps). Returns (info, level): level = the deepest halving used in this step."""
    if policy == "adaptive" and model.contact is not None:
        return _step_adaptive(sim, model, run, max_level, make_row, write_row, budget, grow_after)
    if policy != "refine" or model.contact is None:
        info = sim.step()
        write_row(make_row(info, sim.h))
        return info, 0
    snap = _snapshot(sim, model, run)
    h, th, t0 = sim.h, sim.theta, sim.time
    info = _attempt(sim, model, budget)
    level, spent = 0, _sweeps(info)
    while info.contact and not info.contact.get("converged", True) and level < max_level:
        _failed(run, spent)
        level += 1
        _restore(sim, model, snap)
        sim.set_step(h / 2 ** level, th, nominal=h)
        rows, spent = [], 0
        for _ in range(2 ** level):
            info = _attempt(sim, model, budget if level < max_level else 0)
            spent += _sweeps(info)
            rows.append(make_row(info, sim.h))  # now: the bodies' state at the end of this sub-step
            if not info.contact.get("converged", True) and level < max_level:
                break
        else:
            break
    if level:
        sim.set_step(h, th)
        for row in rows:
            write_row(row)
        sim.time = t0 + h  # the nominal time grid (sub-steps may differ from it by rounding)
    else:
        write_row(make_row(info, h))
    return info, level


def _step_adaptive(sim: Simulation, model: Model, run: dict, max_level: int, make_row, write_row, budget: int,
                   grow_after: int) -> tuple:
    """One nominal step h as sub-steps h / 2^l on the grid of h / 2^max_level: a sub-step that does not converge
    (within `budget` while l < max_level) is thrown away and redone at l + 1; after `grow_after` converged sub-steps
    in a row at level l the next sub-step doubles (l - 1) when it starts on the coarser grid; the level carries over
    to the next nominal step (run["adapt"], reset at each stage start), so a hard stretch is not re-attempted at h
    each step. Each kept sub-step is a history row with its h; at max_level an unconverged sub-step is kept
    (flagged, as with "refine"). The step ends on the nominal time t0 + h. Returns (info, deepest level)."""
    ad = run.setdefault("adapt", dict(level=0, easy=0))
    h, th, t0 = sim.h, sim.theta, sim.time
    units, p, deepest, info = 2 ** max_level, 0, 0, None
    lev = min(int(ad["level"]), max_level)
    while p < units:  # p is a multiple of size (a level drops only at a point of the coarser grid): it fits
        size = 2 ** (max_level - lev)
        hs = h * size / units
        if sim.h != hs:
            sim.set_step(hs, th, nominal=h)
        snap = _snapshot(sim, model, run) if lev < max_level else None
        info = _attempt(sim, model, budget if lev < max_level else 0)
        ok = not info.contact or info.contact.get("converged", True)
        if not ok and lev < max_level:
            _failed(run, _sweeps(info))
            _restore(sim, model, snap)
            lev += 1
            ad["easy"] = 0
            continue
        write_row(make_row(info, sim.h))
        deepest = max(deepest, lev)
        p += size
        ad["easy"] = ad["easy"] + 1 if ok else 0
        if lev > 0 and ad["easy"] >= grow_after and p % (2 * size) == 0:
            lev -= 1
            ad["easy"] = 0
    ad["level"] = lev
    if sim.h != h:
        sim.set_step(h, th)
    sim.time = t0 + h  # the nominal time grid (sub-steps may differ from it by rounding)
    return info, deepest


class _NoHistory:
    """The history of a rank other than 0 on N > 1 MPI ranks: rank 0 writes history.csv."""

    def write(self, row):
        pass

    def flush(self):
        pass

    def close(self):
        pass


def _collective_signal(comm, received):
    """The signal that stops the run at this step: on N > 1 ranks, the largest one any rank received (every rank
    stops at the same step)."""
    if comm is None:
        return received
    from mpi4py import MPI
    got = comm.allreduce(int(received or 0), op=MPI.MAX)
    return got or None


def run_case(case: Case, out_dir: str, progress: bool = True, resume: bool = False, force: bool = False,
             comm=None) -> dict:
    """Run every stage of `case`, writing outputs in `out_dir` as it goes; returns the summary dict.

    comm: an mpi4py communicator of N > 1 ranks running this same call (`mpirun -n N fem-blocks run`). Every rank
    builds the model and steps it; the contact solve is shared (contact/step.py ContactStep.use_comm: the
    Gauss–Seidel sweeps split by contact owner, in colour order); every rank writes the ParaView piece of its block
    of bodies (blocks_<frame>_p<rank>.vtu; output/paraview.py) and of its own contacts (contacts_<frame>_p<rank>.vtu;
    output/contacts.py) and its piece of each checkpoint (its bodies and contacts: distributed/checkpoint.py), rank 0
    the .pvtu/.pvd series and every other output; every rank returns the same summary (and raises the same
    RunStopped).

    resume=True continues from the newest valid checkpoint in `out_dir` (refused if the case file or its meshes
    changed since, unless force=True); history.csv and the .pvd series are cut back to the checkpoint and
    appended to. Raises RunStopped (after writing a checkpoint and the outputs) on SIGINT/SIGTERM, on a
    numerical failure (NaN, penetration, energy growth) and on non-convergence with policy "fail"."""
    from .case import fingerprint
    from .output.checkpoint import latest_checkpoint
    t_start = _time.perf_counter()
    comm = comm if comm is not None and comm.Get_size() > 1 else None
    root = comm is None or comm.Get_rank() == 0
    if root:
        os.makedirs(out_dir, exist_ok=True)
    fp = fingerprint(case)
    ck = None
    if resume:
        if comm is None:
            ck_path, ck = latest_checkpoint(out_dir)
        else:  # rank 0 chooses the checkpoint (or raises on every rank), every other rank reads its files
            from .output.checkpoint import latest_checkpoint_files, load_checkpoint
            found = {}

            def choose():
                label, paths, found["arrays"] = latest_checkpoint_files(out_dir)
                return label, paths
            ck_path, paths = on_root(comm, choose)
            ck = found["arrays"] if found else load_checkpoint(paths)
        if str(ck["case_hash"]) != fp and not force:
            raise InputError(f"{ck_path}: the case file {case.source} (or a base or mesh file it names, or --quick) "
                             "changed since this checkpoint was written; run without --resume to start again, or add "
                             "--force to resume anyway")
    case = expand(case)  # the generated bodies, and the warnings of what was built (expand.py)
    model = build_model(case)
    t_setup = _time.perf_counter() - t_start
    st0 = case.stages[0]
    sim = Simulation(model.bodies, h=st0.h, theta=st0.theta, gravity=model.gravity,
                     velocity_reset=st0.velocity_reset, contact=model.contact)
    if model.contact is not None and comm is not None:
        model.contact.use_comm(comm)
    from .model import groups_without_interface
    start_warnings = list(case.warnings) + groups_without_interface(case, model, sim)
    if comm is not None and model.contact is not None and model.contact.opts.order != case.contact.order:
        start_warnings.append(f"contact.order = {case.contact.order!r}: on {comm.Get_size()} MPI ranks the "
                              "Gauss-Seidel sweeps run in colour order ('colours': the same results on any number of "
                              "ranks and on one process with order = 'colours')")
    for w in start_warnings:  # one line each; also in summary.json "warnings"
        print(f"fem-blocks: warning: {w}", file=sys.stderr)
    import json
    run = dict(stage=0, k=0, stage_done=False, peak_force=0.0, e0=None, frames=0, case_hash=fp,
               cstats=_new_cstats(),
               stages_done=[], stage_t0=[])
    if ck is not None:
        extra = json.loads(str(ck["run.json"]))
        run.update(stage=int(ck["run.stage"]), k=int(ck["run.k"]), stage_done=bool(ck["run.stage_done"]),
                   peak_force=float(ck["run.peak_force"]), e0=tuple(float(x) for x in ck["run.e0"]),
                   frames=int(ck["run.frames"]), **extra)
        run["cstats"] = {**_new_cstats(), **run["cstats"]}  # (checkpoints written before the row counters)
        for si in range(run["stage"] + 1):
            _enter_stage(model, sim, case, si, run["stage_t0"][si] if si < len(run["stage_t0"]) else 0.0)
        try:
            _restore(sim, model, ck)
        except (KeyError, ValueError) as e:
            raise InputError(f"{out_dir}: checkpoint does not match this case's model ({e})") from None
    pdir = os.path.join(out_dir, "paraview")
    t_resume = float(ck["sim.time"]) if ck is not None else None
    Bodies = BodiesWriter if case.dimension == 2 else BodiesWriter3D
    # (N ranks: every rank writes the piece of its block of bodies, rank 0 also the .pvtu and .pvd; paraview.py)
    pv = Bodies(sim, pdir, stress=case.output["stress"], append=resume, keep_until_time=t_resume, comm=comm) \
        if case.output["paraview"] else None
    # (N ranks: every rank writes the piece of its contacts, rank 0 the .pvtu and .pvd, and the joints from the
    # record of every contact: write_contacts)
    jw = _joints_writer(case, model, pdir, resume, t_resume) if root else None
    pc = ContactsWriter(pdir, case.dimension, locate=model.contact.contact_points if case.dimension == 2 else None,
                        append=resume, keep_until_time=t_resume, joints=jw if comm is None else None, comm=comm) \
        if case.output["paraview"] and model.contact is not None else None
    ckpt_every = case.output.get("checkpoint_every", default_of(OutputSpec, "checkpoint_every"))
    cv = case.output.get("curve")
    curve_body = model.bodies[model.index(cv["body"])] if cv else None
    rot_ids = rotation_bodies(case, model)  # [output] rotations
    for si, st in enumerate(case.stages):  # [stages.stop_at_rotation]: its bodies named when the run starts
        if st.stop_rotation is not None:
            _rotation_stop(case, model, si, st.stop_rotation)
    joint_ids = joint_pairs(case, model)  # [output] joints
    gauge_ids = gauge_points(case, model)  # [output] gauges
    cols = history_columns(model, rot_ids, joint_ids, gauge_ids)
    sim.share_bodies(read_bodies(case, model, rot_ids, gauge_ids))  # (N ranks: stepped on every rank)
    hpath = os.path.join(out_dir, "history.csv")

    def open_history():
        if ck is not None and os.path.exists(hpath):
            # the rows before the checkpoint: read once from the file the run wrote (cut back to the checkpoint's
            # step), rather than copied into every checkpoint
            return HistoryWriter.resume(hpath, int(ck["sim.step"]), columns=cols, flush_every=50, keep=True)
        return HistoryWriter(hpath, cols, flush_every=50, keep=True)  # keep=True: figures from memory

    # (N ranks: rank 0 alone opens the history; its failure is raised on every rank)
    hist = on_root(comm, open_history, share=False)
    if hist is None:  # a rank other than 0 on N ranks
        hist = _NoHistory()
    cstats = run["cstats"]
    names = list(model.names)
    guards = _Guards(case, model, names, comm)
    watch = _RotationWatch(sim, names, run.get("rotation"))  # the small-rotation bound (resumed: its record)
    run["rotation"] = watch.state
    missed = _MissedContactWatch(model, names, run.get("missed_contacts"), comm)  # contacts missed by fast bodies
    run["missed_contacts"] = missed.state
    bar = Progress(progress and root)
    info = sim.info()

    def write_contacts():
        """A frame of contacts.pvd (N ranks: each rank the piece of its contacts) and, with `[output]
        joints_paraview`, of joints.pvd (N ranks: rank 0, from the record of every contact, gathered by every
        rank)."""
        if pc is None:
            return
        if comm is not None and case.output.get("joints_paraview"):
            rec, locate = joints_record(model, sim)  # (collective: the record and points of every contact)
            if jw is not None:
                jw.write(sim.time, rec, locate)
        pc.write(sim.time, sim.last_contact)

    if ck is None:
        hist.write(history_row(model, info, 0, sim, rotations=rot_ids, joints=joint_ids, gauges=gauge_ids))
        if pv:
            pv.write(sim.time)
        write_contacts()
        run["frames"] = 1
        run["e0"] = (info.kinetic, info.elastic, info.gravity_potential)

    def checkpoint(arrays=None):
        arrays = arrays if arrays is not None else _snapshot(sim, model, run)
        if comm is None:
            hist.flush()  # the history must hold every step up to the checkpoint
            write_checkpoint(out_dir, arrays)
            return
        # N ranks: each writes its piece (its bodies and contacts), rank 0 after flushing the history
        from .contact.step import ContactStep
        from .distributed.checkpoint import write_pieces
        from .dynamics import body_of_key
        write_pieces(comm, out_dir, arrays, _body_owner(model, comm, arrays), body_of_key,
                     ContactStep.per_contact_keys(arrays), before=hist.flush)

    def finish(status: str, code: int | None = None) -> dict:
        # (N ranks: rank 0 writes the summary and figures, from the record of every contact gathered by every rank;
        # every rank returns the summary, or raises)
        last = None if sim.last_contact is None else sim.last_contact.whole()
        sim.collect_bodies()  # (N ranks with the bodies stepped per rank: rank 0 receives every body's state)
        return on_root(comm, _finish, status, code, last)

    def _finish(status: str, code: int | None, last) -> dict:
        conv = convergence_report(case, run["cstats"], model.contact is not None)
        if status == "completed" and conv["unconverged_steps"]:
            status = "completed with unconverged steps"
        summary = _summary(case, model, sim, info, run, t_start, t_setup, pv, pc, status)
        summary["energy_created_ratio_max"] = guards.max_ratio
        summary["warnings"] = start_warnings + [w for s in run["stages_done"] for w in s.get("warnings", [])]
        summary["warnings"] += [m for m in (watch.message(), missed.message()) if m]
        summary["rotation"] = watch.state if watch.active else None
        if missed.active:  # (updated geometry only: frozen-geometry summaries keep their keys)
            summary["missed_contacts"] = missed.state
        conv["rotation_warning"] = watch.message()  # printed by the CLI before its last line (convergence_line)
        summary["convergence"] = conv
        summary["exit_status"] = conv["exit_status"] if code is None else code
        if comm is not None:
            summary["mpi_ranks"] = comm.Get_size()
            summary["outputs"]["checkpoint"] = "checkpoint.rank<p>.npz"  # (one piece per rank)
        summary.update(_figures(case, sim, model, out_dir, hist.columns_dict(), conv, summary.get("stages"), last))
        write_summary(os.path.join(out_dir, "summary.json"), summary)
        return summary

    stage_bad = {}  # this stage's unconverged rows: count, worst (step, time, residual, solver, message), solvers

    def make_row(inf, hh):
        row = history_row(model, inf, run["stage"], sim, hh, rot_ids, joint_ids, gauge_ids)
        row["_contact"] = inf.contact  # (popped by write_row: the solver and its message, not history columns)
        return row

    def write_row(row):
        c = row.pop("_contact", None)
        hist.write(row)
        if c:
            o = model.contact.opts
            _count_row(cstats, stage_bad, row, c, case.stages[run["stage"]].name, o.tol,
                       "residual" if o.solver == "newton" else o.criterion)

    stopped_run = None
    try:
        with _Signals() as sig:
            si0 = run["stage"] + (1 if ck is not None and run["stage_done"] else 0)
            resumed_mid_stage = ck is not None and not run["stage_done"]
            for si in range(si0, len(case.stages)):
                st = case.stages[si]
                if not resumed_mid_stage:  # (a resumed run entered stages 0..run["stage"] before restoring)
                    run["stage_t0"] = run["stage_t0"][:si] + [sim.time]
                    _enter_stage(model, sim, case, si, sim.time)
                    run.update(stage=si, k=0, stage_done=False, peak_force=0.0, adapt=dict(level=0, easy=0))
                resumed_mid_stage = False
                policy = _policy(case, st)
                max_level = case.contact.max_refinements
                stop_body = {}
                for key, ref in (("disp", st.stop_displacement), ("peak", st.stop_after_peak)):
                    if ref is not None:
                        stop_body[key] = (model.bodies[model.index(ref[0])], model.dofs.index(ref[1])) + tuple(ref[2:])
                if st.stop_rotation is not None:
                    stop_body["rot"] = _rotation_stop(case, model, si, st.stop_rotation)
                stop_rec = None
                n_steps = max(1, int(round(st.duration / st.h)))
                t_stage = _time.perf_counter()
                stage_bad.clear()
                stopped = None
                k = run["k"]
                while k < n_steps:
                    k += 1
                    good = _snapshot(sim, model, run)  # last good state, checkpointed if this step fails
                    info, level = _step(sim, model, run, policy, max_level, make_row, write_row,
                                        case.contact.attempt_budget, case.contact.grow_after)
                    run["k"] = k
                    c = info.contact
                    if c:
                        cstats["steps"] += 1
                        cstats["sweeps"] += c["sweeps"]
                        cstats["max_sweeps"] = max(cstats["max_sweeps"], c["sweeps"])
                        cstats["unconverged"] += 0 if c["converged"] else 1
                        cstats["refined_steps"] += 1 if level else 0
                        cstats["max_residual"] = max(cstats["max_residual"], c["residual"])
                        cstats["max_change"] = max(cstats["max_change"], c["change"])
                    failure = guards.check(sim, info, run["e0"])
                    for w in (watch, missed):  # each warns once, at the step where it first fires
                        msg = w.check(sim)
                        if msg:
                            print(f"fem-blocks: warning: {msg}", file=sys.stderr)
                    if failure is None and c and not c["converged"] and policy in ("fail", "refine", "adaptive") \
                            and (policy == "fail" or level >= max_level):
                        if policy == "fail":
                            failure = (f"the contact solver ({c.get('solver', 'NLGS')}) did not converge: "
                                       f"{c.get('message', '')} (residual {c['residual']:.3g}; on_nonconvergence = "
                                       f"'fail')")
                    if failure is not None:
                        if pv:
                            pv.write(sim.time)
                            write_contacts()
                        checkpoint(good)
                        raise RunStopped(f"stage {st.name!r}, step {k} (t = {sim.time:.6g} s): {failure}. Outputs "
                                         f"so far are in {out_dir}; the checkpoint holds the last good step "
                                         f"({sim.step_count - 1}): fix the case and resume with --resume --force",
                                         1)
                    at_eq = (st.stop_at_equilibrium and k >= st.min_steps
                             and info.max_velocity <= st.equilibrium_velocity)
                    reason = None
                    if "disp" in stop_body:
                        b, d, val = stop_body["disp"]
                        if abs(b.q[d]) >= val * (1 - 1e-12):
                            reason = f"target displacement {val:g} reached after {k} steps"
                    if "rot" in stop_body:
                        b, ref, val = stop_body["rot"]
                        ang = relative_rotation(b, ref, model.dimension)
                        if ang >= val:
                            reason = f"rotation {ang:.6g} rad (target {val:g}) reached after {k} steps"
                            stop_rec = _rotation_record(b, ref, model.dimension, sim.time, ang)
                    if "peak" in stop_body:
                        b, d, drop, min_steps = stop_body["peak"]
                        f = abs(b.reaction[d])
                        run["peak_force"] = max(run["peak_force"], f)
                        pk = run["peak_force"]
                        if k >= min_steps and pk > 0 and f < (1 - drop) * pk:
                            reason = f"force dropped by {drop:.0%} after its peak {pk:.6g} N ({k} steps)"
                    last = k == n_steps or at_eq or reason is not None
                    received = _collective_signal(comm, sig.received)  # (N ranks: one decision for all)
                    interrupted = received is not None
                    if pv and (k % st.output_every == 0 or last or interrupted):
                        pv.write(sim.time)
                        write_contacts()
                        run["frames"] += 1
                    extra = f" sweeps {c['sweeps']}" if c else ""
                    if level:
                        extra += f" (refined x{2 ** level})"
                    if curve_body is not None:
                        extra += f" F{cv['force']} = {curve_body.reaction[model.dofs.index(cv['force'])] / 1e3:.4g} kN"
                    bar.update(f"[{si + 1}/{len(case.stages)} {st.name}] step {k}/{n_steps} t = {sim.time:.6g} s "
                               f"E = {info.total_energy:.6g} J vmax = {info.max_velocity:.3g} m/s{extra}",
                               force=last)
                    if at_eq:
                        stopped = f"equilibrium (max velocity {info.max_velocity:.3g} m/s) after {k} steps"
                    elif reason is not None:
                        stopped = reason
                    if last:
                        n_unconv = stage_bad.get("count", 0)
                        cut = [] if stopped else _cut_histories(case, si, sim.time, run["stage_t0"],
                                                                run["stages_done"])
                        for w in cut:
                            print(f"fem-blocks: warning: {w}", file=sys.stderr)
                        run["stages_done"].append(dict(name=st.name, steps=k, h=st.h, theta=st.theta,
                                                       stopped=stopped or "duration", unconverged_steps=n_unconv,
                                                       **({"stop_rotation": stop_rec} if stop_rec else {}),
                                                       wall_time=_time.perf_counter() - t_stage,
                                                       **({"warnings": cut} if cut else {})))
                        run["stage_done"] = True
                        hist.flush()
                        if root:
                            _inertia_report(run["stages_done"][-1], hist.columns_dict(), si, st)
                        if n_unconv:
                            print(_stage_warning(st, stage_bad), file=sys.stderr)
                    if last or interrupted or (ckpt_every and sim.step_count % ckpt_every == 0):
                        checkpoint()
                    if interrupted:
                        import signal
                        code = 130 if received == signal.SIGINT else 143
                        raise RunStopped(f"interrupted by signal {received} at stage {st.name!r}, step {k} "
                                         f"(t = {sim.time:.6g} s); checkpoint and outputs written in {out_dir}; "
                                         f"continue with: fem-blocks run {case.source} --out {out_dir} --resume",
                                         code)
                    if last:
                        break
    except RunStopped as e:
        stopped_run = e
        raise
    finally:
        hist.close()
        bar.close()
        if model.contact is not None:
            model.contact.close()  # (N ranks: the PETSc objects of the shared solve, on every rank at once)
        if stopped_run is not None:
            try:
                finish(f"stopped: {stopped_run}", stopped_run.code)
            except Exception as e2:  # noqa: BLE001 - the stop message matters more than the summary
                print(f"fem-blocks: warning: could not write the summary: {e2}", file=sys.stderr)
    return finish("completed")


INERTIA_WARN = 0.01   # warn when the inertial part of a driven reaction exceeds 1 % of it (quasi-static stages)
INERTIA_FLOOR = 0.1   # ... at the steps where |R| is at least 10 % of its largest value in the stage


def inertia_shares(hist: dict, stage: int) -> dict:
    """Per driven reaction column `BODY.Rd` of stage `stage`: `max_share` = max |I|/|R| over the steps where
    |R| >= INERTIA_FLOOR x max |R| in the stage, `share_at_peak` = |I|/|R| at the step of max |R|, `max_abs_R`
    (reactions that are 0 throughout the stage, e.g. free dofs, are left out)."""
    sel = np.asarray(hist["stage"]) == stage
    if "step" in hist:
        sel &= np.asarray(hist["step"]) > 0  # the initial row (step 0) belongs to no step
    out = {}
    for col in hist:
        body, _, dof = col.rpartition(".")
        icol = f"{body}.I{dof[1:]}"
        if not body or not dof.startswith("R") or icol not in hist:
            continue
        R = np.abs(np.asarray(hist[col], float)[sel])
        inert = np.abs(np.asarray(hist[icol], float)[sel])
        if R.size == 0 or not np.any(R > 0):
            continue
        big = R >= INERTIA_FLOOR * R.max()
        k = int(np.argmax(R))
        out[col] = dict(max_share=float(np.max(inert[big] / R[big])), share_at_peak=float(inert[k] / R[k]),
                        max_abs_R=float(R[k]))
    return out


def _inertia_report(done: dict, hist: dict, si: int, st) -> None:
    """Adds `inertia_share` (inertia_shares of the run's history columns `hist`) to the stage's summary entry; warns
    in quasi-static stages (velocity_reset) when a share exceeds INERTIA_WARN."""
    shares = inertia_shares(hist, si)
    done["inertia_share"] = shares
    if not st.velocity_reset:
        return
    for col, v in shares.items():
        if v["max_share"] > INERTIA_WARN:
            print(f"fem-blocks: warning: stage {st.name!r}: the inertial part of reaction {col} reaches "
                  f"{v['max_share']:.1%} of it ({v['share_at_peak']:.1%} at its peak |R| = {v['max_abs_R']:.4g}); "
                  f"the inertia force scales as m du/h^2: use a smaller displacement per step, a larger h, or "
                  f"static = true where admissible "
                  f"(history column {col.rpartition('.')[0]}.I{col.rpartition('.')[2][1:]}; docs/case-files.md)",
                  file=sys.stderr)


def _summary(case, model, sim, info, run, t_start, t_setup, pv, pc, status) -> dict:
    cstats = run["cstats"]
    e0 = run["e0"] or (0.0, 0.0, 0.0)
    summary = dict(case=os.path.abspath(case.source), name=case.name, fem_blocks=__version__, status=status,
                   case_hash=run["case_hash"],
                   n_bodies=len(model.bodies),
                   n_deformable=sum(b.kind == 0 for b in model.bodies),
                   n_rigid=sum(b.kind == 1 for b in model.bodies),
                   n_block_types=len(model.block_types),
                   n_dofs=int(sum(bt.ndof * sum(1 for b in model.bodies if b.kind == 0 and b.type is bt)
                                  for bt in model.block_types.values())),
                   stages=run["stages_done"], final_time=sim.time, steps=sim.step_count,
                   final_energy=dict(kinetic=info.kinetic, elastic=info.elastic,
                                     gravity_potential=info.gravity_potential, total=info.total_energy,
                                     initial_total=float(sum(e0)), external_work=sim.external_work,
                                     driver_work=sim.driver_work),
                   frames=run["frames"], setup_time=t_setup,
                   contact=cstats if model.contact is not None else None,
                   wall_time=_time.perf_counter() - t_start,
                   outputs=dict(paraview=os.path.join("paraview", "blocks.pvd") if pv else None,
                                contacts=os.path.join("paraview", "contacts.pvd") if pc else None,
                                history="history.csv", checkpoint="checkpoint.npz"))
    res = sim.last_contact
    if model.contact is not None and res is not None and res.state is not None:
        summary["dissipated_energy_J"] = float(res.dissipated)
    if model.contact is not None and res is not None:
        summary["friction_dissipated_J"] = float(res.friction_total)  # contact/friction.py
    return summary


def _dof_control(case, body: str, dof: str, stage: int):
    """How `dof` of rigid body `body` is controlled during stage `stage` (stages accumulate in order, as in
    `_enter_stage`): ("driven", None), or ("force", history or None) for a free dof (None: no applied force)."""
    from .specs import controls_at
    c = controls_at(case.rigid_bodies, case.stages, stage).get((body, dof))
    return ("driven", None) if c is not None and c.driven else ("force", None if c is None else c.history)


def _vertical_force(case, hist, body: str, k: int):
    """Vertical force on `body` at history row k [kN], positive upwards: the reaction `body.Ry` (3D: `Rz`) when its
    vertical dof is driven (e.g. blocked), the applied force history at that time when the dof is free (force
    control; its reaction column is then 0)."""
    up = "y" if case.dimension == 2 else "z"
    if f"{body}.R{up}" not in hist:
        return None
    kind, force = _dof_control(case, body, up, int(hist["stage"][k]))
    if kind == "driven":
        return float(hist[f"{body}.R{up}"][k] / 1e3)
    from .bodies import as_history
    return 0.0 if force is None else float(as_history(force, f"{body}.forces.{up}")(float(hist["time"][k])) / 1e3)


def _unit_key(unit: str) -> str:
    return {"kN·m": "kNm"}.get(unit, unit)


def _virgin(x) -> np.ndarray:
    """Rows of the first loading branch of a displacement record: up to its first reversal (all rows when it
    never reverses), so that a cyclic test's initial stiffness is not fitted through its unloading branches."""
    dx = np.diff(np.asarray(x, float))
    mv = np.flatnonzero(np.abs(dx) > 0)
    rev = next((j for j in mv if np.sign(dx[j]) != np.sign(dx[mv[0]])), len(dx)) if mv.size else len(dx)
    return np.arange(len(dx) + 1) <= rev


def _cycles(hist: dict, body: str, fk: str, dk: str, out_dir: str, title: str) -> dict:
    """summary.json `cycles` (output/summary.cycles_block) and hysteresis.png (cycles coloured) when the curve's
    displacement goes both ways; {} for a monotone test."""
    from .output.figures import dof_unit, write_hysteresis
    from .output.summary import cycles_block
    (us, uu, _), (fs, fu, _) = dof_unit(dk), dof_unit(fk)
    stored = sum(np.asarray(hist[k], float) for k in ("elastic", "kinetic", "gravity_potential") if k in hist)
    u = np.asarray(hist[f"{body}.{dk}"], float)
    cyc = cycles_block(hist.get("time", np.arange(len(u), dtype=float)), u, hist[f"{body}.{fk}"], u_scale=us,
                       u_unit=_unit_key(uu), f_scale=fs, f_unit=_unit_key(fu), dissipated=hist.get("dissipated"),
                       stored=stored if np.ndim(stored) else None, friction=hist.get("friction_dissipated"))
    if cyc is None:
        return {}
    write_hysteresis(os.path.join(out_dir, "hysteresis.png"), hist, body, fk, dk, cyc, title=title)
    return {"cycles": cyc, "hysteresis": "hysteresis.png"}


def _cracked_bricks(b) -> dict:
    """summary.json `cracked_bricks` of a split-brick wall (output/figures.brick_cracks; {} without brick cracks)."""
    if b is None:
        return {}
    return {"cracked_bricks": dict(count=b["n_cracked"], of=b["n_bricks"], threshold_mm=1e3 * b["threshold_m"],
                                   max_width_mm=1e3 * b["max_width_m"], bricks=b["cracked_names"])}


def _joints_writer(case, model, pdir, resume, t_resume):
    """output.joints.JointsWriter of `[output] joints_paraview` (None when off or without contact)."""
    if not case.output.get("joints_paraview") or model.contact is None:
        return None
    from .output.joints import JointsWriter
    two_d = case.dimension == 2
    return JointsWriter(pdir, case.dimension, model.contact.contact_points if two_d else None,
                        model.contact.joint_lengths if two_d else None, append=resume, keep_until_time=t_resume)


def _figures(case, sim, model, out_dir, hist: dict, conv=None, stages=(), contact=None) -> dict:
    """force_displacement.png and crack_pattern.png, and the curve's peak figures for summary.json (keys named
    with their unit: translations mm / forces kN, rotations rad / moments kN·m; figures.dof_unit). `hist`: the
    run's history columns (HistoryWriter.columns_dict: the rows of history.csv, kept in memory); with `[output]
    rotations`, rotations.png (figures.write_rotations; `stages`: summary.json "stages", their stops at a rotation).
    `contact`: the last step's record of every contact (ContactResult.whole(); None: sim.last_contact).
    """
    contact = contact if contact is not None or sim is None else sim.last_contact
    from .output.figures import curve_data, dof_unit, post_peak, post_peak_summary, write_crack_pattern, write_curve
    out = {}
    if case.dimension == 3:  # deformed blocks, off-screen (pyvista when installed, else matplotlib)
        from .output.figures import write_blocks_3d
        write_blocks_3d(os.path.join(out_dir, "blocks.png"), sim, title=case.name, backend="auto")
        out["blocks_png"] = "blocks.png"
    elif case.output.get("crack_pattern", default_of(OutputSpec, "crack_pattern")) \
            and any(b.kind == 0 for b in model.bodies):
        d = write_crack_pattern(os.path.join(out_dir, "crack_pattern.png"), sim, contact, model.contact,
                                title=case.name)
        out["crack_pattern"] = "crack_pattern.png"
        out.update(_cracked_bricks(d["bricks"]))
    elif getattr(model, "contact", None) is not None and sim is not None:  # no figure: the count all the same
        from .output.figures import brick_cracks
        out.update(_cracked_bricks(brick_cracks(contact, model.contact)))
    if case.output.get("line_of_thrust") and case.dimension == 2 and model.contact is not None:
        from .output.figures import write_line_of_thrust
        d = write_line_of_thrust(os.path.join(out_dir, "line_of_thrust.png"), sim, contact, model.contact,
                                 names=model.names, title=case.name)
        out["line_of_thrust"] = dict(png="line_of_thrust.png", joints=d["n_joints"], compressed=d["n_compressed"],
                                     outside=d["outside"])
    if case.output.get("rotations") and "time" in hist:  # [output] rotations: the rotations against time
        from .output.figures import write_rotations
        write_rotations(os.path.join(out_dir, "rotations.png"), hist, stages, title=case.name)
        out["rotations_png"] = "rotations.png"
    cv = case.output.get("curve")
    if cv:
        body, fk, dk = cv["body"], f"R{cv['force']}", f"u{cv['displacement']}"
        if f"{body}.{fk}" not in hist:
            return out
        note = ""
        if conv and conv.get("unconverged_steps"):
            note = (f"{conv['unconverged_steps']} unconverged steps (x){' (accepted)' if conv['accepted'] else ''}: "
                    f"worst residual {conv['worst_residual']:.3g} at step {conv['worst_step']} "
                    f"(t = {conv['worst_time']:.4g} s)")
        refs = getattr(case, "references", None)  # [[reference]] entries (a Case has them; a stand-in may not)
        c = curve_data(hist, body, fk, dk)
        cyc = _cycles(hist, body, fk, dk, out_dir, case.name)
        pp = None if cyc else post_peak(c["x"], c["y"])  # monotone curves: the softening branch, read once
        write_curve(os.path.join(out_dir, "force_displacement.png"), hist, body, fk, dk, title=case.name, note=note,
                    references=refs, softening=pp)
        if pp is not None:
            out["post_peak"] = post_peak_summary(pp, _unit_key(c["xunit"]), _unit_key(c["yunit"]),
                                                 "rotation" if cv["displacement"].startswith("r") else "displacement")
        if refs:  # model peak vs each [[reference]] (output/summary.reference_comparison)
            from .output.figures import reference_data
            from .output.summary import reference_comparison
            out["reference"] = [reference_comparison(c["x"], c["y"], r, _unit_key(c["yunit"]), _unit_key(c["xunit"]),
                                                     "rotation" if cv["displacement"].startswith("r") else
                                                     "displacement") for r in reference_data(refs, fk, dk)]
        out.update(cyc)
        F, D = np.abs(c["y"]), np.abs(c["x"])  # the peak: largest |force|; magnitudes, as before
        if F.size == 0 or not np.any(np.isfinite(F)):
            return out
        k = int(np.nanargmax(F))
        fu, du = _unit_key(c["yunit"]), _unit_key(c["xunit"])
        fname = "peak_moment" if cv["force"].startswith("r") else "peak_force"
        dname = "rotation" if cv["displacement"].startswith("r") else "displacement"
        out[f"{fname}_{fu}"] = float(F[k])
        out[f"{dname}_at_peak_{du}"] = float(D[k])
        others = [col for col in hist if col.startswith(f"{body}.R") and col != f"{body}.{fk}"]
        out["other_reactions_at_peak_kN"] = {col: float(hist[col][k] * dof_unit(col.split(".", 1)[1])[0])
                                             for col in others if not col.split(".", 1)[1][1:].startswith("r")}
        moments = {col: float(hist[col][k] * dof_unit(col.split(".", 1)[1])[0])
                   for col in others if col.split(".", 1)[1][1:].startswith("r")}
        if moments:
            out["other_moments_at_peak_kNm"] = moments
        sel = (F > 0) & (F <= 0.4 * F[k]) & (D > 0) & _virgin(c["x"])
        out[f"initial_stiffness_{fu}_per_{du}"] = float(np.polyfit(D[sel], F[sel], 1)[0]) \
            if sel.sum() >= 3 else None
        if cv["force"] == "x":
            out["peak_horizontal_force_kN"] = out["peak_force_kN"]
            out["vertical_force_at_peak_kN"] = _vertical_force(case, hist, body, k)
        out["force_displacement"] = "force_displacement.png"
    return out
