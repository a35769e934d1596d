"""Cost of the small-rotation watch (runner._RotationWatch, issue #22) on the running-bond walls of bench_wall.py.

Builds the wall's bodies and Simulation (bench_wall.build), fills every block's q with random values (1e-6 m) and
times `_RotationWatch.check(sim)` (what the runner does after every step of a run whose blocks have no frame):
mean of 50 calls. Compare with the wall's ms/step at equilibrium in docs/benchmarks.md.

Usage: .venv/bin/python bench/bench_rotation_watch.py [n_bricks ...]   (default 1000 10000)
"""
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(__file__))
import bench_wall  # noqa: E402
from fem_blocks.runner import _RotationWatch  # noqa: E402


def main(sizes):
    for n in sizes:
        sim = bench_wall.build(n)[0]
        ndof = sum(g.Q.size for g in sim.groups)
        watch = _RotationWatch(sim, [f"b{i}" for i in range(len(sim.bodies))])
        rng = np.random.default_rng(0)
        for g in sim.groups:
            g.Q[:] = rng.standard_normal(g.Q.shape) * 1e-6
        watch.check(sim)
        k = 50
        t0 = time.perf_counter()
        for _ in range(k):
            watch.check(sim)
        ms = (time.perf_counter() - t0) / k * 1e3
        print(f"{n} bricks: {len(sim.bodies)} bodies, {ndof} dofs, {len(sim.groups)} block types: "
              f"{ms:.3f} ms per check", flush=True)


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [1000, 10000])
