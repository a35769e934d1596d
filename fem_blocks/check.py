"""`fem-blocks check CASE.toml`: validate a case and say what would be built, without running it.

Everything a run checks before its first step is done (the case file, the generated geometry (expand.py), the
meshes, the bodies, the contact detection at the start with its overlap checks); the report lists the bodies, groups, block types, interfaces
(with the contact points found at the start), the openings as built, the stages with their nominal times and the
histories they apply, and every warning a run would print at its start (docs/case-files.md "Checking a case").
"""
from __future__ import annotations

from collections import Counter

import numpy as np

from .case import Case, active_histories, load_case, nominal_stage_times
from .case import quick as make_quick


def _g(v: float) -> str:
    return f"{v:.6g}"


def _placement(placement, dimension: int) -> str:
    """The placement a run uses: the key's value, or the default of the dimension (contact/step.py)."""
    if placement is not None:
        return placement
    return "overlap (default)" if dimension == 2 else "positions (default)"


def check_case(path: str, quick: bool = False) -> tuple[list[str], list[str]]:
    """(report lines, warnings) for the case file at `path`; raises InputError as `fem-blocks run` would."""
    from .dynamics import Simulation
    from .errors import InputError
    from .expand import expand
    from .model import build_model, groups_without_interface
    from .lab import check_lines, load_lab
    lab = load_lab(path)
    if lab is not None:  # a [lab] file: every specimen's case, validated as a run would (fem_blocks/lab)
        return check_lines(lab), [w for _, c, _ in lab.specimens for w in c.warnings]
    case = load_case(path)
    if quick:
        case = make_quick(case)
    try:
        case = expand(case)  # the generated geometry, its notes (openings as built) and warnings
        model = build_model(case)
        st0 = case.stages[0]
        sim = Simulation(model.bodies, h=st0.h, theta=st0.theta, gravity=model.gravity,
                         velocity_reset=st0.velocity_reset, contact=model.contact)
        warnings = list(case.warnings) + groups_without_interface(case, model, sim)
        per_interface = model.contact.initial_contacts(sim) if model.contact is not None else {}
        from .runner import gauge_points, joint_pairs, rotation_bodies
        rotation_bodies(case, model)  # [output] rotations: names matched to the built blocks, as a run does
        joint_pairs(case, model)  # [output] joints: likewise
        gauge_points(case, model)  # [output] gauges: blocks matched and points located, likewise
    except InputError as e:  # found while building the model (meshes, overlaps): name the case file
        msg = str(e)
        raise InputError(msg if msg.startswith(case.source) else f"{case.source}: {msg}") from None
    return _report(case, model, per_interface), warnings


def _report(case: Case, model, per_interface: dict) -> list[str]:
    L = []
    L.append(f"case {case.source}: {case.name!r}, dimension {case.dimension}, units {case.units!r} (reported in SI: "
             "m, s, N)" + (f", variant {case.variant}" if case.variant else ""))
    nd = sum(b.kind == 0 for b in model.bodies)
    ndof = sum(b.type.ndof for b in model.bodies if b.kind == 0)
    L.append(f"bodies: {len(model.bodies)} ({nd} deformable blocks of {len(model.block_types)} block types, "
             f"{len(model.bodies) - nd} rigid bodies), {ndof} deformable dofs")
    kinds = {}
    for b, g in zip(model.bodies, model.groups):
        kinds.setdefault(g, Counter())["deformable" if b.kind == 0 else "rigid"] += 1
    L.append("groups: " + "; ".join(f"{g!r} " + ", ".join(f"{n} {k}" for k, n in sorted(c.items()))
                                      for g, c in kinds.items()))
    for name, bt in model.block_types.items():
        spec = case.block_types[name]
        n = sum(1 for b in model.bodies if b.kind == 0 and b.type is bt)
        P = bt.mesh.points
        ext = " x ".join(_g(v) for v in (P.max(axis=0) - P.min(axis=0)))
        L.append(f"block type {name!r}: {spec.geometry}, {ext} m, material {spec.material!r}, "
                 f"{len(bt.mesh.cells)} {bt.mesh.cell_type} elements, {len(P)} nodes; {n} block(s)")
    for r in case.rigid_bodies:
        V = np.asarray(r.vertices, dtype=float)
        ext = " x ".join(_g(v) for v in (V.max(axis=0) - V.min(axis=0)))
        mass = "no mass (fixed or fully driven)" if r.rho is None and r.mass is None else \
            (f"rho {_g(r.rho)} kg/m^3" if r.rho is not None else f"mass {_g(r.mass)} kg")
        piv = [(d, s.pivot) for d, s in r.drivers.items() if getattr(s, "pivot", None) is not None]
        driven = sorted(set(r.drivers) | (set(case.dofs[:case.dimension]) if piv else set()))
        L.append(f"rigid body {r.name!r} (group {r.group!r}): {ext} m, {mass}; driven dofs "
                 f"{driven or 'none'}" + (f" ({piv[0][0]} about the pivot {list(piv[0][1])} m, which drives "
                                          f"{', '.join(case.dofs[:case.dimension])})" if piv else ""))
    moving = [(b.name, b.initial_velocity, b.initial_spin) for b in list(case.blocks) + list(case.rigid_bodies)
              if b.initial_velocity is not None or b.initial_spin is not None]
    for name, v, w in moving[:5]:
        L.append(f"initial motion of {name!r}: velocity {list(v) if v is not None else 0} m/s, spin "
                 f"{(list(w) if isinstance(w, tuple) else w) if w is not None else 0} rad/s")
    if len(moving) > 5:
        L.append(f"initial motion: {len(moving) - 5} more bodies")
    if not case.interfaces:
        L.append("interfaces: none (bodies do not interact)")
    for itf in case.interfaces:
        pars = ", ".join(f"{k} = {_g(v) if isinstance(v, float) else v}" for k, v in itf.params.items())
        L.append(f"interface {itf.name!r}: {itf.groups[0]} / {itf.groups[1]}, law {itf.law}, mu = {_g(itf.mu)}"
                 + (f", {pars}" if pars else "") + f", g0 = {_g(itf.g0)} m, alert = {_g(itf.alert)} m, "
                 f"orientation {itf.orientation}, placement {_placement(itf.placement, case.dimension)}; "
                 f"{per_interface.get(itf.name, 0)} contact points at the start")
    if case.allow_no_interface:
        L.append("allowed without interface: " + ", ".join(f"{a} / {b}" for a, b in case.allow_no_interface))
    for note in case.notes:
        L.append("opening: " + note.split(": ", 1)[-1])
    times = nominal_stage_times(case)
    L.append(f"stages: {len(case.stages)}; history times {case.history_times!r}"
             + (" (from the start of the run)" if case.history_times == "absolute" else
                " (stage histories from the stage's start)")
             + "; nominal times: every stage runs its full duration")
    for si, (st, (t0, t1)) in enumerate(zip(case.stages, times)):
        stops = [s for s, on in (("at equilibrium", st.stop_at_equilibrium),
                                 ("at a displacement", st.stop_displacement is not None),
                                 ("at a rotation", st.stop_rotation is not None),
                                 ("after the peak", st.stop_after_peak is not None)) if on]
        L.append(f"stage {si} {st.name!r}: t = {_g(t0)} to {_g(t1)} s, h = {_g(st.h)} s, "
                 f"{max(1, int(round(st.duration / st.h)))} steps, theta = {_g(st.theta)}"
                 + (", velocity reset" if st.velocity_reset else "")
                 + (f"; may stop early {' or '.join(stops)} (later stages then start earlier)" if stops else ""))
        for (body, dof), (lab, kind, h, s) in sorted(active_histories(case, si).items()):
            if s != si and not (si == 0 and s == -1):  # a stage's own histories; the bodies' ones at stage 0
                continue
            if kind == "pivot":
                L.append(f"  {lab}: drives {body}.{dof} (rotation about the pivot)")
                continue
            if isinstance(h, dict):
                off = t0 if case.history_times == "stage" else 0.0
                what = (f"times {_g(h['times'][0] + off)} to {_g(h['times'][-1] + off)} s, values "
                        f"{_g(h['values'][0])} to {_g(h['values'][-1])}"
                        + (f" ({len(h['values'])} knots, between {_g(min(h['values']))} and {_g(max(h['values']))})"
                           if len(h["values"]) > 2 else ""))
            else:
                what = f"constant {_g(h)}"
            if isinstance(h, dict) and "file" in h:
                what += f", from {h['file']}"
            if kind == "acceleration" and isinstance(h, dict) and len(h["times"]) > 1:
                from .records import record_velocity_knots
                T, A = np.asarray(h["times"]), np.asarray(h["values"])
                v = record_velocity_knots(T, A)
                d = float(np.sum(np.diff(T) * 0.5 * (v[:-1] + v[1:])))
                what += f"; at its end the driven velocity is {_g(v[-1])} m/s and the displacement {_g(d)} m"
            L.append(f"  {lab}: {kind}, {what}")
    return L
