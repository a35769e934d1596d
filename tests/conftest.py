"""Shared test set-up. Paths (project root, demos, meshes, FCLIB data) have one home, tests/_paths.py, which
test modules import directly (`from _paths import ROOT`; pytest discourages importing conftest). Here: tests/ on
sys.path, so `_paths` and sibling test modules (`from test_output import _vtk_read`) import under any
`--import-mode`; and the same paths as fixtures for tests that prefer them."""
import os
import subprocess
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from _paths import DEMOS, FCLIB, ROOT  # noqa: E402


@pytest.fixture
def root() -> str:
    """The project root (the directory holding fem_blocks/, demos/, tests/)."""
    return ROOT


@pytest.fixture
def demo_path():
    """demo_path("arch.toml") -> the absolute path of demos/arch.toml."""
    return lambda name: os.path.join(DEMOS, name)


@pytest.fixture
def fclib_dir() -> str:
    """The FCLIB data directory (../shared/data/fclib beside the project). Missing: the test fails in CI (CI set),
    and is skipped elsewhere (a checkout without shared/ beside it)."""
    if not os.path.isdir(FCLIB):
        msg = f"FCLIB data not found at {FCLIB} (expected ../shared/data/fclib beside the project)"
        if os.environ.get("CI"):
            pytest.fail(msg)
        pytest.skip(msg)
    return FCLIB


@pytest.fixture
def cli(capsys):
    """cli("run", CASE, "--out", OUT, ...) -> subprocess.CompletedProcess(args, exit status, stdout, stderr) of
    `fem-blocks ARGS` run in this process (fem_blocks.cli.main: the command's own code, exit status and messages),
    instead of a `python -m fem_blocks.cli` launch (about 2.5 s of imports each). For runs that need their own
    process (killed, interrupted, a determinism check across processes, a count of every line on stderr: a Python
    warning goes to pytest here) the tests keep launching one; the process entry itself is run by
    tests/test_case.py and tests/test_demo.py."""
    def run(*args):
        from fem_blocks.cli import main
        capsys.readouterr()
        code = main([str(a) for a in args])
        out, err = capsys.readouterr()
        return subprocess.CompletedProcess(["fem-blocks", *map(str, args)], code, out, err)
    return run
