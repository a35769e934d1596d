"""summary.json `vertical_force_at_peak_kN`: the reaction of the beam's vertical dof when it is driven (blocked),
the applied force history when it is free (force control, e.g. a pre-compression held constant while pushing)."""
import copy
import os

import numpy as np
import pytest

from fem_blocks import casefile
from fem_blocks.case import parse_case
from fem_blocks.laws import LAW_KEYS
from fem_blocks.expand import expand
from fem_blocks.runner import _dof_control, _vertical_force

from _paths import ROOT  # noqa: E402
DEMO = casefile.read(os.path.join(ROOT, "demos", "shear_wall_fc_p030.toml"), LAW_KEYS)[0]  # with its base, laws resolved


def fake_history(stage, time, ry):
    return {"stage": np.asarray(stage, float), "time": np.asarray(time, float), "beam.Ry": np.asarray(ry, float)}


def test_blocked_vertical_dof_reports_the_reaction():
    case = expand(parse_case(copy.deepcopy(DEMO), "shear_wall_fc_p030.toml"))
    hist = fake_history([0, 0, 1, 1], [0.15, 0.4, 0.5, 0.9], [0.0, 0.0, -41234.5, -81234.5])
    # pre-compression: y free under the ramp 0 -> -29.7 kN over [0, 0.3] s (applied force, reaction column 0)
    assert _vertical_force(case, hist, "beam", 0) == pytest.approx(-14.85, rel=1e-12)
    assert _vertical_force(case, hist, "beam", 1) == pytest.approx(-29.7, rel=1e-12)
    # push with y blocked: the reaction
    assert _vertical_force(case, hist, "beam", 3) == pytest.approx(-81.2345, rel=1e-12)
    assert _dof_control(case, "beam", "y", 1)[0] == "driven"


def test_free_vertical_dof_reports_the_held_force():
    data = copy.deepcopy(DEMO)
    del data["stages"][1]["drivers"]["beam"]["y"]  # the pre-compression force stays applied while pushing
    data["stages"].append({"name": "unload", "duration": 0.1, "h": 0.01, "theta": 1.0,
                           "forces": {"beam": {"y": {"times": [1.4, 1.5], "values": [-29700.0, -9700.0]}}}})
    data["stages"].append({"name": "blocked", "duration": 0.1, "h": 0.01, "theta": 1.0,
                           "drivers": {"beam": {"y": {"kind": "velocity", "history": 0.0}}}})
    data["stages"].append({"name": "freed", "duration": 0.1, "h": 0.01, "theta": 1.0,
                           "drivers": {"beam": {"y": "free"}}})
    case = expand(parse_case(data, "variant.toml"))
    hist = fake_history([1, 2, 3, 4], [0.9, 1.45, 1.55, 1.65], [0.0, 0.0, -12345.0, 0.0])
    assert _dof_control(case, "beam", "y", 1)[0] == "force"
    assert _vertical_force(case, hist, "beam", 0) == pytest.approx(-29.7, rel=1e-12)   # held after the ramp
    assert _vertical_force(case, hist, "beam", 1) == pytest.approx(-19.7, rel=1e-12)   # stage force history
    assert _vertical_force(case, hist, "beam", 2) == pytest.approx(-12.345, rel=1e-12)  # driven again: reaction
    assert _vertical_force(case, hist, "beam", 3) == 0.0                                # freed: no applied force
