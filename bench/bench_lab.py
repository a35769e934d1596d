"""The virtual laboratory's catalogue: every `[lab]` demo run through the command line, one after the other.

Prints per demo: wall time [s], CPU time of the child [s], exit status, the contact solver's iterations summed over
the specimens' history.csv (`sweeps`: Newton iterations or NLGS sweeps; robust under load), and the read-out's
quantities; then the catalogue's total. Issue #23's targets: each demo <= 60 s, the catalogue <= 5 min on the 2-core
machine. Usage: `.venv/bin/python bench/bench_lab.py [--quick] [--out DIR] [NAME ...]` (default: all [lab] demos).
"""
from __future__ import annotations

import argparse
import csv
import glob
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def lab_demos() -> list[str]:
    out = []
    for f in sorted(glob.glob(os.path.join(ROOT, "demos", "*.toml"))):
        with open(f, encoding="utf-8") as fh:
            if any(line.strip() == "[lab]" for line in fh):
                out.append(os.path.splitext(os.path.basename(f))[0])
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("names", nargs="*")
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", default=None, help="output folder (default: a new temporary folder)")
    a = p.parse_args(argv)
    if a.out is None:
        a.out = tempfile.mkdtemp(prefix="bench_lab_")
    names = a.names or lab_demos()
    total_wall = total_cpu = 0.0
    print(f"{'demo':24s} {'wall s':>7s} {'cpu s':>7s} {'exit':>4s} {'iterations':>10s}  quantities")
    for nm in names:
        out = os.path.join(a.out, nm)
        cmd = [sys.executable, "-m", "fem_blocks.cli", "run", os.path.join(ROOT, "demos", nm + ".toml"), "--out", out,
               "--quiet"] + (["--quick"] if a.quick else [])
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
        total_wall += wall
        total_cpu += cpu
        it, q = 0, {}
        sp = os.path.join(out, "summary.json")
        if os.path.exists(sp):
            with open(sp) as f:
                s = json.load(f)
            q = {k: v["value"] for k, v in s["quantities"].items()}
            for spec in s["specimens"]:
                with open(os.path.join(out, spec["dir"], "history.csv")) as f:
                    it += sum(int(float(r["sweeps"] or 0)) for r in csv.DictReader(f))
        qs = ", ".join(f"{k} {v:.5g}" for k, v in list(q.items())[:3])
        print(f"{nm:24s} {wall:7.1f} {cpu:7.1f} {proc.returncode:4d} {it:10d}  {qs}", flush=True)
    print(f"{'catalogue':24s} {total_wall:7.1f} {total_cpu:7.1f}   (load average {os.getloadavg()[0]:.2f} at the end)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
