"""Run every benchmark and print the markdown tables (copy them into docs/benchmarks.md with the date)."""
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
for script, args in (("bench_kernel.py", []), ("bench_wall.py", ["100", "1000"])):
    print(f"\n## {script}\n", flush=True)
    subprocess.run([sys.executable, os.path.join(HERE, script), *args], check=True)
