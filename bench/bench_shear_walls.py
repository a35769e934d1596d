"""Shear-wall cases of the masonry-test issue (speed issue, benchmark 4): every `demos/shear_wall*.toml` (except the
split-brick walls — the micro-model files `shear_wall_p030/_p121/_p212.toml` and the hollow wall, ≈ 20-50 min each at
--quick today, docs/validation.md — run only when named) run with
the CLI as a user would (`fem-blocks run CASE --out DIR`), then per case: contacts, wall time per phase (stage),
steps, contact-solver iterations per step (Newton iterations + Gauss–Seidel sweeps, or NLGS sweeps: the
`sweeps` column of history.csv), unconverged steps, peak horizontal force and total wall time.
Target: each case (both phases) under 10 minutes on this 2-core machine.

Usage: .venv/bin/python bench/bench_shear_walls.py [CASE.toml ...] [--quick] [--out DIR]
       .venv/bin/python bench/bench_shear_walls.py --breakdown CASE.toml [--quick] [--out DIR] [--steps N]
              [--resume-from DIR] [--set KEY=VALUE ...]

--breakdown: one case in this process (a window of steps, not the whole run), with a per-stage cost breakdown:
wall time per nominal step, history rows, Newton iterations and Gauss–Seidel sweeps per row (from the solver's
message), the share of time in the contact solve (solver + law commit), detection/Delassus assembly, the local
problem, the velocity corrections, the free-velocity solves, outputs (history, ParaView, checkpoints, snapshots)
and, separately, the time and iterations of the attempts that "refine"/"adaptive" threw away (the calls of
Simulation.step between a snapshot and the restore that undid them). --steps N cuts every stage to its first N
steps (resumed: N more steps in the checkpoint's stage); --resume-from copies DIR (a run's output directory with a
checkpoint, e.g. the end of the pre-compression) into the output and resumes from it (--force: the cut case differs
from the one that wrote it); --set contact.KEY=VALUE (TOML value) changes a [contact] key, stages.NAME.KEY=VALUE a
stage key. A window ended by SIGTERM (the runner checkpoints and stops) is still reported.
"""
import argparse
import csv
import glob
import json
import os
import re
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def split_bricks(path):
    """Whether the case file (with its bases) asks for split bricks."""
    sys.path.insert(0, ROOT)
    from fem_blocks import casefile
    from fem_blocks.laws import LAW_KEYS
    return bool(casefile.read(path, LAW_KEYS)[0].get("wall", {}).get("split_bricks", False))


def run_case(path, out, quick):
    name = os.path.splitext(os.path.basename(path))[0]
    d = os.path.join(out, name)
    cmd = [sys.executable, "-m", "fem_blocks.cli", "run", path, "--out", d] + (["--quick"] if quick else [])
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    if p.returncode not in (0, 3):  # 3: completed with unconverged steps (counted in the table)
        return dict(name=name, error=f"exit {p.returncode}: {p.stderr.strip().splitlines()[-1:]}")
    with open(os.path.join(d, "summary.json")) as f:
        s = json.load(f)
    with open(os.path.join(d, "history.csv")) as f:
        rows = list(csv.DictReader(f))
    stages = []
    for st in s["stages"]:
        its = [int(float(r["sweeps"])) for r in rows if r["stage"] == st["name"]]
        stages.append(dict(name=st["name"], steps=st["steps"], wall=st["wall_time"],
                           it_mean=sum(its) / max(len(its), 1), it_max=max(its, default=0),
                           unconverged=st["unconverged_steps"]))
    contacts = max((int(float(r["contacts"])) for r in rows), default=0)
    return dict(name=name, contacts=contacts, stages=stages, setup=s.get("setup_time", 0.0), wall=wall,
                peak=s.get("peak_horizontal_force_kN"), at=s.get("displacement_at_peak_mm"))


_ITS = re.compile(r"(\d+) Newton iterations, (\d+) Gauss-Seidel sweeps")


def _toml_value(text):
    import tomllib
    return tomllib.loads(f"v = {text}")["v"]


def _reopen_stage(out, case):
    """A window run ends its (cut) stage: when the checkpoint in `out` closed a stage before the case's own end of
    it, reopen it (stage_done false, its summary entry dropped) so that the resumed run goes on in that stage."""
    import numpy as np
    from fem_blocks.output.checkpoint import latest_checkpoint, write_checkpoint
    _, ck = latest_checkpoint(out)
    si, k = int(ck["run.stage"]), int(ck["run.k"])
    st = case.stages[si]
    if not bool(ck["run.stage_done"]) or k >= int(round(st.duration / st.h)):
        return
    d = {key: ck[key] for key in ck if key != "_digest"}
    extra = json.loads(str(d["run.json"]))
    extra["stages_done"] = extra["stages_done"][:-1]
    d["run.json"], d["run.stage_done"] = np.array(json.dumps(extra)), np.bool_(False)
    write_checkpoint(out, d)


def breakdown(path, out, quick, steps=None, resume_from=None, sets=()):
    """Cost breakdown of one case run in this process (module docstring). Returns one dict per stage."""
    import dataclasses
    import shutil
    sys.path.insert(0, ROOT)
    from fem_blocks import runner
    from fem_blocks.case import load_case, quick as make_quick
    from fem_blocks.contact.step import ContactStep
    from fem_blocks.dynamics import Simulation
    from fem_blocks.output import history, paraview, contacts
    case = load_case(path)
    if quick:
        case = make_quick(case)
    for kv in sets:
        key, _, val = kv.partition("=")
        v = _toml_value(val)
        if key.startswith("contact."):
            case.contact = dataclasses.replace(case.contact, **{key.split(".", 1)[1]: v})
        else:
            _, name, k = key.split(".", 2)
            for st in case.stages:
                if st.name == name:
                    setattr(st, k, v)
    if steps:  # the window: N steps per stage; resumed: N more steps in the checkpoint's stage
        si, k = -1, 0
        if resume_from:
            from fem_blocks.output.checkpoint import latest_checkpoint
            _, ck = latest_checkpoint(resume_from)
            si, k = int(ck["run.stage"]), int(ck["run.k"])
        for i, st in enumerate(case.stages):
            if i >= si:
                st.duration = min(st.duration, ((k if i == si else 0) + steps) * st.h)
    if os.path.exists(out):
        shutil.rmtree(out)
    if resume_from:
        shutil.copytree(resume_from, out)
        _reopen_stage(out, case)
    T = dict(free=0.0, output=0.0, snapshot=0.0)
    calls = []      # per Simulation.step: [stage, seconds, newton its, gs sweeps, sweeps, failed]
    mark = [0]      # index of the first step call since the last snapshot/restore
    stage = [None]

    def timed(obj, name, key):
        f = getattr(obj, name)

        def w(*a, **k):
            t = time.perf_counter()
            try:
                return f(*a, **k)
            finally:
                T[key] += time.perf_counter() - t
        setattr(obj, name, w)
        return f

    saved = [(Simulation, "free_velocities", timed(Simulation, "free_velocities", "free"))]
    for mod, cls in ((history, "HistoryWriter"), (paraview, "BodiesWriter"), (contacts, "ContactsWriter")):
        saved.append((getattr(mod, cls), "write", timed(getattr(mod, cls), "write", "output")))
    saved.append((runner, "write_checkpoint", timed(runner, "write_checkpoint", "output")))
    step0, snap0, rest0, enter0 = Simulation.step, runner._snapshot, runner._restore, runner._enter_stage
    nominal0 = runner._step
    nominal = {}  # stage -> nominal steps run in this window

    def nominal_step(*a, **k):
        nominal[stage[0]] = nominal.get(stage[0], 0) + 1
        return nominal0(*a, **k)

    def step(sim):
        t, c0 = time.perf_counter(), time.process_time()
        info = step0(sim)
        c = info.contact or {}
        m = _ITS.search(str(c.get("message", "")))
        calls.append([stage[0], time.perf_counter() - t, int(m.group(1)) if m else 0,
                      int(m.group(2)) if m else int(c.get("sweeps", 0)), int(c.get("sweeps", 0)), False,
                      time.process_time() - c0])
        return info

    def snapshot(*a):
        t = time.perf_counter()
        mark[0] = len(calls)
        d = snap0(*a)
        T["snapshot"] += time.perf_counter() - t
        return d

    def restore(*a):
        for c in calls[mark[0]:]:
            c[5] = True
        mark[0] = len(calls)
        return rest0(*a)

    def enter(model, sim, case_, si, *a):
        stage[0] = case_.stages[si].name
        return enter0(model, sim, case_, si, *a)

    Simulation.step, runner._snapshot, runner._restore, runner._enter_stage = step, snapshot, restore, enter
    runner._step = nominal_step
    t_run, c_run = time.perf_counter(), time.process_time()
    cs_timers = {}
    init0 = ContactStep.__init__

    def init(self, *a, **k):
        init0(self, *a, **k)
        cs_timers["t"] = self.timers
    ContactStep.__init__ = init
    try:
        try:
            summary = runner.run_case(case, out, progress=False, resume=bool(resume_from), force=True)
        except runner.RunStopped as e:  # (e.g. SIGTERM to end a window early: the summary was written)
            print(f"stopped: {e}", file=sys.stderr)
            with open(os.path.join(out, "summary.json")) as f:
                summary = json.load(f)
    finally:
        Simulation.step, runner._snapshot, runner._restore, runner._enter_stage = step0, snap0, rest0, enter0
        runner._step = nominal0
        ContactStep.__init__ = init0
        for obj, name, f in saved:
            setattr(obj, name, f)
    wall, cpu = time.perf_counter() - t_run, time.process_time() - c_run
    tm = cs_timers.get("t", {})
    rows = []
    walls = {st["name"]: st["wall_time"] for st in summary["stages"]}
    for name in dict.fromkeys(c[0] for c in calls):  # the stages run in this window, in order
        st = dict(name=name, wall_time=walls.get(name, sum(c[1] for c in calls if c[0] == name)))
        cl = [c for c in calls if c[0] == st["name"]]
        kept = [c for c in cl if not c[5]]
        lost = [c for c in cl if c[5]]
        rows.append(dict(stage=st["name"], steps=nominal.get(st["name"], 0), rows=len(kept), wall=st["wall_time"],
                         cpu=sum(c[6] for c in cl), step_time=sum(c[1] for c in cl),
                         failed_time=sum(c[1] for c in lost),
                         failed_calls=len(lost), newton=sum(c[2] for c in kept), gs=sum(c[3] for c in kept),
                         failed_its=sum(c[4] for c in lost), max_its=max((c[4] for c in kept), default=0)))
    total = dict(wall=wall, cpu=cpu, solver=tm.get("nlgs", 0.0), detection=tm.get("detection", 0.0),
                 local=tm.get("local", 0.0), correction=tm.get("correction", 0.0), **T,
                 convergence=summary.get("convergence"), setup=summary.get("setup_time"))
    return rows, total


def print_breakdown(rows, total):
    print("| stage | nominal steps | rows | wall [s] | s per nominal step (CPU s) | Newton its / row | "
          "GS sweeps / row | max its (row) | thrown-away attempts: calls, time [s], iterations |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        n, ns = max(r["rows"], 1), max(r["steps"], 1)
        print(f"| {r['stage']} | {r['steps']} | {r['rows']} | {r['wall']:.1f} | "
              f"{r['wall'] / ns:.2f} ({r['cpu'] / ns:.2f}) | "
              f"{r['newton'] / n:.0f} | {r['gs'] / n:.0f} | {r['max_its']} | {r['failed_calls']}, "
              f"{r['failed_time']:.1f}, {r['failed_its']} |")
    w = total["wall"]
    parts = [("contact solve (solver + law commit)", total["solver"]),
             ("detection + Delassus assembly", total["detection"]), ("local problem", total["local"]),
             ("velocity corrections", total["correction"]), ("free-velocity solves", total["free"]),
             ("outputs (history, ParaView, checkpoints)", total["output"]), ("snapshots", total["snapshot"])]
    rest = w - sum(t for _, t in parts)
    print(f"\nrun (after set-up {total['setup']:.1f} s): {w:.1f} s wall, {total['cpu']:.1f} s CPU of this process; "
          + "; ".join(
        f"{k} {t:.1f} s ({t / w:.0%})" for k, t in parts) + f"; other {rest:.1f} s ({rest / w:.0%})")
    conv = total["convergence"] or {}
    print(f"convergence: {conv.get('unconverged_steps')} unconverged of {conv.get('solved_steps')} rows; "
          f"sub-stepped {conv.get('substepped_steps')} of {conv.get('nominal_steps')} nominal steps; "
          f"{conv.get('failed_attempts')} attempts thrown away")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="*")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench_shear_walls"))
    ap.add_argument("--breakdown", action="store_true", help="per-phase cost breakdown of one case (docstring)")
    ap.add_argument("--steps", type=int, default=None)
    ap.add_argument("--resume-from", default=None)
    ap.add_argument("--set", action="append", default=[])
    a = ap.parse_args()
    if a.breakdown:
        if len(a.cases) != 1:
            ap.error("--breakdown: expected one CASE.toml")
        rows, total = breakdown(os.path.abspath(a.cases[0]), a.out, a.quick, a.steps, a.resume_from, a.set)
        print_breakdown(rows, total)
        sys.exit(0)
    # the split-brick walls (≈ 20-50 min each at --quick, docs/validation.md) only when named
    cases = a.cases or sorted(f for f in glob.glob(os.path.join(ROOT, "demos", "shear_wall*.toml"))
                              if not split_bricks(f))
    print("| case | contacts | setup [s] | phase: steps, wall time [s], iterations/step mean (max), unconverged "
          "| total wall time [s] | peak horizontal force [kN] (at mm) |")
    print("|---|---|---|---|---|---|")
    for c in cases:
        r = run_case(os.path.abspath(c), a.out, a.quick)
        if "error" in r:
            print(f"| {r['name']} | failed: {r['error']} | | | | |", flush=True)
            continue
        ph = "; ".join(f"{st['name']}: {st['steps']}, {st['wall']:.1f}, {st['it_mean']:.1f} ({st['it_max']}), "
                       f"{st['unconverged']}" for st in r["stages"])
        pk = "—" if r["peak"] is None else f"{r['peak']:.1f} ({r['at']:.2f})" if r["at"] is not None else f"{r['peak']:.1f}"
        print(f"| {r['name']} | {r['contacts']} | {r['setup']:.1f} | {ph} | {r['wall']:.0f} | {pk} |", flush=True)
