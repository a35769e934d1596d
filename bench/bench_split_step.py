"""Captured contact steps of a shear wall: capture them from a run, then re-solve them standalone (seconds each).

    # run a case (CLI arguments after --) and record every interface-law Newton solve: one line per solve in
    # DIR/calls.jsonl (stage time, h, Newton iterations, Gauss–Seidel sweeps, coupled pass failed or not, residual,
    # wall time); with --save, the problems of the solves whose index (1-based, in call order) is listed are saved
    # as DIR/call_NNNN.npz (W, q, μ, law data, committed state, start r0, tolerance)
    python bench/bench_split_step.py capture DIR [--save 5,12,...|all] -- run CASE.toml --out OUT --quick [--resume]

    # re-solve saved problems with solve_cohesive_newton (this tree) and print one line per problem
    # (--staggered: damage_inside = False; --ac-rows: the coupled pass with the Alart–Curnier rows; --no-give-up:
    # the compliant coupled pass runs to max_iter, newton.GIVE_UP = None)
    python bench/bench_split_step.py solve DIR/call_0012.npz [...] [--staggered] [--ac-rows]

    # one problem, one line per Newton iteration: residual, step length, regularisation, share of ‖F‖² on the
    # crack contacts (k_n >= 1e12), and every K iterations the Jacobian against central finite differences
    python bench/bench_split_step.py trace DIR/call_0012.npz [--fd-every K]

Used for docs/benchmarks.md, "Split-brick steps: where the iterations go". The iteration counts are the numbers to
compare (robust under machine load); wall times depend on the load of the shared machine.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from fem_blocks.laws import NPAR  # noqa: E402
from fem_blocks.linalg import BlockCSR  # noqa: E402
from fem_blocks.solver import newton  # noqa: E402

_MSG = re.compile(r"(\d+) Newton iterations, (\d+) Gauss-Seidel sweeps \((\d+) fallbacks\)")


def parse_message(msg: str) -> dict:
    m = _MSG.search(msg)
    it, gs, fb = (int(g) for g in m.groups()) if m else (-1, -1, -1)
    return dict(newton=it, sweeps=gs, fallbacks=fb, staggered="staggered instead" in msg)


def save_problem(path, W, q, mu, law, par, st, ueff, area, h, theta, r0, kw):
    np.savez_compressed(path, indptr=W.indptr, indices=W.indices, blocks=W.blocks, diag_pos=W.diag_pos, q=q,
                        mu=np.broadcast_to(np.asarray(mu, float), (W.n,)), law=law, par=par, st=st, ueff=ueff,
                        area=area, h=h, theta=theta, r0=np.zeros(2 * W.n) if r0 is None else r0,
                        tol=kw.get("tol", 1e-8), max_sweeps_total=kw.get("max_sweeps_total", 100000))


def load_problem(path):
    z = np.load(path)
    W = BlockCSR(z["indptr"], z["indices"], np.ascontiguousarray(z["blocks"]), z["diag_pos"])
    par = z["par"]
    if par.shape[1] < NPAR:  # captured before parameter columns were appended (19: hardening cap, 21: C_ss): default 0
        par = np.hstack([par, np.zeros((par.shape[0], NPAR - par.shape[1]))])
    args = (W, z["q"], z["mu"], z["law"], par, z["st"], z["ueff"], z["area"], float(z["h"]), float(z["theta"]))
    return args, dict(r0=z["r0"], tol=float(z["tol"]), max_sweeps_total=int(z["max_sweeps_total"]))


def capture(out_dir, save, cli_args):
    os.makedirs(out_dir, exist_ok=True)
    log = open(os.path.join(out_dir, "calls.jsonl"), "a")
    orig = newton.solve_cohesive_newton
    k = [0]

    def wrapped(W, q, mu, law, par, st, ueff, area, h, theta, r0=None, **kw):
        k[0] += 1
        if save == "all" or k[0] in save:
            save_problem(os.path.join(out_dir, f"call_{k[0]:04d}.npz"), W, q, mu, law, par, st, ueff, area, h,
                         theta, r0, kw)
        t0 = time.perf_counter()
        res, x = orig(W, q, mu, law, par, st, ueff, area, h, theta, r0=r0, **kw)
        rec = dict(call=k[0], h=float(h), n=int(W.n), seconds=round(time.perf_counter() - t0, 3),
                   residual=float(res.residual), converged=bool(res.converged),
                   damaging=int(np.sum((law == 5) & (x > st[:, 0]))), **parse_message(res.message))
        log.write(json.dumps(rec) + "\n")
        log.flush()
        return res, x

    newton.solve_cohesive_newton = wrapped
    from fem_blocks import cli
    return cli.main(cli_args)


def solve(paths, staggered=False):
    for p in paths:
        args, kw = load_problem(p)
        t0 = time.perf_counter()
        res, x = newton.solve_cohesive_newton(*args, damage_inside=not staggered, **kw)
        info = parse_message(res.message)
        print(json.dumps(dict(problem=os.path.basename(p), n=args[0].n, seconds=round(time.perf_counter() - t0, 2),
                              residual=float(res.residual), converged=bool(res.converged),
                              damaged=int(np.sum(x > args[5][:, 0])), **info)), flush=True)


def trace(path, fd_every=0, staggered=False, seed=0):
    """Re-solve one saved problem with a probe on every Newton iteration: the residual, the step length, the share of
    ‖F‖² carried by the crack contacts (k_n >= 1e12) and the joint contacts, and every `fd_every` iterations the
    Jacobian J of the iteration against central finite differences of F along the Newton direction and a random
    direction (relative error ‖J d - FD‖/‖FD‖ over all rows and over the rows whose F is smooth there)."""
    args, kw = load_problem(path)
    W, law, par = args[0], args[3], args[4]
    crack = np.repeat(par[:, 1] >= 1e12, 2)
    rng = np.random.default_rng(seed)
    rows = []

    def probe(ev):
        F = ev["F"]
        f2 = float(F @ F) or 1.0
        rec = dict(it=ev["it"], res=ev["res"], t=ev["t"], gs=ev["gs"], eps=ev["eps"],
                   crack_share=round(float(F[crack] @ F[crack]) / f2, 4),
                   worst=int(np.argmax(np.abs(F)) // 2), worst_is_crack=bool(crack[int(np.argmax(np.abs(F)))]))
        if fd_every and ev["it"] % fd_every == 1:
            import scipy.sparse.linalg as spla
            r, J, Ff = ev["r"], ev["J"], ev["Ffun"]
            dn = spla.spsolve(J.tocsc(), -F)
            for name, d in (("newton", dn), ("random", rng.standard_normal(r.size) * (np.abs(r) + np.abs(r).mean()))):
                e = 1e-7 * (np.linalg.norm(r) or 1.0) / (np.linalg.norm(d) or 1.0)
                Fp, Fm, F0 = Ff(r + e * d), Ff(r - e * d), Ff(r)
                fd = (Fp - Fm) / (2 * e)
                jd = J @ d
                smooth = np.abs(Fp - 2 * F0 + Fm) <= 1e-6 * (np.abs(Fp - Fm) + 1e-300)  # no kink within ±e d
                err = np.abs(jd - fd)
                rec[f"fd_{name}"] = round(float(np.linalg.norm(err) / (np.linalg.norm(fd) or 1.0)), 6)
                rec[f"fd_{name}_smooth"] = round(float(np.linalg.norm(err[smooth]) /
                                                       (np.linalg.norm(fd[smooth]) or 1.0)), 6)
                bad = np.flatnonzero(smooth & (err > 1e-4 * (np.abs(fd) + np.abs(jd)).max()))
                rec[f"fd_{name}_badrows"] = [int(b) for b in bad[:6]]
            ev["restore"]()
        rows.append(rec)
        print(json.dumps(rec), flush=True)

    res, x = newton.solve_cohesive_newton(*args, damage_inside=not staggered, probe=probe, **kw)
    print(res.message)
    return rows


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    cli_args = []
    if "--" in argv:
        i = argv.index("--")
        argv, cli_args = argv[:i], argv[i + 1:]
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("capture")
    c.add_argument("dir")
    c.add_argument("--save", default="")
    s = sub.add_parser("solve")
    s.add_argument("paths", nargs="+")
    s.add_argument("--staggered", action="store_true", help="damage_inside = False (staggered only)")
    s.add_argument("--ac-rows", action="store_true", help="coupled pass with the Alart-Curnier rows for compliant "
                   "contacts (newton.COMPLIANT_ROWS = False)")
    s.add_argument("--no-give-up", action="store_true", help="the compliant coupled pass runs to max_iter "
                   "(newton.GIVE_UP = None: the logic before 2026-11-26)")
    t = sub.add_parser("trace")
    t.add_argument("path")
    t.add_argument("--fd-every", type=int, default=0)
    t.add_argument("--staggered", action="store_true")
    a = p.parse_args(argv)
    if a.cmd == "trace":
        trace(a.path, a.fd_every, a.staggered)
        return 0
    if a.cmd == "capture":
        save = "all" if a.save == "all" else {int(v) for v in a.save.split(",") if v}
        return capture(a.dir, save, cli_args)
    newton.COMPLIANT_ROWS = not a.ac_rows
    if a.no_give_up:
        newton.GIVE_UP = None
    solve(a.paths, a.staggered)
    return 0


if __name__ == "__main__":
    sys.exit(main())
