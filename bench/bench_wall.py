"""Scaling: running-bond walls of deformable bricks under gravity, run to equilibrium (speed issue, benchmark 2).

Each wall: bricks 0.25 × 0.06 m (Q1, 0.03 m, lumped mass, E = 5 GPa), about twice as wide as high, on a rigid
fixed floor; θ = 1 with velocity reset (quasi-static), h = 1e-3 s, NLGS tolerance 1e-4 on the change, at most
1000 sweeps per step. Joints: dry (Coulomb μ = 0.7) or Frémond–Cangémi (`--joints fremond`: c_N = 0.5e10,
c_T = 0.3e10 N/m³, w = 18 J/m², μ = 0.7; the floor joint stays dry).

Reported per wall:
* setup: building the bodies (meshing and factoring each block type once, placing instances) + the first
  step's scene, detection, boundary Delassus blocks W_bb and Delassus assembly (not the first solve);
* the transient: steps to equilibrium (floor reaction = weight within 1e-3 and at most 2 sweeps per step over
  5 consecutive steps; cap `--max-steps`), the step from which the floor reaction stays within 1e-3 of the weight
  until the end of the transient, its wall time and sweeps (`--trace CSV`: one row per transient step);
* the cost of a step at equilibrium (mean over 20 steps after it): ms/step, sweeps/step, NLGS µs per contact
  update and the split (local quantities, NLGS, velocity correction);
* peak RSS, the floor reaction / weight at the end.
With several sizes it fits the exponent a of cost ∝ contacts^a (least squares in log–log) for the time per step at
equilibrium, the time per sweep and the time to equilibrium.

`--coarse interfaces`: two-level NLGS ([contact] coarse, solver/coarse.py; dry joints).

Usage: .venv/bin/python bench/bench_wall.py [n_bricks ...] [--joints dry|fremond] [--max-steps N]
[--coarse none|interfaces] [--trace CSV]
(default sizes 100 1000; 10000 takes several minutes and about 1 GB).
"""
import argparse
import os
import resource
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
from fem_blocks import builders  # noqa: E402
from fem_blocks.bodies import BlockType, DeformableBody, Driver, Material, RigidBody  # noqa: E402
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec  # noqa: E402
from fem_blocks.dynamics import Simulation  # noqa: E402
from fem_blocks.meshing import mesh_rectangle  # noqa: E402

FREMOND = dict(c_N=0.5e10, c_T=0.3e10, w=18.0, mu=0.7)


def build(n_bricks, joints="dry", h=1e-3, theta=1.0, velocity_reset=True, coarse="none", max_sweeps=1000,
          geometry="frozen", corotational=None):
    """The wall, its floor, the contact step and the simulation; returns (sim, cs, floor, blocks, weight, t_build)."""
    per = max(2, int(round(np.sqrt(n_bricks * 0.25 / 0.5))))  # about twice as wide as high (in bricks)
    courses = max(1, int(round(n_bricks / per)))
    t0 = time.perf_counter()
    blocks = builders.running_bond(courses, per, 0.25, 0.06)
    mat = Material(E=5e9, nu=0.2, rho=1800.0, thickness=0.12)
    types, bodies = {}, []
    for b in blocks:
        if b.size_key not in types:
            types[b.size_key] = BlockType(mesh_rectangle(b.length, b.height, 0.03, cell="quad"), mat)
        bodies.append(DeformableBody(types[b.size_key], (b.x, b.y)))
    W = per * 0.25
    floor = RigidBody([(-0.1, -0.2), (W + 0.1, -0.2), (W + 0.1, 0), (-0.1, 0)],
                      drivers={k: Driver("velocity", 0.0) for k in ("x", "y", "rz")})
    joint = (InterfaceSpec("j", ("b", "b"), mu=0.7) if joints == "dry" else
             InterfaceSpec("j", ("b", "b"), law="fremond", params=dict(FREMOND)))
    cs = ContactStep([joint, InterfaceSpec("f", ("b", "g"), mu=0.7)],
                     ["b"] * len(bodies) + ["g"], ContactOptions(tol=1e-4, max_sweeps=max_sweeps, coarse=coarse,
                                                                geometry=geometry))
    sim = Simulation(bodies + [floor], h=h, theta=theta, contact=cs, velocity_reset=velocity_reset,
                     corotational=corotational)
    t_build = time.perf_counter() - t0
    weight = sum(1800.0 * b.length * b.height * 0.12 for b in blocks) * 9.81
    return sim, cs, floor, blocks, weight, t_build


def wall_dynamic(n_bricks, joints="dry", steps=200):
    """Dynamic run with benchmark 1's settings (h = 1e-4 s, θ = 0.505, no velocity reset), `steps` steps from
    rest: the cost per step of a dynamic simulation (the wall does not reach equilibrium in that time)."""
    sim, cs, floor, blocks, weight, t_build = build(n_bricks, joints, h=1e-4, theta=0.505, velocity_reset=False)
    info = sim.step()  # setup step (scene, detection, W_bb, Delassus), not timed below
    t_setup = t_build + cs.timers["detection"]
    for k in cs.timers:
        cs.timers[k] = 0.0
    sweeps, smax, limit = [], 0, 0
    t1 = time.perf_counter()
    for _ in range(steps):
        info = sim.step()
        sweeps.append(info.contact["sweeps"])
        limit += int(not info.contact.get("converged", True))
    dt = (time.perf_counter() - t1) / steps
    nc = info.contact["contacts"]
    tm = {k: v / steps * 1e3 for k, v in cs.timers.items()}
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return dict(bricks=len(blocks), contacts=nc, setup_s=t_setup, steps=steps, ms_per_step=dt * 1e3,
                sweeps_per_step=float(np.mean(sweeps)), max_sweeps=int(np.max(sweeps)), limit_steps=limit,
                us_per_update=cs.timers["nlgs"] / max(sum(sweeps) * nc, 1) * 1e6, split=tm,
                floor_reaction_over_weight=floor.reaction[1] / weight, rss_mb=rss)


def wall(n_bricks, joints="dry", h=1e-3, max_steps=300, steady_steps=20, coarse="none", trace=None,
         max_sweeps=1000):
    sim, cs, floor, blocks, weight, t_build = build(n_bricks, joints, h=h, coarse=coarse, max_sweeps=max_sweeps)

    t1 = time.perf_counter()
    info = sim.step()  # first step: scene, detection, W_bb, Delassus, then a cold NLGS solve
    t_setup = t_build + cs.timers["detection"]  # the detection timer includes W_bb and the Delassus assembly
    sweeps, quiet, steps = info.contact["sweeps"], 0, 1
    limit_steps = int(not info.contact.get("converged", True))
    rows = [(1, info.contact["sweeps"], floor.reaction[1] / weight, time.perf_counter() - t1)]
    while steps < max_steps and quiet < 5:
        c = time.perf_counter()
        info = sim.step()
        steps += 1
        sweeps += info.contact["sweeps"]
        limit_steps += int(not info.contact.get("converged", True))
        rows.append((steps, info.contact["sweeps"], floor.reaction[1] / weight, time.perf_counter() - c))
        ok = abs(floor.reaction[1] / weight - 1.0) < 1e-3 and info.contact["sweeps"] <= 2
        quiet = quiet + 1 if ok else 0
    t_eq = time.perf_counter() - t1
    out = [k for k, _, rw, _ in rows if abs(rw - 1.0) >= 1e-3]
    within = 1 if not out else (out[-1] + 1 if out[-1] < steps else None)  # reaction within 1e-3 from this step on
    if trace:
        with open(trace, "a") as f:
            f.writelines(f"{n_bricks},{cs.opts.coarse},{k},{s},{rw:.7f},{dt:.4f}\n" for k, s, rw, dt in rows)
    for k in cs.timers:
        cs.timers[k] = 0.0
    s_sweeps = 0
    t2 = time.perf_counter()
    for _ in range(steady_steps):
        info = sim.step()
        s_sweeps += info.contact["sweeps"]
    dt = (time.perf_counter() - t2) / steady_steps
    nc = info.contact["contacts"]
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    tm = {k: v / steady_steps * 1e3 for k, v in cs.timers.items()}
    return dict(bricks=len(blocks), contacts=nc, setup_s=t_setup, eq_steps=steps if quiet >= 5 else None, within=within,
                steps=steps, eq_s=t_eq, eq_sweeps=sweeps, limit_steps=limit_steps, ms_per_step=dt * 1e3,
                sweeps_per_step=s_sweeps / steady_steps,
                us_per_update=cs.timers["nlgs"] / max(s_sweeps * nc, 1) * 1e6,
                ms_per_sweep=cs.timers["nlgs"] / max(s_sweeps, 1) * 1e3,
                split=tm, floor_reaction_over_weight=floor.reaction[1] / weight, rss_mb=rss)


def fit_exponent(x, y):
    """Least-squares slope a of log y = a log x + b."""
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def split_text(r):
    s = r["split"]
    return f"{s['local']:.1f}, {s['nlgs']:.1f}, {s['correction']:.1f}"


def table(sizes, run, header, row, exponents):
    """One markdown row per wall size (run(n) -> result dict, row(r) -> cells), then the fitted exponents
    (label, key) of cost ∝ contacts^a."""
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    rows = []
    for n in sizes:
        rows.append(run(n))
        print("| " + " | ".join(row(rows[-1])) + " |", flush=True)
    if len(rows) >= 2:
        c = [r["contacts"] for r in rows]
        print("\nexponents vs contacts: " + ", ".join(f"{label} {fit_exponent(c, [r[key] for r in rows]):.2f}"
                                                     for label, key in exponents))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sizes", nargs="*", type=int, default=[100, 1000])
    ap.add_argument("--joints", choices=("dry", "fremond"), default="dry")
    ap.add_argument("--max-steps", type=int, default=300)
    ap.add_argument("--trace", metavar="CSV", help="append one row per transient step: bricks, coarse, step, sweeps, "
                    "floor reaction / weight, step time [s]")
    ap.add_argument("--coarse", choices=("none", "interfaces"), default="none",
                    help="[contact] coarse: two-level NLGS (coarse correction per interface, dry joints)")
    ap.add_argument("--h", type=float, default=1e-3, help="time step of the quasi-static steps [s] (default 1e-3)")
    ap.add_argument("--max-sweeps", type=int, default=1000, help="NLGS sweep cap per step (default 1000)")
    ap.add_argument("--dynamic", type=int, default=0, metavar="STEPS",
                    help="instead: STEPS dynamic steps with benchmark 1's settings (h = 1e-4 s, theta = 0.505)")
    a = ap.parse_args()
    print(f"joints: {a.joints}, coarse: {a.coarse}" + ("" if a.dynamic else f", h = {a.h:g} s, sweep cap {a.max_sweeps}"))
    if a.dynamic:
        print(f"dynamic: h = 1e-4 s, theta = 0.505, {a.dynamic} steps from rest\n")
        table(a.sizes, lambda n: wall_dynamic(n, a.joints, a.dynamic),
              ["bricks", "contacts", "setup [s]", "ms/step", "sweeps/step (max; steps at the sweep limit)",
               "NLGS µs/update", "split ms/step (local, nlgs, correction)", "floor reaction / weight at the end",
               "peak RSS [MB]"],
              lambda r: [f"{r['bricks']}", f"{r['contacts']}", f"{r['setup_s']:.2f}", f"{r['ms_per_step']:.1f}",
                         f"{r['sweeps_per_step']:.1f} ({r['max_sweeps']}; {r['limit_steps']})",
                         f"{r['us_per_update']:.3f}", split_text(r), f"{r['floor_reaction_over_weight']:.4f}",
                         f"{r['rss_mb']:.0f}"],
              [("time per step", "ms_per_step"), ("sweeps per step", "sweeps_per_step")])
    else:
        table(a.sizes, lambda n: wall(n, a.joints, h=a.h, max_steps=a.max_steps, coarse=a.coarse, trace=a.trace,
                                             max_sweeps=a.max_sweeps),
              ["bricks", "contacts", "setup [s]", "steps to equilibrium", "reaction within 1e-3 from step",
               "time to equilibrium [s] (sweeps; steps at the sweep limit)", "ms/step at equilibrium", "sweeps/step",
               "ms/sweep", "NLGS µs/update", "split ms/step (local, nlgs, correction)", "floor reaction / weight",
               "peak RSS [MB]"],
              lambda r: [f"{r['bricks']}", f"{r['contacts']}", f"{r['setup_s']:.2f}",
                         f"{r['eq_steps']}" if r["eq_steps"] is not None else f"not reached in {r['steps']}",
                         f"{r['within']}" if r["within"] is not None else "-",
                         f"{r['eq_s']:.1f} ({r['eq_sweeps']}; {r['limit_steps']})", f"{r['ms_per_step']:.1f}",
                         f"{r['sweeps_per_step']:.1f}", f"{r['ms_per_sweep']:.2f}", f"{r['us_per_update']:.3f}",
                         split_text(r), f"{r['floor_reaction_over_weight']:.6f}", f"{r['rss_mb']:.0f}"],
              [("time per step at equilibrium", "ms_per_step"), ("time per sweep", "ms_per_sweep"),
               ("time to equilibrium", "eq_s"), ("setup", "setup_s")])
