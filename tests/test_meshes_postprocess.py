"""Shipped gmsh sources load with their physical groups; the history plotting script runs."""
import os
import subprocess
import sys

import numpy as np
import pytest

from fem_blocks.meshing import load_geo

from _paths import ROOT  # noqa: E402


def test_voussoir_geo_loads_with_tags():
    m = load_geo(os.path.join(ROOT, "meshes", "voussoir.geo"))
    assert set(m.tag_names) >= {"joint_lower", "joint_upper", "extrados", "intrados"}
    a = np.pi / 30
    assert m.area() == pytest.approx(a * (1.3 ** 2 - 1.0 ** 2), rel=0.01)  # annular sector, polygonal arcs
    lower = m.boundary_edges[m.edge_tags == m.tag_names["joint_lower"]]
    L = np.linalg.norm(m.points[lower[:, 1]] - m.points[lower[:, 0]], axis=1).sum()
    assert L == pytest.approx(0.3, rel=1e-12)


def test_plot_history_script(tmp_path):
    h = tmp_path / "h.csv"
    h.write_text("step,time,beam.ux,beam.Rx\n0,0,0,0\n1,0.1,0.001,5\n2,0.2,0.002,7\n")
    out = tmp_path / "p.png"
    p = subprocess.run([sys.executable, os.path.join(ROOT, "postprocess", "plot_history.py"), str(h), "beam.ux",
                        "beam.Rx", "-o", str(out)], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert out.stat().st_size > 5000
    p = subprocess.run([sys.executable, os.path.join(ROOT, "postprocess", "plot_history.py"), str(h), "beam.ux",
                        "nope"], capture_output=True, text=True, timeout=120)
    assert p.returncode != 0 and "column 'nope'" in p.stderr
