"""Cost of the co-rotational kinematics per step (issue 22: at most 10 % more): updated contact geometry, the same
model run with `Simulation(corotational=False)` (linear kinematics) and `corotational=True` (a frame per block,
docs/method.md §7), alternately, a window of steps after a warm-up.

Models: benchmark 1 (`bench1`: LMGC90's 43-brick wall of bench_lmgc90_wall.py, h = 1e-4 s, θ = 0.505, dynamic) and
the running-bond walls of bench_wall.py (`wall N`, N bricks, benchmark 1's dynamic settings h = 1e-4 s, θ = 0.505, no
velocity reset, as `bench_wall.py --dynamic`), both with `[contact] geometry = "updated"`, redetect_every 1.

Reported per run: wall-clock and CPU (process) time per step, the part spent in the frame kinematics (the start of
step: centroids, ω, gravity in the frames; the end: re-basing), the contact step's timers, NLGS sweeps per step.

Usage: .venv/bin/python bench/bench_corotational.py bench1 [--steps 300] [--warmup 20] [--repeat 2]
       .venv/bin/python bench/bench_corotational.py wall 10000 [--steps 5] [--warmup 2] [--repeat 1]
"""
import argparse
import functools
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(__file__))


def build_bench1(corotational):
    from bench_lmgc90_wall import build
    sim, cs, *_ = build(geometry="updated", corotational=corotational)
    return sim, cs


def build_wall(n, corotational):
    import bench_wall
    sim, cs, *_ = bench_wall.build(n, "dry", h=1e-4, theta=0.505, velocity_reset=False, geometry="updated",
                                   corotational=corotational)
    return sim, cs


def run(build, corotational, steps, warmup):
    sim, cs = build(corotational)
    assert sim.corotational == corotational
    t_frame = [0.0]
    for name in ("_frame_start", "_frame_update"):
        orig = getattr(sim, name)

        def timed(*a, _orig=orig):
            c = time.perf_counter()
            _orig(*a)
            t_frame[0] += time.perf_counter() - c
        setattr(sim, name, timed)
    for _ in range(warmup):
        sim.step()
    for k in cs.timers:
        cs.timers[k] = 0.0
    t_frame[0] = 0.0
    sweeps = []
    w0, c0 = time.perf_counter(), time.process_time()
    for _ in range(steps):
        info = sim.step()
        sweeps.append(info.contact["sweeps"])
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    rot = max((abs(np.asarray(b.rotation())).max() for b in sim.bodies if b.kind == 0), default=0.0)
    return dict(wall_ms=wall / steps * 1e3, cpu_ms=cpu / steps * 1e3, frame_ms=t_frame[0] / steps * 1e3,
                timers={k: v / steps * 1e3 for k, v in cs.timers.items()}, sweeps=float(np.mean(sweeps)),
                contacts=info.contact["contacts"], dofs=sum(b.type.ndof for b in sim.bodies if b.kind == 0),
                max_rotation=rot)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", choices=("bench1", "wall"))
    ap.add_argument("n", nargs="?", type=int, default=10000, help="bricks of the wall model")
    ap.add_argument("--steps", type=int, default=None)
    ap.add_argument("--warmup", type=int, default=None)
    ap.add_argument("--repeat", type=int, default=None, help="alternating (linear, co-rotational) pairs")
    a = ap.parse_args()
    if a.model == "bench1":
        build, steps, warmup, repeat = build_bench1, a.steps or 300, a.warmup or 20, a.repeat or 2
    else:
        build, steps, warmup, repeat = (functools.partial(build_wall, a.n), a.steps or 5, a.warmup or 2,
                                        a.repeat or 1)
    print(f"load average at start: {os.getloadavg()}")
    print("| run | kinematics | contacts | dofs | ms/step (wall) | ms/step (CPU) | frame kinematics ms/step | "
          "detection+Delassus | local | NLGS | correction | sweeps/step | largest rotation [rad] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for k in range(repeat):
        for cor in (False, True):
            r = run(build, cor, steps, warmup)
            t = r["timers"]
            print(f"| {k + 1} | {'co-rotational' if cor else 'linear'} | {r['contacts']} | {r['dofs']} | "
                  f"{r['wall_ms']:.2f} | {r['cpu_ms']:.2f} | {r['frame_ms']:.3f} | {t['detection']:.2f} | "
                  f"{t['local']:.2f} | {t['nlgs']:.2f} | {t['correction']:.2f} | {r['sweeps']:.1f} | "
                  f"{r['max_rotation']:.2e} |", flush=True)
    print(f"load average at end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
