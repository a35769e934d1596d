"""Command line: `fem-blocks run CASE.toml --out DIR`, `fem-blocks check CASE.toml`, `fem-blocks demo [NAME|--list]`,
`--version`.

Exit status: 0 success, 2 invalid input (one line on stderr naming the file/key and what was
expected, no traceback), 1 a run that failed numerically or by solver policy (message says where; a
checkpoint of the last good step and the outputs so far are written), 3 a run that completed with steps
whose contact solve stayed above the tolerance (unless `[checks] accept_unconverged = true`; the last line
printed gives their count and the worst residual with its step), 130/143 stopped by SIGINT/SIGTERM after
finishing the current step and writing a checkpoint (`--resume` continues it).
"""
from __future__ import annotations

import argparse
import os
import sys

from . import __version__
from .errors import ConvergenceError, InputError, RankMismatchError

DEMO_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "demos")
DEFAULT_DEMO = "shear_wall_p030"  # `make demo`: the micro-model wall (docs/validation.md); the thesis' model is "shear_wall_fc_p030"


def list_demos() -> dict[str, str]:
    """name -> case file path of the demos shipped in `demos/`. A case file with the stem of a Python demo
    (demos/dome.toml next to demos/dome.py) is listed with its extension (`dome.toml`)."""
    out = {}
    if os.path.isdir(DEMO_DIR):
        files = sorted(f for f in os.listdir(DEMO_DIR)
                       if f.endswith(".toml") or (f.endswith(".py") and not f.startswith("_")))
        scripts = {os.path.splitext(f)[0] for f in files if f.endswith(".py")}
        for f in files:
            stem = os.path.splitext(f)[0]
            out[f if f.endswith(".toml") and stem in scripts else stem] = os.path.join(DEMO_DIR, f)
    return out


def _first_line(path: str) -> str:
    with open(path, encoding="utf-8") as f:
        for line in f:
            if line.startswith("#") and not line.startswith("#!"):
                return line.lstrip("# ").strip()
            if line.startswith('"""'):
                return line.strip().strip('"').strip()
    return ""


def _run_script(path: str, out: str, quick: bool = False, extra=()) -> int:
    """A Python demo: a module with main(out_dir[, quick, argv]); `quick` and the demo's own options (`extra`,
    e.g. `--joints brittle`) are passed if its main accepts them."""
    import inspect
    import runpy
    mod = runpy.run_path(path, run_name="fem_blocks_demo")
    params = inspect.signature(mod["main"]).parameters
    kw = {}
    if "quick" in params:
        kw["quick"] = quick
    if "argv" in params:
        kw["argv"] = list(extra)
    elif extra:
        raise InputError(f"demo {os.path.basename(path)}: unrecognized arguments {' '.join(extra)}")
    mod["main"](out, **kw)
    return 0


def _world():
    """MPI.COMM_WORLD when this process is one of N > 1 ranks (`mpirun -n N fem-blocks run ...`), else None."""
    from mpi4py import MPI
    return MPI.COMM_WORLD if MPI.COMM_WORLD.Get_size() > 1 else None


def _run(case_path: str, out: str, quiet: bool, quick: bool = False, resume: bool = False,
         force: bool = False, comm=None) -> int:
    from .case import load_case
    from .case import quick as make_quick
    from .lab import load_lab, run_lab
    lab = load_lab(case_path)  # a [lab] file: a standard test, one generated case per specimen (fem_blocks/lab)
    if lab is not None:
        return run_lab(lab, out, quick=quick, quiet=quiet, resume=resume, force=force, comm=comm)
    case = load_case(case_path)  # validate before importing the heavy stages
    if quick:
        case = make_quick(case)
    from .runner import RunStopped, convergence_line, run_case
    try:
        summary = run_case(case, out, progress=not quiet, resume=resume, force=force, comm=comm)
    except InputError as e:  # found while building or starting the model (overlaps, meshes): name the case file
        msg = str(e)
        raise InputError(msg if msg.startswith(case.source) else f"{case.source}: {msg}") from None
    except RunStopped as e:
        print(f"fem-blocks: run stopped: {e}", file=sys.stderr)
        return e.code
    pv = summary["outputs"].get("paraview")
    ranks = f" on {comm.Get_size()} MPI ranks" if comm is not None else ""
    print(f"fem-blocks: {case.name}: {summary['steps']} steps in {summary['wall_time']:.1f} s{ranks}")
    if pv:
        print(f"ParaView files: {os.path.join(os.path.abspath(out), pv)}")
    print(f"history: {os.path.join(os.path.abspath(out), 'history.csv')}; "
          f"summary: {os.path.join(os.path.abspath(out), 'summary.json')}")
    figs = [summary[k] for k in ("force_displacement", "hysteresis", "crack_pattern", "blocks_png") if summary.get(k)]
    if figs:
        print("figures: " + ", ".join(os.path.join(os.path.abspath(out), f) for f in figs))
    if "peak_horizontal_force_kN" in summary and "displacement_at_peak_mm" in summary:
        print(f"peak horizontal force {summary['peak_horizontal_force_kN']:.3f} kN at "
              f"{summary['displacement_at_peak_mm']:.3f} mm (vertical force {summary['vertical_force_at_peak_kN']:.3f} kN)")
    line = convergence_line(summary.get("convergence"))
    if line:
        print(line)  # the last line: the outcome of the contact solves
    return int(summary.get("exit_status") or 0)


def _check(case_path: str, quick: bool = False) -> int:
    """`fem-blocks check`: the report on stdout, each warning on one line on stderr (as a run prints them at its
    start); exit status 0 if the case is valid, 2 if not (the one-line error)."""
    from .check import check_case
    lines, warnings = check_case(case_path, quick)
    for line in lines:
        print(line)
    sys.stdout.flush()
    for w in warnings:
        print(f"fem-blocks: warning: {w}", file=sys.stderr)
    print(f"fem-blocks: {case_path}: valid, {len(warnings)} warning(s)" + (" (on stderr)" if warnings else ""))
    return 0


def main(argv=None) -> int:
    """The command line. Under `mpirun -n N` (N > 1) `run` and `demo` run on the N ranks (runner.run_case(comm=)):
    rank 0 prints and writes; the other ranks print nothing, and every rank exits with the same status. An error
    that is not one of the run's own (input, stop, convergence, arithmetic) stops every rank through MPI_Abort."""
    if argv is None and len(sys.argv) > 1 and sys.argv[1] in ("run", "demo") and "--list" not in sys.argv:
        comm = _world()
        if comm is not None:
            return _main_ranks(comm)
    return _main(argv)


def _main_ranks(comm) -> int:
    """main() on one of N > 1 ranks: ranks other than 0 are silent; an unexpected error aborts all ranks."""
    err = sys.stderr
    if comm.Get_rank() > 0:
        sys.stdout = open(os.devnull, "w")
        sys.stderr = open(os.devnull, "w")
    try:
        return _main(None, comm)
    except SystemExit:
        raise
    except BaseException as e:  # noqa: BLE001 - a rank that fails alone would leave the others waiting
        import traceback
        print(f"fem-blocks: rank {comm.Get_rank()} of {comm.Get_size()}: run failed: {type(e).__name__}: {e}",
              file=err)
        traceback.print_exc(file=err)
        err.flush()
        comm.Abort(1)
        return 1


def _main(argv=None, comm=None) -> int:
    p = argparse.ArgumentParser(prog="fem-blocks", description="Deformable-block masonry simulator (NSCD).")
    p.add_argument("--version", action="version", version=f"fem-blocks {__version__}")
    sub = p.add_subparsers(dest="command")
    r = sub.add_parser("run", help="run a case file")
    r.add_argument("case", help="TOML case file")
    r.add_argument("--out", required=True, help="output directory")
    r.add_argument("--quiet", action="store_true", help="no progress line")
    r.add_argument("--quick", action="store_true", help="reduced resolution: element sizes and time steps x2")
    r.add_argument("--resume", action="store_true", help="continue from the last checkpoint in --out")
    r.add_argument("--force", action="store_true", help="with --resume: resume even if the case file changed")
    c = sub.add_parser("check", help="validate a case file and print what would be built, without running it")
    c.add_argument("case", help="TOML case file")
    c.add_argument("--quick", action="store_true", help="check the reduced-resolution variant")
    d = sub.add_parser("demo", help="run a shipped demo")
    d.add_argument("name", nargs="?", default="default", help="demo name (see --list); 'default' = "
                                                              + DEFAULT_DEMO)
    d.add_argument("--list", action="store_true", help="list the demos")
    d.add_argument("--out", default=None, help="output directory (default out/demo-NAME)")
    d.add_argument("--quiet", action="store_true")
    d.add_argument("--quick", action="store_true", help="reduced resolution (smoke test, first look)")
    args, extra = p.parse_known_args(argv)
    if extra and args.command != "demo":
        p.error(f"unrecognized arguments: {' '.join(extra)}")
    if args.command is None:
        p.print_help()
        return 2
    try:
        if args.command == "run":
            if args.force and not args.resume:
                raise InputError("--force: only meaningful with --resume")
            return _run(args.case, args.out, args.quiet, args.quick, args.resume, args.force, comm)
        if args.command == "check":
            return _check(args.case, args.quick)
        demos = list_demos()
        if args.list:
            for name, path in demos.items():
                print(f"{name:24s} {_first_line(path)}")
            return 0
        name = DEFAULT_DEMO if args.name == "default" else args.name
        if name not in demos:
            raise InputError(f"demo {name!r} not found; expected one of {sorted(demos)} (fem-blocks demo --list)")
        out = args.out or os.path.join("out", f"demo-{name}")
        if demos[name].endswith(".py"):
            if comm is not None:
                raise InputError(f"demo {name}: a Python script runs on one process; expected no mpirun (or a case "
                                 "file demo)")
            return _run_script(demos[name], out, args.quick, extra)
        if extra:
            raise InputError(f"demo {name}: unrecognized arguments {' '.join(extra)}")
        return _run(demos[name], out, args.quiet, args.quick, comm=comm)
    except InputError as e:
        print(f"fem-blocks: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("fem-blocks: interrupted", file=sys.stderr)
        return 130
    except ConvergenceError as e:
        print(f"fem-blocks: run stopped: {e}", file=sys.stderr)
        return 1
    except RankMismatchError as e:
        print(f"fem-blocks: run failed: {e}", file=sys.stderr)
        return 1
    except (FloatingPointError, ArithmeticError) as e:
        print(f"fem-blocks: run failed: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
