"""Launching a test's helper on N MPI ranks, defined once: the Open MPI environment of the suite (root allowed,
oversubscription for N above the cores, no single-copy transport in containers, the project on PYTHONPATH) and the
launch of a script in tests/ that must end, and end well, within a time bound.
"""
import os
import shutil
import subprocess
import sys

import pytest

from _paths import ROOT

ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           OMPI_MCA_rmaps_base_oversubscribe="1", OMPI_MCA_btl_vader_single_copy_mechanism="none", PYTHONPATH=ROOT)


def run_helper(n: int, script: str, *args, timeout: float = 120):
    """`mpirun -n N python tests/SCRIPT ARGS...` from the project root: skips the test without mpirun, fails it if
    the launch does not end within `timeout` seconds (a rank left waiting) or ends with a nonzero status (the end of
    its output in the message). Returns the CompletedProcess."""
    if shutil.which("mpirun") is None:
        pytest.skip("no mpirun")
    try:
        p = subprocess.run(["mpirun", "-n", str(n), sys.executable, os.path.join(ROOT, "tests", script),
                            *map(str, args)], capture_output=True, text=True, cwd=ROOT, env=ENV, timeout=timeout)
    except subprocess.TimeoutExpired as e:
        pytest.fail(f"a rank was left waiting: the launch did not end in {timeout:g} s\n{e.stdout}\n{e.stderr}")
    assert p.returncode == 0, (p.stdout + p.stderr)[-3000:]
    return p


def run_alone(script: str, *args):
    """tests/SCRIPT ARGS... on one process, in this one (the serial reference of a helper run under mpirun by
    `run_helper`): the script run as `__main__` with these arguments (runpy), MPI.COMM_WORLD of size 1 as in a
    launch of its own, without the launch's seconds of imports; an error in it fails the test."""
    import runpy
    argv = sys.argv
    sys.argv = [os.path.join(ROOT, "tests", script), *map(str, args)]
    try:
        runpy.run_path(sys.argv[0], run_name="__main__")
    finally:
        sys.argv = argv


def rank_results(out, size: int) -> list:
    """The JSON files OUT.<rank>.json that a helper's ranks 0..size-1 wrote, read, in rank order."""
    import json
    return [json.loads(open(f"{out}.{r}.json").read()) for r in range(size)]
