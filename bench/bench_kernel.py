"""NLGS kernel on every FCLIB Coulomb problem (2D and 3D, local and condensed global): contacts, sweeps to the
FCLIB residual ‖F‖/‖q‖ <= 1e-8 (cap 20 000 sweeps, checked every 10), wall time of that solve, µs per contact
update (separate run of a fixed number of sweeps), final residual, and Siconos' figures from
reference_solutions/SUMMARY.json.

Usage: .venv/bin/python bench/bench_kernel.py [--no-write] [--cap N]
Writes the section "## NLGS kernel on FCLIB problems" of docs/benchmarks.md (other sections untouched)
unless --no-write; always prints the table.
"""
import argparse
import datetime
import glob
import json
import os
import platform
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)
from fem_blocks.errors import InputError  # noqa: E402
from fem_blocks.io import fclib  # noqa: E402
from fem_blocks.solver import nlgs  # noqa: E402
from fem_blocks.linalg import to_block_csr  # noqa: E402

FCLIB = os.environ.get("FCLIB_DIR", os.path.join(ROOT, "..", "shared", "data", "fclib"))
HEADING = "## NLGS kernel on FCLIB problems"
# per-problem runs (default: one run, given order, cold start, cap --cap). Larger caps where Gauss-Seidel is slow
# (the two large granular problems get Siconos' NSGS sweep counts); OneObject cycles (period 2) in the given
# order, the shuffled order breaks the cycle; Capsules-i97-269 also warm-started from /guesses/1 (README).
VARIANTS = {
    "OneObject-i100000-316": [dict(), dict(order="shuffled", seed=0)],
    "BoxesStack1-i100000-32": [dict(max_sweeps=300000)],
    "fclib_local_problem_test": [dict(max_sweeps=300000)],
    "spheres-in-a-box-98-i10000-256-10": [dict(max_sweeps=2000000)],
    "fc2d_granularflowonwall_02020_00213": [dict(max_sweeps=500000)],
    "fc2d_granularflowonwall_07002_00801": [dict(max_sweeps=120000)],
    "Capsules-i97-269": [dict(), dict(warm=True)],
}


def machine():
    def sh(cmd):
        try:
            return subprocess.run(cmd, shell=True, capture_output=True, text=True, timeout=10).stdout.strip()
        except Exception:
            return "?"
    import numba
    import scipy
    model = sh("lscpu | grep 'Model name'").split(":", 1)[-1].strip()
    return (f"`nproc` = {sh('nproc')}, {model}; {datetime.date.today().isoformat()}; Python "
            f"{platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}, numba {numba.__version__}")


def run(cap=20000, tol=1e-8):
    ref = {}
    sp = os.path.join(FCLIB, "reference_solutions", "SUMMARY.json")
    if os.path.exists(sp):
        with open(sp) as fh:
            ref = {d["problem"]: d for d in json.load(fh)}
    rows, skipped = [], []
    warmed = set()
    for f in sorted(glob.glob(os.path.join(FCLIB, "**", "*.hdf5"), recursive=True)):
        try:
            p = fclib.read(f)
        except InputError as e:
            skipped.append((os.path.basename(f), str(e).split(": ", 1)[-1]))
            continue
        B = to_block_csr(p.W, p.dim)
        if p.dim not in warmed:  # compile / load the numba cache outside the timings
            nlgs.solve_block_csr(B, p.q, p.mu, max_sweeps=2, criterion="residual", check_every=1)
            warmed.add(p.dim)
        for var in VARIANTS.get(p.name, [dict()]):
            opts = dict(max_sweeps=cap, order="given")
            opts.update(var)
            warm = opts.pop("warm", False)
            if warm:
                opts["r0"] = p.guess_r
            t0 = time.perf_counter()
            res = nlgs.solve_block_csr(B, p.q, p.mu, tol=tol, criterion="residual", check_every=10, **opts)
            t_solve = time.perf_counter() - t0
            # pure kernel cost: a fixed number of sweeps (criterion "change" with a tolerance it cannot reach)
            n_time = int(min(opts["max_sweeps"], max(50, 2e6 // p.n_contacts)))
            topts = dict(opts, max_sweeps=n_time)
            t0 = time.perf_counter()
            rt = nlgs.solve_block_csr(B, p.q, p.mu, tol=1e-300, criterion="change", **topts)
            us = (time.perf_counter() - t0) / (rt.sweeps * p.n_contacts) * 1e6
            if rt.sweeps * p.n_contacts < 10000:  # stopped early (exact solution): the call overhead, not the kernel
                us = None
            R = fclib.residual(p.W, p.q, p.mu, res.r, p.dim)
            r = ref.get(p.name)
            sic_us = None
            if r and r["solver"].startswith("NSGS") and r["iters"] >= 100:
                sic_us = r["time_s"] / (r["iters"] * p.n_contacts) * 1e6
            label = opts["order"] + (", warm start /guesses/1" if warm else "")
            rows.append(dict(problem=p.name, kind=p.kind, dim=p.dim, contacts=p.n_contacts,
                             nnzb=int(B.indices.size), sweeps=res.sweeps, cap=opts["max_sweeps"],
                             converged=res.converged, residual=R.rel_q, rel_max=R.rel_max, t_solve=t_solve,
                             us=us, label=label, ref=r, sic_us=sic_us,
                             cases=None if res.local_cases is None else res.local_cases.tolist()))
            print(f"{p.name} [{label}]: {res.sweeps} sweeps, {R.rel_q:.2e}, {t_solve:.3f} s, {us} us/update",
                  flush=True)
    return rows, skipped


# why a problem does not reach 1e-8 within its cap (printed only for those rows)
REASONS = {
    "OneObject-i100000-316": "in the given order Gauss–Seidel enters a period-2 cycle (the reactions alternate "
                             "exactly between two states, residual 1.7e-3 forever); a shuffled order or ω = 0.7 "
                             "breaks it",
    "spheres-in-a-box-98-i10000-256-10": "slow Gauss–Seidel convergence (hyperstatic packing, rank-deficient W); "
                                         "the residual keeps decreasing (1e-5 at 10⁴, 2.5e-6 at 10⁵, 8e-8 at 10⁶ "
                                         "sweeps); Siconos' NSGS stalls too, its global Newton NSN_AC reaches 1.7e-14",
    "fc2d_granularflowonwall_02020_00213": "Gauss–Seidel stalls near 5e-7, like Siconos' NSGS (4.7e-7 after "
                                           "5·10⁵ sweeps); only a global method goes further",
    "fc2d_granularflowonwall_07002_00801": "Gauss–Seidel stalls near 1e-8, like Siconos' NSGS (1.2e-8 after "
                                           "1.2·10⁵ sweeps)",
}


def kernel_reading(rows):
    """One line against the speed issue's kernel targets (≤ 0.1 µs per 2D contact update, ≤ 0.5 µs per 3D one):
    the range of the timed rows per dimension, and Siconos' NSGS figures where SUMMARY.json has them."""
    parts = []
    for d, target in ((2, 0.1), (3, 0.5)):
        us = [r["us"] for r in rows if r["dim"] == d and r["us"] is not None]
        sic = [r["sic_us"] for r in rows if r["dim"] == d and r["sic_us"] is not None]
        if not us:
            continue
        verdict = "met" if max(us) <= target else "**not met**"
        parts.append(f"{d}D {min(us):.3f}–{max(us):.3f} µs per contact update over {len(us)} timed runs (target "
                     f"≤ {target} µs: {verdict}" + (f"; Siconos NSGS {min(sic):.2f}–{max(sic):.2f} µs on the problems "
                     "where it ran ≥ 100 iterations" if sic else "") + ")")
    return "Kernel cost: " + "; ".join(parts) + "."


def markdown(rows, skipped, cap):
    out = [HEADING, "",
           "`bench/bench_kernel.py` (writes this section): every FCLIB Coulomb problem of `../shared/data/fclib` "
           "(local, and global condensed with W = Hᵀ M⁻¹ H, q = Hᵀ M⁻¹ f + w), cold start r = 0 and contacts in the "
           f"given order unless stated. Sweeps until the FCLIB residual ‖F‖/‖q‖ ≤ 1e-8 (checked every 10 sweeps, cap "
           f"{cap:,} sweeps, raised where Gauss–Seidel is slow: see `VARIANTS` in the script); \"time\" is that solve; µs per contact update from a separate run of a fixed number of sweeps "
           "(includes the per-sweep overhead, which dominates on the tiny problems; — when the problem is solved "
           "exactly in a couple of sweeps, so that fewer than 10⁴ updates could be timed). The residual is recomputed "
           "from the returned reactions with `fclib.residual` (numpy). Siconos' columns are "
           "`reference_solutions/SUMMARY.json` (its best solver at tolerance 1e-12; µs/update only for its NSGS "
           "runs of ≥ 100 iterations).", "",
           f"Machine: {machine()}. Shared machine: expect ±30 %.", "",
           "| problem | kind | d | contacts | W blocks | sweeps | ‖F‖/‖q‖ | ‖F‖/max(‖q‖,‖r‖,‖u‖) | time [s] | "
           "µs / contact update | Siconos: solver, iterations, ‖F‖/‖q‖, time [s] | Siconos NSGS µs / update |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        sw = f"{r['sweeps']:,}" if r["converged"] else f"**{r['sweeps']:,} (cap)**"
        if r["label"] != "given":
            sw += f" ({r['label']})"
        ref = r["ref"]
        sic = (f"{ref['solver']}, {ref['iters']}, {ref['err_rel_q']:.1e}, {ref['time_s']:.3g}" if ref else "—")
        sus = f"{r['sic_us']:.3f}" if r["sic_us"] is not None else "—"
        out.append(f"| {r['problem']} | {r['kind']} | {r['dim']} | {r['contacts']} | {r['nnzb']} | {sw} | "
                   f"{r['residual']:.2e} | {r['rel_max']:.1e} | {r['t_solve']:.3f} | "
                   f"{'—' if r['us'] is None else format(r['us'], '.3f')} | {sic} | {sus} |")
    out += ["", kernel_reading(rows)]
    ok = sorted({r["problem"] for r in rows if r["converged"]})
    bad = [r for r in rows if not r["converged"]]
    out += ["", f"Reach ‖F‖/‖q‖ ≤ 1e-8 ({len(ok)} of {len({r['problem'] for r in rows})} problems, in at least one "
            "of their runs): " + ", ".join(ok) + "."]
    if bad:
        out += ["", "Runs that stop at the cap:"]
        for r in bad:
            out.append(f"* {r['problem']} ({r['label']}, {r['sweeps']:,} sweeps): {r['residual']:.1e} — "
                       f"{REASONS.get(r['problem'], 'no diagnosis recorded')}.")
    out += ["", "3D local solves: the counts of local cases over all sweeps (open, stick, Alart–Curnier Newton, "
            "direction search, projection) show that the Newton step with line search solved every sliding contact "
            "of these problems; the fallbacks are exercised by the random-block tests (tests/test_nlgs.py)."
            if all(r["cases"] is None or (r["cases"][4] == 0 and r["cases"][5] == 0) for r in rows) else
            "3D local solves: some sliding contacts needed the fallbacks: " + ", ".join(
                f"{r['problem']} (search {r['cases'][4]}, projection {r['cases'][5]})" for r in rows
                if r["cases"] is not None and (r["cases"][4] or r["cases"][5])) + "."]
    if skipped:
        out += ["", "Not run: " + "; ".join(f"`{f}` ({why})" for f, why in skipped) + "."]
    return "\n".join(out) + "\n"


def write_section(text, path=os.path.join(ROOT, "docs", "benchmarks.md"), heading=HEADING):
    """Replace the section under `heading` (up to the next '## ' heading) or append it at the end (also used by
    bench_fclib3d with its own heading)."""
    old = open(path).read() if os.path.exists(path) else "# Benchmarks\n"
    lines = old.splitlines(keepends=True)
    start = next((i for i, ln in enumerate(lines) if ln.strip() == heading), None)
    if start is None:
        new = old.rstrip("\n") + "\n\n" + text
    else:
        end = next((j for j in range(start + 1, len(lines)) if lines[j].startswith("## ")), len(lines))
        new = "".join(lines[:start]) + text + ("\n" if end < len(lines) else "") + "".join(lines[end:])
    with open(path, "w") as fh:
        fh.write(new)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--cap", type=int, default=20000)
    a = ap.parse_args()
    rows, skipped = run(cap=a.cap)
    md = markdown(rows, skipped, a.cap)
    print(md)
    if not a.no_write:
        write_section(md)
