"""Running-bond walls of deformable bricks under gravity (dry joints, velocity reset, theta = 1):
setup time, wall-clock per step and its split, NLGS sweeps, contacts, contact updates per second.

Usage: .venv/bin/python bench/bench_wall.py [n_bricks ...]   (default: 100 1000)
"""
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


def wall(n_bricks, steps=int(os.environ.get("BENCH_STEPS", 50)), h=1e-3):
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
    cs = ContactStep([InterfaceSpec("j", ("b", "b"), mu=0.7), InterfaceSpec("f", ("b", "g"), mu=0.7)],
                     ["b"] * len(bodies) + ["g"], ContactOptions(tol=1e-4, max_sweeps=1000))
    sim = Simulation(bodies + [floor], h=h, theta=1.0, contact=cs, velocity_reset=True)
    t_build = time.perf_counter() - t0
    sim.step()  # first step: scene, detection, W_bb, Delassus, then a cold NLGS solve
    t_setup = t_build + cs.timers["detection"]  # detection timer includes W_bb and the Delassus assembly
    for k in cs.timers:
        cs.timers[k] = 0.0
    sweeps = 0
    t1 = time.perf_counter()
    for _ in range(steps):
        info = sim.step()
        sweeps += info.contact["sweeps"]
    dt = (time.perf_counter() - t1) / steps
    nc = info.contact["contacts"]
    weight = sum(1800.0 * b.length * b.height * 0.12 for b in blocks) * 9.81
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    tm = {k: v / steps * 1e3 for k, v in cs.timers.items()}
    return dict(bricks=len(blocks), contacts=nc, setup_s=t_setup, ms_per_step=dt * 1e3,
                sweeps_per_step=sweeps / steps, us_per_update=cs.timers["nlgs"] / max(sweeps * nc, 1) * 1e6 * steps / steps,
                split=tm, floor_reaction_over_weight=floor.reaction[1] / weight, rss_mb=rss)


if __name__ == "__main__":
    sizes = [int(a) for a in sys.argv[1:]] or [100, 1000]
    print("| bricks | contacts | setup [s] | ms/step | sweeps/step | NLGS µs/update | split ms/step (local, nlgs, "
          "correction) | floor reaction / weight | peak RSS [MB] |")
    print("|---|---|---|---|---|---|---|---|---|")
    for n in sizes:
        r = wall(n)
        s = r["split"]
        print(f"| {r['bricks']} | {r['contacts']} | {r['setup_s']:.2f} | {r['ms_per_step']:.1f} | "
              f"{r['sweeps_per_step']:.1f} | {r['us_per_update']:.3f} | {s['local']:.1f}, {s['nlgs']:.1f}, "
              f"{s['correction']:.1f} | {r['floor_reaction_over_weight']:.6f} | {r['rss_mb']:.0f} |", flush=True)
