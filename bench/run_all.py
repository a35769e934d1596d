"""Run every benchmark and print the markdown tables (copy them into docs/benchmarks.md with the date).
`make bench` runs the short set (a few minutes); `BENCH_FULL=1 make bench` adds the 10⁴-brick walls and the six
full shear-wall cases (about an hour on 2 cores)."""
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
FULL = os.environ.get("BENCH_FULL") == "1"
sizes = ["100", "1000"] + (["10000"] if FULL else [])
RUNS = [("bench_kernel.py", []),
        ("bench_lmgc90_wall.py", []),
        ("bench_wall.py", sizes + ["--joints", "dry"]),
        ("bench_wall.py", sizes + ["--joints", "fremond"]),
        ("bench_contact_solvers.py", []),
        ("bench_lu.py", [] if FULL else ["--quick"]),
        ("bench_shear_walls.py", [] if FULL else ["--quick"])]
for script, args in RUNS:
    print(f"\n## {script} {' '.join(args)}\n", flush=True)
    subprocess.run([sys.executable, os.path.join(HERE, script), *args], check=True)
