"""Cost of one iteration of the interface-law Newton on captured problems (bench/bench_split_step.py capture).

    # re-solve saved problems, one JSON line each: Newton iterations, whole-solve CPU seconds, ms per iteration and
    # its split (cProfile, CPU time): assembly of J, factorisation + solve, evaluations of F (the Jacobian call and
    # the line-search merits), residuals, the rest. --tree DIR imports fem_blocks from DIR (e.g. a worktree of an
    # older commit: the "before"); --superlu sets newton.BLOCK_LU = False (the pivoting SuperLU for every direction)
    python bench/bench_newton_iter.py [--tree DIR] [--superlu] [--no-profile] DIR/call_0012.npz [...]

Times are CPU seconds of this process (time.process_time), less sensitive than wall time to the other jobs of the
shared machine but not insensitive (caches, turbo); cProfile adds its overhead to the Python-level parts (the F
evaluations), --no-profile gives the whole-solve time without it. Used for docs/benchmarks.md, "One Newton
iteration: the block LU".
"""
from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# (group, function names as cProfile reports them: (file suffix, name)); "cum": cumulative time (includes callees)
GROUPS = {
    "assembly": [("newton.py", "_assemble_jacobian", "cum"), ("~", "<built-in method numpy.core._multiarray_umath."
                                                                   "c_einsum>", "tot")],
    "linear_solve": [("newton.py", "_direction", "cum"), ("linalg.py", "lu_solve", "cum")],
    "F_evaluations": [("newton.py", "fun", "cum")],
    "residuals": [("newton.py", "residual", "cum")],
}


def profile_split(prof: cProfile.Profile) -> dict:
    st = pstats.Stats(prof).stats  # {(file, line, name): (cc, nc, tt, ct, callers)}
    out = {}
    for g, keys in GROUPS.items():
        s = 0.0
        for suffix, name, kind in keys:
            for (f, _, fn), (cc, nc, tt, ct, callers) in st.items():
                if fn == name and f.endswith(suffix):
                    if name == "lu_solve" and any(c[2] == "_direction" for c in callers):
                        continue  # counted in _direction
                    s += ct if kind == "cum" else tt
        out[g] = s
    out["F_calls"] = sum(nc for (f, _, fn), (cc, nc, tt, ct, callers) in st.items()
                         if fn == "fun" and f.endswith("newton.py"))
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("paths", nargs="+")
    p.add_argument("--tree", default=ROOT, help="import fem_blocks from this directory (default: this tree)")
    p.add_argument("--superlu", action="store_true", help="newton.BLOCK_LU = False")
    p.add_argument("--no-profile", action="store_true")
    a = p.parse_args(argv)
    sys.path.insert(0, os.path.abspath(a.tree))
    from fem_blocks.solver import newton  # before bench_split_step, which puts this tree first on sys.path
    sys.path.insert(0, os.path.join(ROOT, "bench"))
    import bench_split_step as bss
    assert os.path.abspath(newton.__file__).startswith(os.path.abspath(a.tree)), newton.__file__
    if a.superlu:
        newton.BLOCK_LU = False
    for path in a.paths:
        args, kw = bss.load_problem(path)
        prof = None if a.no_profile else cProfile.Profile(time.process_time)
        t0, w0 = time.process_time(), time.perf_counter()
        if prof is not None:
            prof.enable()
        res, x = newton.solve_cohesive_newton(*args, **kw)
        if prof is not None:
            prof.disable()
        cpu, wall = time.process_time() - t0, time.perf_counter() - w0
        info = bss.parse_message(res.message)
        it = max(info["newton"], 1)
        rec = dict(problem=os.path.basename(path), newton=info["newton"], fallbacks=info["fallbacks"],
                   staggered=info["staggered"], converged=bool(res.converged), residual=float(res.residual),
                   cpu_s=round(cpu, 3), wall_s=round(wall, 3), ms_per_iter=round(1e3 * cpu / it, 2))
        if prof is not None:
            split = profile_split(prof)
            calls = split.pop("F_calls")
            for g, s in split.items():
                rec[f"{g}_ms"] = round(1e3 * s / it, 2)
            rec["rest_ms"] = round(1e3 * (cpu - sum(split.values())) / it, 2)
            rec["F_calls_per_iter"] = round(calls / it, 1)
        print(json.dumps(rec), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
