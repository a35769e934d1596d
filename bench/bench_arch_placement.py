"""Collapse (limit) thickness of the shipped arch (demos/arch.toml) for several mesh sizes and placements.

The demo's geometry and settings (semicircular arch, intrados radius 1 m, 15 voussoirs, rigid piers, mu = 0.5,
E = 1e10 Pa, rho = 2000 kg/m^3, theta = 1, h = 2e-3 s, NLGS tol 1e-8) with the ring depth t changed and the
mesh size a fixed fraction of t. A run "stands" when the crown (middle voussoir) has dropped by less than
1 mm after `duration` seconds of gravity (an elastic arch settles by ~1e-6 m; a mechanism 1 % past its limit
drops by centimetres in 0.5 s), "collapses" otherwise (the run stops as soon as the drop passes 1 mm).
Bisection on t between `lo` (collapses) and `hi` (stands) until hi/lo - 1 <= rtol.

Usage: .venv/bin/python bench/bench_arch_placement.py [--divisors 2 8] [--placement nodes] [--rtol 0.005]
                                                     [--lo 0.08] [--hi 0.2] [--duration 0.6]
"""
import argparse
import os
import sys
import time
import tomllib

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
from fem_blocks.case import parse_case  # noqa: E402
from fem_blocks.expand import expand  # noqa: E402
from fem_blocks.dynamics import Simulation  # noqa: E402
from fem_blocks.model import build_model  # noqa: E402

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
DROP = 1e-3  # [m] crown drop that marks a collapse


def arch_stands(t, divisor, placement=None, duration=0.6):
    """True if the demo arch with ring depth t [m] and mesh size t/divisor stands after `duration` s."""
    with open(os.path.join(ROOT, "demos", "arch.toml"), "rb") as f:
        doc = tomllib.load(f)
    doc["arch"]["ring_depth"] = float(t)
    doc["arch"]["mesh_size"] = float(t) / divisor
    if placement is not None:
        for itf in doc["interfaces"]:
            itf["placement"] = placement
    case = expand(parse_case(doc, "arch.toml"))
    model = build_model(case)
    st = case.stages[0]
    sim = Simulation(model.bodies, h=st.h, theta=st.theta, gravity=model.gravity,
                     velocity_reset=st.velocity_reset, contact=model.contact)
    crown = model.bodies[model.index(f"voussoir{len(case.blocks) // 2}")]
    for _ in range(int(round(duration / st.h))):
        sim.step()
        if -crown.displacement_global()[:, 1].mean() > DROP:
            return False
    return True


def limit_thickness(divisor, placement=None, lo=0.08, hi=0.2, rtol=0.005, duration=0.6, log=print):
    """Bisection (geometric mean) on t: returns (lo, hi) with lo collapsing, hi standing, hi/lo - 1 <= rtol."""
    while hi / lo - 1 > rtol:
        t = float(np.sqrt(lo * hi))
        c = time.perf_counter()
        ok = arch_stands(t, divisor, placement, duration)
        log(f"  t = {t:.5f} m, mesh t/{divisor}: {'stands' if ok else 'collapses'} ({time.perf_counter() - c:.1f} s)")
        if ok:
            hi = t
        else:
            lo = t
    return lo, hi


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--divisors", type=float, nargs="+", default=[2, 8])
    ap.add_argument("--placement", default=None, help="interface placement (default: the case-file default)")
    ap.add_argument("--lo", type=float, default=0.08)
    ap.add_argument("--hi", type=float, default=0.2)
    ap.add_argument("--rtol", type=float, default=0.005)
    ap.add_argument("--duration", type=float, default=0.6)
    a = ap.parse_args()
    res = {}
    for d in a.divisors:
        c = time.perf_counter()
        lo, hi = limit_thickness(d, a.placement, a.lo, a.hi, a.rtol, a.duration, log=lambda s: print(s, flush=True))
        res[d] = (lo, hi)
        tm = 0.5 * (lo + hi)
        print(f"mesh t/{d:g}, placement {a.placement or 'default'}: limit t in [{lo:.5f}, {hi:.5f}] m "
              f"(t/R_centre = {tm / (1 + tm / 2):.4f}), {time.perf_counter() - c:.0f} s", flush=True)
    if len(res) > 1:
        m = [0.5 * (lo + hi) for lo, hi in res.values()]
        print(f"spread of the limit thickness: {100 * (max(m) / min(m) - 1):.2f} %")


if __name__ == "__main__":
    main()
