"""Shear-wall cases of the masonry-test issue (speed issue, benchmark 4): every `demos/shear_wall*.toml` (except the
split-brick walls — the micro-model files `shear_wall_p030/_p121/_p212.toml` and the hollow wall, ≈ 20-50 min each at
--quick today, docs/validation.md — run only when named) run with
the CLI as a user would (`fem-blocks run CASE --out DIR`), then per case: contacts, wall time per phase (stage),
steps, contact-solver iterations per step (Newton iterations + Gauss–Seidel sweeps, or NLGS sweeps: the
`sweeps` column of history.csv), unconverged steps, peak horizontal force and total wall time.
Target: each case (both phases) under 10 minutes on this 2-core machine.

Usage: .venv/bin/python bench/bench_shear_walls.py [CASE.toml ...] [--quick] [--out DIR]
"""
import argparse
import csv
import glob
import json
import os
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


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="*")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench_shear_walls"))
    a = ap.parse_args()
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
