"""NLGS kernel speed on the 2D FCLIB problems: sweeps, time, µs per contact update, residual reached.

Usage: .venv/bin/python bench/bench_kernel.py [--markdown]   (results go to docs/benchmarks.md by hand/run_all)
"""
import glob
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
from fem_blocks.io import fclib  # noqa: E402
from fem_blocks.solver import nlgs  # noqa: E402

FCLIB = os.environ.get("FCLIB_DIR", os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "fclib"))


def run(max_sweeps=20000, tol=1e-8):
    ref = {}
    sp = os.path.join(FCLIB, "reference_solutions", "SUMMARY.json")
    if os.path.exists(sp):
        ref = {d["problem"]: d for d in json.load(open(sp))}
    rows = []
    files = sorted(glob.glob(os.path.join(FCLIB, "**", "*.hdf5"), recursive=True))
    # compile once
    p0 = None
    for f in files:
        try:
            p = fclib.read(f)
        except Exception:
            continue
        if p.dim != 2:
            continue
        if p0 is None:
            nlgs.solve(p.W, p.q, p.mu, max_sweeps=2)
            p0 = p
        B = nlgs.to_block_csr(p.W, 2)
        # timing of pure sweeps: criterion "change" with tol 0 never stops early -> exact sweep count
        n_time = min(max_sweeps, max(200, int(2e6 // p.n_contacts)))
        t = time.perf_counter()
        rt = nlgs.solve_block_csr(B, p.q, p.mu, tol=1e-300, max_sweeps=n_time, criterion="change")
        dt = time.perf_counter() - t
        us = dt / (rt.sweeps * p.n_contacts) * 1e6  # may stop early once the reactions stop changing
        res = nlgs.solve_block_csr(B, p.q, p.mu, tol=tol, max_sweeps=max_sweeps, criterion="residual",
                                   check_every=10)
        r = ref.get(p.name, {})
        rows.append(dict(problem=p.name, kind=p.kind, contacts=p.n_contacts, sweeps=res.sweeps,
                         residual=res.residual, converged=res.converged, us_per_update=us,
                         siconos_solver=r.get("solver"), siconos_residual=r.get("err_rel_q")))
    return rows


def markdown(rows):
    out = ["| problem | kind | contacts | sweeps to 1e-8 (cap 20 000) | ‖F‖/‖q‖ reached | µs / contact update | "
           "Siconos reference (solver, ‖F‖/‖q‖) |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['problem']} | {r['kind']} | {r['contacts']} | {r['sweeps']} | {r['residual']:.2e} | "
                   f"{r['us_per_update']:.3f} | {r['siconos_solver']}, {r['siconos_residual']:.1e} |"
                   if r['siconos_residual'] is not None else
                   f"| {r['problem']} | {r['kind']} | {r['contacts']} | {r['sweeps']} | {r['residual']:.2e} | "
                   f"{r['us_per_update']:.3f} | — |")
    return "\n".join(out)


if __name__ == "__main__":
    rows = run()
    print(markdown(rows))
