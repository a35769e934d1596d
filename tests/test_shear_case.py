"""Shear-wall protocol end to end on a reduced wall: force-controlled pre-compression, then a horizontal push
with the beam's vertical displacement blocked (stage drivers), stop after the peak, figures and summary."""
import json
import os

import numpy as np
import pytest

from fem_blocks.output.history import read_history

pytestmark = pytest.mark.dolfinx
from _paths import ROOT  # noqa: E402


def reduced_case(text: str) -> str:
    start = text.index("rows = [")
    end = text.index("]\n", text.index("\n]", start)) + 2
    text = text[:start] + "rows = [[1, 1, 0.5], [0.5, 1, 1], [1, 1, 0.5], [0.5, 1, 1]]\n" + text[end:]
    text = text.replace("values = [0.0, -29700.0]", "values = [0.0, -15000.0]")
    text = text.replace("mesh_size = 0.031", "mesh_size = 0.062")
    text = text.replace("values = [0.0, 0.004]", "values = [0.0, 0.002]")
    return text


def test_reduced_shear_wall_protocol(tmp_path, cli):
    case = tmp_path / "sw.toml"
    case.write_text(reduced_case(open(os.path.join(ROOT, "demos", "base", "shear_wall.toml")).read()))
    out = tmp_path / "out"
    p = cli("run", case, "--out", out, "--quiet")  # in this process (conftest.cli)
    assert p.returncode == 0, p.stderr
    s = json.loads((out / "summary.json").read_text())
    h = read_history(out / "history.csv")
    pre = h["stage"] == 0
    # end of pre-compression: the foundation carries the applied force + weights (quasi-static)
    width = 2.5 * 0.22
    weight = 2500.0 * 0.1 * (4 * width * 0.062) * 9.81 + 7800.0 * 0.1 * 0.1 * width * 9.81  # bricks + beam
    assert h["foundation.Ry"][pre][-1] == pytest.approx(15000.0 + weight, rel=1e-3)
    push = h["stage"] == 1
    assert np.all(h["beam.uy"][push] == h["beam.uy"][push][0])  # vertical displacement blocked
    assert s["peak_horizontal_force_kN"] > 0 and s["displacement_at_peak_mm"] > 0
    k = int(np.argmax(np.abs(h["beam.Rx"])))
    assert s["peak_horizontal_force_kN"] == pytest.approx(abs(h["beam.Rx"][k]) / 1e3, rel=1e-12)
    assert s["vertical_force_at_peak_kN"] == pytest.approx(h["beam.Ry"][k] / 1e3, rel=1e-12)
    # friction bound: the horizontal force cannot exceed cohesion + mu x vertical force on the bed joints
    assert s["peak_horizontal_force_kN"] < (0.75 * abs(h["beam.Ry"][k]) + width * 0.1 * np.sqrt(18 * 0.3e10)) / 1e3
    assert (out / "force_displacement.png").stat().st_size > 10000
    assert (out / "crack_pattern.png").stat().st_size > 10000
    assert s["dissipated_energy_J"] >= 0.0
