"""Behaviour does not change: run every demo at commit REF and in the working tree and compare their numbers.

Usage: .venv/bin/python bench/compare_outputs.py REF [--steps N] [--only NAME,NAME] [--skip NAME,NAME]
                                                      [--rename OLD=NEW,...] [--rtol 1e-12] [--work DIR]

REF (a commit, branch or tag) is exported with `git archive` into a scratch folder; every case is run twice, once
with that tree and once with the working tree (each on its own PYTHONPATH, cwd = the tree), into DIR/ref/NAME and
DIR/new/NAME; a later call with the same --work (same REF and --steps) reuses the reference runs. Cases: every `demos/*.toml` at `--quick` resolution (cut to the first N steps of each stage with
`--steps N`: the split-brick shear walls take 20-50 minutes each in full), every `demos/*.py` demo through its
`main(out_dir[, quick])` (its returned dict is written to `returned.json`), and benchmark 1 (LMGC90's brick wall,
`bench/bench_lmgc90_wall.py`, 200 steps or N, floor reaction and top settlement per step in `history.csv`).

Cases are paired by name; `--rename OLD=NEW` pairs REF's case OLD with the working tree's case NEW (a demo file
renamed between the two), reported and filtered (--only, --skip) under the new name.

Compared: every column of every `*.csv` and every numeric leaf of `summary.json` / `returned.json`, except the
wall-clock ones (names matching WALL_CLOCK below). Two numbers agree when they are bitwise equal; otherwise the
relative difference |a - b| / max(|a|, |b|, FLOOR) is reported, and the case fails above --rtol (default 1e-12:
only summation-order differences are accepted; each must be explained where the comparison is reported).
The set of columns / keys and the text of the csv files must match too (a missing or extra one is a
difference); text fields of the json files (case fingerprint, messages) are listed, not judged. The time stamp
is left out.

Exit status 0 when every case agrees, 1 otherwise. Prints one line per case and a final verdict.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PY = sys.executable
WALL_CLOCK = re.compile(r"(^|[._])(wall|cpu|seconds|elapsed|timers?|setup_time|wall_time|rss|memory)($|[._])"
                        r"|_s$|_ms$|^timestamp$")
FLOOR = 1e-300

TOML_DRIVER = r"""
import sys
from fem_blocks.case import load_case, quick
from fem_blocks.runner import run_case
path, out, steps = sys.argv[1], sys.argv[2], int(sys.argv[3])
import os
import fem_blocks
try:  # a [lab] file (fem_blocks/lab): each specimen's case into OUT/LABEL (trees before it: no fem_blocks.lab; an
    #  editable install's finder may still find the working tree's: only this tree's package counts)
    import fem_blocks.lab as _lab
    if os.path.dirname(os.path.dirname(_lab.__file__)) != os.path.dirname(fem_blocks.__file__):
        raise ImportError
    load_lab = _lab.load_lab
except ImportError:
    load_lab = lambda p: None
lab = load_lab(path)
cases = [(quick(c), f"{out}/{label}") for label, c, _ in lab.specimens] if lab else [(quick(load_case(path)), out)]
for case, d in cases:
    if steps > 0:
        for st in case.stages:
            st.duration = min(st.duration, steps * st.h)
            st.output_every = min(st.output_every, steps)
    try:
        run_case(case, d, progress=False)
    except SystemExit:
        pass
"""

PY_DRIVER = r"""
import importlib.util, inspect, json, sys
import numpy as np
path, out = sys.argv[1], sys.argv[2]
spec = importlib.util.spec_from_file_location("demo", path)
mod = importlib.util.module_from_spec(spec)
spec.loader.exec_module(mod)
kw = {"quick": True} if "quick" in inspect.signature(mod.main).parameters else {}
r = mod.main(out, **kw)
def plain(v):
    if isinstance(v, dict):
        return {str(k): plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    if isinstance(v, np.ndarray):
        return plain(v.tolist())
    if isinstance(v, np.generic):
        return v.item()
    return v if isinstance(v, (int, float, str, bool)) or v is None else repr(v)
with open(out + "/returned.json", "w") as f:
    json.dump(plain(r), f)
"""


def cases(tree: str, steps: int) -> list:
    """(name, argv, cwd) of every case of the tree REF or the working tree."""
    out = []
    demos = os.path.join(tree, "demos")
    for f in sorted(os.listdir(demos)):
        p = os.path.join(demos, f)
        if f.endswith(".toml"):
            out.append((f[:-5], [PY, "-c", TOML_DRIVER, p, "{out}", str(steps)]))
        elif f.endswith(".py"):  # named NAME.py where a case file NAME.toml exists too (dome)
            name = f if os.path.exists(os.path.join(demos, f[:-3] + ".toml")) else f[:-3]
            out.append((name, [PY, "-c", PY_DRIVER, p, "{out}"]))
    out.append(("benchmark1", [PY, os.path.join(tree, "bench", "bench_lmgc90_wall.py"), str(steps or 200),
                               "overlap", "{out}/history.csv"]))
    return out


def run(tree: str, name: str, argv: list, out: str) -> tuple:
    os.makedirs(out, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=tree, MPLBACKEND="Agg")
    t0 = time.perf_counter()
    p = subprocess.run([a.replace("{out}", out) for a in argv], cwd=tree, env=env, capture_output=True, text=True)
    with open(os.path.join(out, "console.txt"), "w") as f:
        f.write(p.stdout + p.stderr)
    return p.returncode, time.perf_counter() - t0


def _num(s):
    try:
        return float(s)
    except (TypeError, ValueError):
        return None


def _cmp(a, b, where: str, diffs: list, worst: list):
    fa, fb = _num(a), _num(b)
    if isinstance(a, bool) or isinstance(b, bool) or fa is None or fb is None:
        if a != b:
            diffs.append(f"{where}: {a!r} != {b!r}")
        return
    if fa == fb or (math.isnan(fa) and math.isnan(fb)):
        return
    rel = abs(fa - fb) / max(abs(fa), abs(fb), FLOOR)
    if rel > worst[0]:
        worst[0], worst[1] = rel, f"{where}: {a} vs {b}"


def compare_csv(pa: str, pb: str, diffs: list, worst: list):
    with open(pa) as f:
        ra = list(csv.reader(f))
    with open(pb) as f:
        rb = list(csv.reader(f))
    if not ra or not rb:
        if ra != rb:
            diffs.append(f"{os.path.basename(pa)}: one file empty")
        return
    ha, hb = ra[0], rb[0]
    if ha != hb:
        diffs.append(f"{os.path.basename(pa)}: columns differ: only ref {sorted(set(ha) - set(hb))}, "
                     f"only new {sorted(set(hb) - set(ha))}")
    if len(ra) != len(rb):
        diffs.append(f"{os.path.basename(pa)}: {len(ra) - 1} rows vs {len(rb) - 1}")
    cols = [c for c in ha if c in hb and not WALL_CLOCK.search(c)]
    ia, ib = {c: i for i, c in enumerate(ha)}, {c: i for i, c in enumerate(hb)}
    for k, (x, y) in enumerate(zip(ra[1:], rb[1:])):
        for c in cols:
            _cmp(x[ia[c]] if ia[c] < len(x) else None, y[ib[c]] if ib[c] < len(y) else None,
                 f"{os.path.basename(pa)} row {k + 1} {c}", diffs, worst)


def compare_json(a, b, where: str, diffs: list, worst: list, notes: list):
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if WALL_CLOCK.search(str(k)):
                continue
            if k not in a or k not in b:
                diffs.append(f"{where}.{k}: only in {'new' if k not in a else 'ref'}")
                continue
            compare_json(a[k], b[k], f"{where}.{k}", diffs, worst, notes)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            diffs.append(f"{where}: length {len(a)} vs {len(b)}")
        for i, (x, y) in enumerate(zip(a, b)):
            compare_json(x, y, f"{where}[{i}]", diffs, worst, notes)
    elif isinstance(a, (dict, list)) or isinstance(b, (dict, list)):
        diffs.append(f"{where}: {type(a).__name__} vs {type(b).__name__}")
    elif isinstance(a, str) and isinstance(b, str):  # text of summary.json: told, not judged (numbers are)
        if a != b and not (os.sep in a or os.sep in b):  # paths differ between the two trees
            notes.append(f"{where}: {a!r} != {b!r} (text)")
    else:
        _cmp(a, b, where, diffs, worst)


def compare_dirs(da: str, db: str) -> tuple:
    diffs, worst, notes = [], [0.0, ""], []
    for name in sorted(set(os.listdir(da)) | set(os.listdir(db))):
        pa, pb = os.path.join(da, name), os.path.join(db, name)
        if os.path.isdir(pa) and os.path.isdir(pb) and name != "paraview":   # a [lab] test's specimens
            d, w, n = compare_dirs(pa, pb)
            diffs += [f"{name}/{x}" for x in d]
            notes += [f"{name}/{x}" for x in n]
            if w[0] > worst[0]:
                worst[:] = [w[0], f"{name}/{w[1]}"]
            continue
        if name.endswith(".csv") or name in ("summary.json", "returned.json"):
            if not (os.path.exists(pa) and os.path.exists(pb)):
                diffs.append(f"{name}: only in {'new' if not os.path.exists(pa) else 'ref'}")
            elif name.endswith(".csv"):
                compare_csv(pa, pb, diffs, worst)
            else:
                with open(pa) as f:
                    ja = json.load(f)
                with open(pb) as f:
                    jb = json.load(f)
                compare_json(ja, jb, name, diffs, worst, notes)
    return diffs, worst, notes


def rename_cases(ref_cases: dict, spec: str) -> dict:
    """REF's cases under the working tree's names: `spec` "OLD=NEW,..." renames case OLD to NEW (ValueError naming the
    pair when OLD is not a case of REF, NEW is named twice or the pair is not OLD=NEW)."""
    out = dict(ref_cases)
    pairs = [p.split("=") for p in filter(None, spec.split(","))]
    for p in pairs:
        if len(p) != 2 or not all(p):
            raise ValueError(f"--rename {'='.join(p)!r}: expected OLD=NEW")
    for k, side in ((1, "new"), (0, "old")):
        if len({p[k] for p in pairs}) != len(pairs):
            raise ValueError(f"--rename {spec!r}: the same {side} name appears twice")
    moved = {}
    for old, new in pairs:
        if old not in ref_cases:
            raise ValueError(f"--rename {old}={new}: {old!r} is not a case of the reference tree")
        moved[new] = out.pop(old)
    out.update(moved)  # after all pops: a chain of renames (a=b, b=c) swaps names without losing a case
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("ref")
    ap.add_argument("--steps", type=int, default=0, help="cut every stage of the case-file demos to N steps")
    ap.add_argument("--only", default="", help="comma-separated case names")
    ap.add_argument("--skip", default="", help="comma-separated case names")
    ap.add_argument("--rename", default="", help="comma-separated OLD=NEW: REF's case OLD is the tree's case NEW")
    ap.add_argument("--rtol", type=float, default=1e-12)
    ap.add_argument("--work", default=None, help="scratch folder (default: a new temporary one, kept)")
    a = ap.parse_args(argv)
    work = a.work or tempfile.mkdtemp(prefix="compare_outputs_")
    ref_tree = os.path.join(work, "tree_ref")
    if not os.path.isdir(ref_tree):
        os.makedirs(ref_tree)
        arch = subprocess.run(["git", "-C", ROOT, "archive", a.ref], capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", ref_tree], input=arch, check=True)
    rev = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", a.ref], capture_output=True, text=True).stdout
    only = set(filter(None, a.only.split(",")))
    skip = set(filter(None, a.skip.split(",")))
    try:
        ref_cases = rename_cases(dict(cases(ref_tree, a.steps)), a.rename)
    except ValueError as e:
        print(f"compare_outputs: {e}", file=sys.stderr)
        return 2
    new_cases = {n: argv for n, argv in cases(ROOT, a.steps)}
    names = [n for n in sorted(set(ref_cases) | set(new_cases)) if (not only or n in only) and n not in skip]
    print(f"ref {a.ref} ({rev.strip()}) vs working tree {ROOT}; steps per stage: {a.steps or 'all (--quick)'}; "
          f"rtol {a.rtol:g}; outputs in {work}", flush=True)
    bad = 0
    for n in names:
        if n not in ref_cases or n not in new_cases:
            print(f"{n}: only in {'ref' if n in ref_cases else 'working tree'} (not compared)", flush=True)
            continue
        da, db = os.path.join(work, "ref", n), os.path.join(work, "new", n)
        mark = os.path.join(da, ".exit")
        if os.path.exists(mark):  # the reference runs of an earlier call with the same --work are reused
            with open(mark) as f:
                rca, ta = int(f.read().split()[0]), 0.0
        else:
            rca, ta = run(ref_tree, n, ref_cases[n], da)
            with open(mark, "w") as f:
                f.write(f"{rca} {ta}\n")
        rcb, tb = run(ROOT, n, new_cases[n], db)
        diffs, worst, notes = compare_dirs(da, db)
        if rca != rcb:
            diffs.insert(0, f"exit status {rca} vs {rcb} (see {da}/console.txt, {db}/console.txt)")
        ok = not diffs and worst[0] <= a.rtol
        bad += not ok
        verdict = ("identical bits" if not diffs and worst[0] == 0.0 else
                   f"largest relative difference {worst[0]:.2e} ({worst[1]})")
        print(f"{n}: {'OK' if ok else 'DIFFERENT'} - {verdict}; exit {rca}/{rcb}; {ta:.0f} s / {tb:.0f} s", flush=True)
        for d in (diffs + notes)[:10]:
            print(f"    {d}", flush=True)
        if len(diffs + notes) > 10:
            print(f"    ... and {len(diffs + notes) - 10} more", flush=True)
    print(f"compare_outputs: {'all ' + str(len(names)) + ' cases agree' if not bad else f'{bad} of {len(names)} cases differ'}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
