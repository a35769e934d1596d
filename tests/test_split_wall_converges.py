"""A split-brick wall at reduced size (issue #21): the shipped micro-model (demos/base/lourenco_rots_1997.toml:
mixed-mode joints with the softening cap, a potential crack in every full brick, viscous damage) on a wall of
4 courses × 2.5 bricks at p = 0.30 MPa, pre-compressed and pushed at the full-resolution step of the shipped walls
through its peak and well into softening, with sub-stepping switched off (`on_nonconvergence = "fail"`): every step
must converge to the residual tolerance at its nominal size. A Newton that stalls on a softening step (a wrong
Jacobian row, a broken line search or linear solve, a coupled pass that neither converges nor hands over) fails it
— such steps were sub-stepped down to h/8 before the coupled-pass changes of issue #21 (docs/benchmarks.md)."""
import json
import os

import pytest

pytestmark = pytest.mark.dolfinx
from _paths import ROOT  # noqa: E402

from fem_blocks.case import load_case  # noqa: E402
from fem_blocks.runner import run_case  # noqa: E402

CASE = """
extends = "{base}"
name = "small split-brick wall"
[wall]
rows = [[1, 1, 0.5], [0.5, 1, 1], [1, 1, 0.5], [0.5, 1, 1]]
[wall.beam.forces]
y = {{times = [0.0, 0.3], values = [0.0, -16500.0]}}   # N: 0.30 MPa x 0.55 m x 0.1 m
[contact]
on_nonconvergence = "fail"
"""


def test_small_split_brick_wall_converges_through_softening_without_substeps(tmp_path):
    base = os.path.join(ROOT, "demos", "base", "lourenco_rots_1997.toml")
    p = tmp_path / "small.toml"
    p.write_text(CASE.format(base=base))
    case = load_case(str(p))
    s = run_case(case, str(tmp_path / "out"), progress=False)
    conv = s["convergence"]
    assert s["status"] == "completed" and s["exit_status"] == 0
    assert conv["unconverged_steps"] == 0 and conv["substepped_steps"] == 0 and conv["failed_attempts"] == 0
    assert s["contact"]["max_residual"] <= 1e-6
    # it went through the peak and softened: the force fell below half the peak (the case's stop criterion) and the
    # joints dissipated fracture energy; the pre-compression held (the beam carries the applied 16.5 kN and more)
    assert s["stages"][1]["stopped"].startswith("force dropped by 50%")
    assert s["post_peak"]["end_to_peak"] < 0.5 + 0.05
    assert s["dissipated_energy_J"] > 1.0
    assert s["peak_horizontal_force_kN"] > 10.0 and -s["vertical_force_at_peak_kN"] >= 16.5 * (1 - 1e-6)
    with open(tmp_path / "out" / "summary.json") as f:
        assert json.load(f)["convergence"]["substepped_share"] == 0.0
