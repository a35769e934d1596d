"""Benchmark 1 of the speed issue: LMGC90's deformable-brick wall with a window under gravity.

Full bricks 0.10 x 0.05 m, half bricks 0.05 x 0.05 m, lintel 0.30 x 0.05 m, no joint thickness; 9 courses
(bottom first) [1/2,1,1,1,1,1/2], [1]*5, [1/2,1,1,1,1,1/2], [1]*5, [1/2,1,gap 0.2,1,1/2], [1,1/2,gap 0.2,1/2,1],
[1/2,1,gap 0.2,1,1/2], [1,lintel,1], [1/2,1,1,1,1,1/2]; E = 1e10 Pa, nu = 0.15, rho = 1800 kg/m^3, plane strain,
Q4 of 0.025 m, lumped mass; rigid fixed floor; mu = 0.3 between bricks, 0.5 on the floor; gravity 9.81;
h = 1e-4 s, theta = 0.505, 2000 steps; Gauss-Seidel tolerance 1e-4.

Usage: .venv/bin/python bench/bench_lmgc90_wall.py [steps [placement [history.csv]]]  (placement: overlap
(default), nodes, positions; history.csv: per step, the floor reaction and the mean settlement of the top at full
precision, for bench/compare_outputs.py)
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

G = {"gap": 0.2}
ROWS = [[0.5, 1, 1, 1, 1, 0.5], [1] * 5, [0.5, 1, 1, 1, 1, 0.5], [1] * 5, [0.5, 1, G, 1, 0.5], [1, 0.5, G, 0.5, 1],
        [0.5, 1, G, 1, 0.5], [1, 3, 1], [0.5, 1, 1, 1, 1, 0.5]]


def build(placement=None, geometry="frozen", corotational=None):
    """The benchmark's model -> (sim, contact step, blocks (builder geometry), deformable bodies, floor)."""
    blocks = builders.courses(ROWS, 0.10, 0.05)
    mat = Material(E=1e10, nu=0.15, rho=1800.0, thickness=1.0, plane="strain")
    types, bodies = {}, []
    for b in blocks:
        if b.size_key not in types:
            types[b.size_key] = BlockType(mesh_rectangle(b.length, b.height, 0.025, cell="quad"), mat, mass="lumped")
        bodies.append(DeformableBody(types[b.size_key], (b.x, b.y)))
    floor = RigidBody([(-0.1, -0.1), (0.6, -0.1), (0.6, 0.0), (-0.1, 0.0)],
                      drivers={k: Driver("velocity", 0.0) for k in ("x", "y", "rz")})
    cs = ContactStep([InterfaceSpec("bricks", ("b", "b"), mu=0.3, placement=placement),
                      InterfaceSpec("floor", ("b", "f"), mu=0.5, placement=placement)],
                     ["b"] * len(bodies) + ["f"], ContactOptions(tol=1e-4, max_sweeps=10000, geometry=geometry))
    sim = Simulation(bodies + [floor], h=1e-4, theta=0.505, contact=cs, gravity=(0.0, -9.81),
                     corotational=corotational)
    return sim, cs, blocks, bodies, floor


def main(steps=2000, placement=None, history=None):
    t0 = time.perf_counter()
    sim, cs, blocks, bodies, floor = build(placement)
    info0 = sim.step()
    t_setup = time.perf_counter() - t0
    for k in cs.timers:
        cs.timers[k] = 0.0
    t_free = 0.0
    sweeps = []
    ry = [floor.reaction[1]]  # floor reaction after steps 1, 2, ...
    top = max(b.y + b.height for b in blocks)
    on_top = [np.abs(bd.reference_points[:, 1] - top) < 1e-9 for bd in bodies]

    def settlement():
        return float(np.mean(np.concatenate([bd.displacement_global()[m, 1] for bd, m in zip(bodies, on_top)
                                             if np.any(m)])))
    rows = [(1, sim.time, ry[0], settlement(), info0.contact["contacts"], info0.contact["sweeps"])]
    t1 = time.perf_counter()
    orig = sim.free_velocities

    def timed_free(a, b):
        nonlocal t_free
        c = time.perf_counter()
        orig(a, b)
        t_free += time.perf_counter() - c
    sim.free_velocities = timed_free
    import tempfile
    from fem_blocks.output.contacts import ContactsWriter
    from fem_blocks.output.paraview import BodiesWriter
    tmp = tempfile.TemporaryDirectory()
    t_out = 0.0
    c = time.perf_counter()
    pv = BodiesWriter(sim, tmp.name)  # ParaView output every 100 steps (blocks with stresses, contact points)
    pc = ContactsWriter(tmp.name, 2, locate=cs.contact_points)
    t_out += time.perf_counter() - c
    for k in range(1, steps):
        info = sim.step()
        sweeps.append(info.contact["sweeps"])
        ry.append(floor.reaction[1])
        if history:
            rows.append((k + 1, sim.time, ry[-1], settlement(), info.contact["contacts"], info.contact["sweeps"]))
        if k % 100 == 0 or k == steps - 1:
            c = time.perf_counter()
            pv.write(sim.time)
            pc.write(sim.time, sim.last_contact)
            t_out += time.perf_counter() - c
    wall = time.perf_counter() - t1
    frames = pv.frame
    tmp.cleanup()
    n = steps - 1
    weight = sum(1800.0 * b.length * b.height for b in blocks) * 9.81
    tm = cs.timers
    print(f"bricks {len(blocks)}, block types {len({id(b.type) for b in bodies})}, dofs {sum(b.type.ndof for b in bodies)}, "
          f"contacts {info.contact['contacts']}")
    print(f"setup {t_setup:.2f} s (incl. first step and numba compilation)")
    print(f"per step {wall / n * 1e3:.2f} ms: free velocity {t_free / n * 1e3:.2f}, detection+Delassus "
          f"{tm['detection'] / n * 1e3:.3f}, local {tm['local'] / n * 1e3:.2f}, NLGS {tm['nlgs'] / n * 1e3:.2f}, "
          f"correction {tm['correction'] / n * 1e3:.2f}, ParaView output {t_out / n * 1e3:.3f} "
          f"({frames} frames, {100 * t_out / wall:.1f} % of the run)")
    print(f"whole run (setup + {steps} steps + output): {t_setup + wall:.2f} s")
    print(f"sweeps per step mean {np.mean(sweeps):.1f} max {np.max(sweeps)}; NLGS "
          f"{tm['nlgs'] / max(np.sum(sweeps) * info.contact['contacts'], 1) * 1e6:.3f} µs per contact update")
    if history:
        with open(history, "w") as f:
            f.write("step,time,floor_Ry,top_uy_mean,contacts,sweeps\n")
            f.writelines(",".join(repr(v) for v in r) + "\n" for r in rows)
    uy = [bd.displacement_global()[np.abs(bd.reference_points[:, 1] - top) < 1e-9, 1]
          for bd in bodies if np.any(np.abs(bd.reference_points[:, 1] - top) < 1e-9)]
    last = np.asarray(ry[1500:2000] if steps > 1500 else ry[steps // 2:]) / weight  # steps 1501-2000
    print(f"mean settlement of the top (vertical displacement of the top-edge nodes) "
          f"{np.mean(np.concatenate(uy)):.3e} m; floor reaction / weight over steps "
          f"{1501 if steps > 1500 else steps // 2 + 1}-{min(steps, 2000)}: mean {last.mean():.5f}, "
          f"max - min {100 * (last.max() - last.min()):.3f} %, standard deviation {100 * last.std():.4f} %")
    print(f"floor reaction {floor.reaction[1]:.3f} N vs weight {weight:.3f} N (ratio {floor.reaction[1] / weight:.5f}); "
          f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 2000, sys.argv[2] if len(sys.argv) > 2 else None,
         sys.argv[3] if len(sys.argv) > 3 else None)
