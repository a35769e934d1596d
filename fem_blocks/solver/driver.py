"""One entry point for the contact problem: `solve(problem, options, r0=None, coarse=None)`.

Solves u = W r + q with Signorini–Coulomb or interface laws per contact (solver/problem.py: ContactProblem) by the
method of `options` (specs.py: SolverOptions), and returns a SolverResult. Dispatch:

    laws      options.solver  options.fallback  dim   runs
    Coulomb   "nlgs"          "none"            2, 3  nlgs.solve_block_csr (with `coarse`: two-level NLGS, 2D)
    Coulomb   "nlgs"          "newton"          2, 3  nlgs_then_newton: NLGS windows, then newton.solve_newton
    Coulomb   "newton"        -                 2, 3  newton.solve_newton (20 NLGS sweeps, then Newton)
    laws      "nlgs"          (not used)        2, 3  nlgs.solve_cohesive (staggered internal variables)
    laws      "newton"        -                 2     newton.solve_cohesive_newton (3D: InputError)
    any       "nlgs", order "colours"  "none"   2, 3  distributed/colour.ColourSolver (colour-order sweeps, serial or on
                                                      the MPI ranks of `colours`; exact sums in the stopping tests)

`r0` warm-starts the reactions (zeros by default). Newton reads tol, max_sweeps (its budget of fallback
sweeps) and, with interface laws, max_iterations (its budget of Newton iterations) only; order, omega, seed,
criterion and check_every are NLGS's. The result carries which solver produced r (`solver`) and, with interface
laws, the trial internal variables (`trial`) that laws.commit_step commits.
"""
from __future__ import annotations

from ..errors import InputError
from . import newton, nlgs
from ..specs import SolverOptions
from .problem import ContactProblem, SolverResult

STALL_SWEEPS = 200     # fallback: Gauss–Seidel window [sweeps]
STALL_FACTOR = 0.5     # fallback: a window that does not bring the residual below this factor of its start stagnates
NEWTON_MAX_ITER = 200  # fallback: Newton iterations after the hand-over


def solve(problem: ContactProblem, options: SolverOptions | None = None, r0=None, coarse=None,
          colours=None, linear=None) -> SolverResult:
    """Solve `problem` with `options` (default SolverOptions()) from reactions r0; `coarse`: the coarse space of
    options.coarse = "interfaces" (solver/coarse.py, built by the caller from the contact set); `colours`: the
    colour solver of options.order = "colours" (distributed/colour.ColourSolver for problem.W, serial or
    distributed; None: a serial one is built here); `linear`: the solver of the Newton iterations' J Δr = -F
    (distributed/linear.DistBlockSolver on W's pattern; None: the serial block LU / LU). Never raises on
    non-convergence: see `converged`."""
    o = options if options is not None else SolverOptions()
    W, q, mu, L = problem.W, problem.q, problem.mu, problem.laws
    if o.order == "colours":  # (SolverOptions checks solver = "nlgs", no fallback, no coarse correction)
        if colours is None:
            from ..distributed.colour import ColourSolver
            colours = ColourSolver(W)
        if colours.W is not W:
            raise InputError("colours: built for another Delassus operator than problem.W")
        return colours.solve(q, mu, r0=r0, tol=o.tol, max_sweeps=o.max_sweeps, omega=o.omega, criterion=o.criterion,
                             check_every=o.check_every, laws=L, own_rows=problem.own_rows)
    if problem.own_rows:
        raise InputError("own_rows: a problem of a rank's own contacts is solved in colour order only; expected "
                         "options.order = 'colours'")
    if o.coarse != "none" and coarse is None:
        raise InputError(f"coarse = None: options.coarse = {o.coarse!r} needs the coarse space (solver/coarse.py)")
    if coarse is not None and (L is not None or o.solver != "nlgs" or o.fallback != "none"):
        raise InputError("coarse: the coarse correction is a step of the Gauss-Seidel solver for the Coulomb law; "
                         "expected solver = 'nlgs', fallback = 'none' and no interface laws")
    if L is not None:
        if o.solver == "newton":
            res, trial = newton.solve_cohesive_newton(W, q, mu, L.law, L.par, L.state, L.ueff, L.area, L.h, L.theta,
                                                      r0=r0, tol=o.tol, max_sweeps_total=o.max_sweeps,
                                                      max_total_iter=o.max_iterations, linear=linear)
        else:
            res, trial = nlgs.solve_cohesive(W, q, mu, L.law, L.par, L.state, L.ueff, L.area, L.h, L.theta, r0=r0,
                                             tol=o.tol, max_sweeps=o.max_sweeps, omega=o.omega, order=o.order,
                                             seed=o.seed, criterion=o.criterion, check_every=o.check_every)
        res.trial = trial
        return res
    if o.solver == "newton":
        return newton.solve_newton(W, q, mu, r0=r0, tol=o.tol, max_sweeps_total=o.max_sweeps, linear=linear)
    if o.fallback == "newton":
        return nlgs_then_newton(problem, o, r0, linear=linear)
    return nlgs.solve_block_csr(W, q, mu, r0=r0, tol=o.tol, max_sweeps=o.max_sweeps, omega=o.omega, order=o.order,
                                seed=o.seed, criterion=o.criterion, check_every=o.check_every, coarse=coarse)


def nlgs_then_newton(problem: ContactProblem, options: SolverOptions, r0=None, stall_sweeps: int = STALL_SWEEPS,
                     stall_factor: float = STALL_FACTOR, newton_max_iter: int = NEWTON_MAX_ITER,
                     linear=None) -> SolverResult:
    """NLGS with the residual criterion in windows of `stall_sweeps` sweeps; when a window does not reduce the
    residual below `stall_factor` times its value at the window's start (stagnation: slow convergence or a cycle),
    or options.max_sweeps is spent, the global semismooth Newton (solver/newton.py, `newton_max_iter` iterations,
    no further Gauss–Seidel start) continues from the current reactions. Window k uses the seed options.seed + k.
    The message says which solver finished; `sweeps` counts sweeps + Newton iterations + Newton's fallback
    sweeps. (Coulomb contacts; criterion "residual".)"""
    if options.criterion != "residual":
        raise InputError("fallback = 'newton' needs criterion = 'residual' (stagnation is measured on the "
                         "FCLIB residual)")
    if int(stall_sweeps) != stall_sweeps or stall_sweeps < 1:
        raise InputError(f"stall_sweeps = {stall_sweeps!r}: expected an integer >= 1")
    if not (0.0 < stall_factor < 1.0):
        raise InputError(f"stall_factor = {stall_factor!r}: expected 0 < stall_factor < 1")
    if int(newton_max_iter) != newton_max_iter or newton_max_iter < 1:
        raise InputError(f"newton_max_iter = {newton_max_iter!r}: expected an integer >= 1")
    W, q, mu = problem.W, problem.q, problem.mu
    tol, max_sweeps, omega, order = options.tol, options.max_sweeps, options.omega, options.order
    seed, check_every, window, factor = options.seed, options.check_every, int(stall_sweeps), float(stall_factor)
    total = 0
    res = nlgs.solve_block_csr(W, q, mu, r0=r0, tol=tol, max_sweeps=min(window, max_sweeps), omega=omega,
                               order=order, seed=seed, criterion="residual", check_every=check_every)
    total += res.sweeps
    cases = res.local_cases.copy() if res.local_cases is not None else None
    k = 0
    while not res.converged and total < max_sweeps:
        k += 1
        start = res.residual
        res = nlgs.solve_block_csr(W, q, mu, r0=res.r, tol=tol, max_sweeps=min(window, max_sweeps - total),
                                   omega=omega, order=order, seed=seed + k, criterion="residual",
                                   check_every=check_every)
        total += res.sweeps
        if cases is not None:
            cases += res.local_cases
        if not res.converged and res.residual > factor * start:
            break
    if res.converged:
        res.sweeps = total
        res.message = f"converged in {total} sweeps (Gauss-Seidel alone)"
        res.local_cases = cases
        return res
    nt = newton.solve_newton(W, q, mu, r0=res.r, tol=tol, max_iter=int(newton_max_iter), gs_sweeps=0, linear=linear)
    nt.message = (f"Gauss-Seidel stagnated at residual {res.residual:.3g} after {total} sweeps, then Newton: "
                  f"{nt.message}")
    nt.sweeps += total
    nt.local_cases = cases
    nt.solver = "NLGS + Newton fallback"
    return nt
