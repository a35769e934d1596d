"""Virtual masonry laboratory: the standard tests of masonry as generated cases (docs/lab-tests.md).

A lab case file is an ordinary case file without geometry or stages, plus a `[lab]` table naming the test:

    [materials.brick]  E, nu, rho, thickness        (the bricks; `[lab] material` names another)
    [laws.joint]       law = "mixed", k_n, ...      (the joints; `[lab] joint` names another)
    [lab]              test = "triplet_shear", the specimen's dimensions, levels, loading
    [contact], [output], [checks], [[reference]]    (optional; as in any case file)

`load_lab(path)` reads it (with its bases and named laws, casefile.py) and asks the test's module
(specimen.TESTS) for one ordinary case per specimen (`specimens(spec, emitter_factory)` -> [(label, data,
info)]), each validated by `case.parse_case`. `run_lab` runs every specimen with `runner.run_case` into
OUT/LABEL/ (history.csv, summary.json, ParaView files, crack pattern, force-displacement figure with the
file's references: the same guards and outputs as any run), then the test's `readout(spec, runs)` reads the
specimens' histories and returns the standard's quantities, written to OUT/summary.json, and `plot` draws the
standard's construction on OUT/TEST.png. Data flow: case file -> [lab] spec -> specimen cases -> runs -> read-out.

Exit status: the most severe of the specimens' (0; 3 with unconverged steps; 1 a run stopped by a numerical failure)
and 1 when the read-out could not measure one of the standard's quantities (NaN, listed in summary "unmeasured").
"""
from __future__ import annotations

import copy
import importlib
import json
import math
import os
import sys
from dataclasses import dataclass, field

from ..distributed.root import on_root
from ..errors import InputError
from .specimen import TESTS, Emitter, SpecimenSpec

#: exit statuses from the least to the most severe: 0 clean, 3 unconverged steps, 1 a run stopped by a guard or a
#: quantity of the standard that the read-out could not measure (NaN: e.g. no failure within the loading)
SEVERITY = {0: 0, 3: 1, 1: 2}
__all__ = ["LabCase", "load_lab", "parse_lab", "run_lab", "TESTS", "SpecimenSpec"]

#: top-level tables a [lab] file may hold besides [lab]: they pass into every specimen (generated keys excluded)
PASS_THROUGH = ("name", "units", "description", "dimension", "gravity", "materials", "laws", "contact", "output",
                "checks", "reference", "history_times")
GENERATED = ("blocks", "block_types", "rigid_bodies", "interfaces", "stages", "wall", "arch", "wall3d", "dome",
             "allow_no_interface")


@dataclass
class LabCase:
    source: str
    name: str
    spec: SpecimenSpec          # the test's spec (SI)
    module: object              # the test's module (STANDARD, readout, plot)
    specimens: list = field(default_factory=list)   # of (label, case.Case, info dict)
    units: str = "SI"
    inputs: dict = field(default_factory=dict)      # the material and joint law as written (file units)


def test_module(test: str):
    return importlib.import_module(f"{__name__}.{TESTS[test]}")


def load_lab(path: str) -> LabCase | None:
    """A case file with a `[lab]` table -> LabCase (every specimen validated); None for an ordinary case file."""
    from .. import casefile
    from ..laws import LAW_KEYS
    data, source = casefile.read(path, LAW_KEYS, resolve=False)
    if not isinstance(data, dict) or "lab" not in data:
        return None
    return parse_lab(data, source)


def parse_lab(data: dict, source) -> LabCase:
    """[lab] and the file's tables -> LabCase; InputError naming the file and the key."""
    from .. import casefile
    from ..case import UNIT_SYSTEMS, Table, parse_case, read_fields
    from ..laws import LAW_KEYS
    from ..specs import schema_fields
    root = Table(data, "", source, UNIT_SYSTEMS["SI"])
    units = root.string("units", "SI", choices=list(UNIT_SYSTEMS))
    U = UNIT_SYSTEMS[units]
    D = data.get("dimension", 2)
    if D != 2:
        raise root.error("dimension", f"= {D!r}: expected 2 (the [lab] tests are 2D)")
    for k in data:
        if k in GENERATED:
            raise root.error(k, f"a [lab] case generates its own {k}; remove it (or list it in `unset` if it "
                                "comes from a base)")
        if k not in PASS_THROUGH and k != "lab":
            raise root.error(k, f"unknown key in a [lab] case (expected [lab] and {', '.join(PASS_THROUGH)})")
    t = root.table("lab", required=True)
    t.units = U
    test = read_fields(t, SpecimenSpec, ("test",))["test"]
    mod = test_module(test)
    cls = mod.SPEC
    simple = [f.name for f in schema_fields(cls) if str(f.type).split("|")[0].strip() in ("str", "int", "float",
                                                                                           "bool")]
    kw = read_fields(t, cls, simple)
    kw.update(mod.read_lists(t, U))   # the test's list keys (levels), validated, in SI
    spec = cls(**kw)
    mod.check(spec, t)   # the test's own rules (geometry that cannot hold the specimen): InputError naming the key
    t.done()
    # keys naming a table of the file: the material, the joint law and the test's other laws (NAMED_LAWS; None:
    # unused)
    named = [("material", "materials"), ("joint", "laws")] + [(k, "laws") for k in getattr(mod, "NAMED_LAWS", ())]
    for key, table in named:
        name, have = getattr(spec, key), sorted(data.get(table) or {})
        if name is not None and name not in have:
            raise t.error(key, f"= {name!r}: expected the name of a [{table}.NAME] table of the file"
                               + (f" ({', '.join(map(repr, have))})" if have else f" (the file has no [{table}])"))
    base = {k: v for k, v in data.items() if k != "lab"}
    name = str(data.get("name") or os.path.splitext(os.path.basename(str(source)))[0])
    lab = LabCase(source=source, name=name, spec=spec, module=mod, units=units,
                  inputs=dict(material=copy.deepcopy(data["materials"][spec.material]),
                              joint=copy.deepcopy(data["laws"][spec.joint])))
    for label, d, info in mod.specimens(spec, lambda nm: Emitter(base, U, spec, f"{name}/{nm}")):
        casefile.resolve_laws(d, source, LAW_KEYS)
        lab.specimens.append((label, parse_case(d, source), info))
    return lab


def run_lab(lab: LabCase, out: str, quick: bool = False, quiet: bool = False, resume: bool = False,
            force: bool = False, comm=None) -> int:
    """Run every specimen (runner.run_case into OUT/LABEL), read the test out, write OUT/summary.json and
    OUT/TEST.png; return the exit status (the worst of the specimens'). comm: N > 1 MPI ranks running this same
    call (each specimen runs on all of them, runner.run_case; rank 0 writes the report)."""
    from ..case import quick as make_quick
    from ..output.checkpoint import has_checkpoint
    from ..output.history import read_history
    from ..runner import RunStopped, convergence_line, run_case
    root = comm is None or comm.Get_rank() == 0
    if root:
        os.makedirs(out, exist_ok=True)
    runs, status = [], 0
    for label, case, info in lab.specimens:
        if quick:
            case = make_quick(case)
        d = os.path.join(out, label)
        # (N ranks: rank 0's view of the files decides for every rank)
        has_ck = on_root(comm, lambda: resume and has_checkpoint(d))
        try:
            summ = run_case(case, d, progress=not quiet, resume=has_ck, force=force, comm=comm)
            st, line = int(summ.get("exit_status") or 0), convergence_line(summ.get("convergence"))
        except RunStopped as e:
            if e.code in (130, 143):   # SIGINT / SIGTERM: stop the whole test (the checkpoint is written)
                print(f"fem-blocks: {lab.name}: specimen {label} interrupted ({e}); the specimens continue with: "
                      f"fem-blocks run {lab.source} --out {out} --resume", file=sys.stderr)
                return e.code
            summ, st, line = None, e.code, f"run stopped: {e}"
        status = max(status, st, key=SEVERITY.get)
        hist = read_history(os.path.join(d, "history.csv"))
        runs.append(dict(label=label, dir=label, info=info, history=hist, summary=summ, exit_status=st, case=case,
                         convergence=line))
        print(f"{lab.name}: specimen {label}: "   # (printed with --quiet too, as a run's result)
              + (lab.module.specimen_line(lab.spec, runs[-1]) if summ is not None else "")
              + (f"; {line}" if line and st else ""))
    png = f"{lab.spec.test}.png"
    try:
        report = lab.module.readout(lab.spec, runs)
        if root:
            lab.module.plot(lab.spec, report, runs, os.path.join(out, png), title=lab.name)
    except (ValueError, IndexError, KeyError, ZeroDivisionError) as e:
        if not status:   # a complete set of runs must read out: a bug, not a specimen's failure
            raise
        report, png = dict(quantities={}, error=f"no read-out: {type(e).__name__}: {e}"), None  # (a stopped run)
    unmeasured = [k for k, q in report.get("quantities", {}).items()
                  if not (isinstance(q.get("value"), (int, float)) and math.isfinite(q["value"]))]
    if unmeasured or "error" in report:   # a quantity the test did not measure (NaN): never a clean exit
        status = max(status, 1, key=SEVERITY.get)
    summary = dict(case=str(lab.source), name=lab.name, test=lab.spec.test, standard=lab.module.STANDARD,
                   exit_status=status, unmeasured=unmeasured, variant="quick x2" if quick else "",
                   quantities=report.pop("quantities"), report=report, figure=png,
                   specimens=[dict(label=r["label"], dir=r["dir"], exit_status=r["exit_status"], **r["info"],
                                   convergence=r["convergence"])
                              for r in runs],
                   inputs=dict(lab={k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(lab.spec).items()},
                               units_of_lab="SI", material=lab.inputs["material"], joint=lab.inputs["joint"],
                               units_of_material_and_joint=lab.units))
    if root:
        with open(os.path.join(out, "summary.json"), "w") as f:
            json.dump(summary, f, indent=1, default=float)
    for k, q in summary["quantities"].items():
        meas = f" (measures {q['measures']}" + (f" = {q['input']:g}" if isinstance(q.get("input"), (int, float))
                                               else "") + ")" if q.get("measures") else ""
        print(f"{lab.name}: {k} = {q['value']:.6g} {q['unit']}{meas}")
    print(f"report: {os.path.join(os.path.abspath(out), 'summary.json')}"
          + (f"; figure: {os.path.join(os.path.abspath(out), png)}" if png else f" ({report['error']})"))
    if status:   # the last line: the outcome
        why = (f"the read-out could not measure {', '.join(unmeasured)} (NaN in summary.json)" if unmeasured
               else "a specimen did not complete cleanly (see its line above)")
        print(f"{lab.name}: WARNING: exit status {status}: {why}; do not trust this report")
    return status


def check_lines(lab: LabCase) -> list[str]:
    """`fem-blocks check` on a [lab] file: the test and one line per specimen."""
    out = [f"case {lab.source}: lab test {lab.spec.test!r} ({lab.module.STANDARD}), {len(lab.specimens)} "
           f"specimen(s), bricks {lab.spec.bricks}, material {lab.spec.material!r}, joint law {lab.spec.joint!r}"]
    for label, case, info in lab.specimens:
        out.append(f"  specimen {label}: {len(case.blocks)} blocks, {len(case.rigid_bodies)} rigid bodies, "
                   f"{sum(round(s.duration / s.h) for s in case.stages)} steps; {info}")
    return out
