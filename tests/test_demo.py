"""Smoke test of the default demo (solid shear wall, p = 0.30 MPa) in reduced-resolution mode."""
import json
import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.dolfinx
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_default_demo_quick(tmp_path):
    out = tmp_path / "demo"
    p = subprocess.run([sys.executable, "-m", "fem_blocks.cli", "demo", "--quick", "--quiet", "--out", str(out)],
                       capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    assert "ParaView files:" in p.stdout and "peak horizontal force" in p.stdout
    s = json.loads((out / "summary.json").read_text())
    assert s["name"].startswith("shear_wall_p030") and s["peak_horizontal_force_kN"] > 0
    for f in ("paraview/blocks.pvd", "paraview/contacts.pvd", "history.csv", "force_displacement.png",
              "crack_pattern.png", "checkpoint.npz"):
        assert (out / f).exists(), f
