"""`[stages.stop_after_peak]` fires: a rigid block glued by a Frémond joint (rate-independent) to a fixed base is
pulled off at a constant rate; the step and the force at which the run stops are computed by hand from the
closed-form opening curve (thesis eq. 5.3.47, docs/method.md §4):

    r_N = A c_N u                 for u <= u_c = sqrt(w / c_N)   (β = 1)
    r_N = A w² / (c_N u³)         for u >  u_c                   (β = w / (c_N u²))

Opening u_k = 0.045 k u_c at step k (h = 0.01 s, 4.5 u_c per second). Peak at k = 22 (u = 0.99 u_c):
F_peak = 0.99 A sqrt(w c_N). With drop = 0.3 the run stops at the first k >= min_steps with
F_k < 0.7 F_peak, i.e. (0.045 k)³ > 1/(0.7 · 0.99) = 1.443, 0.045 k > 1.1298, k > 25.1: step 26, where
F = A sqrt(w c_N) / 1.17³ (step 25: 1/1.125³ = 0.702 > 0.693, not yet).
"""
import csv

import numpy as np
import pytest

from fem_blocks.case import load_case
from fem_blocks.runner import run_case

CN, W, L, T = 1e10, 50.0, 0.2, 0.1
UC = np.sqrt(W / CN)
A = L * T

CASE = f"""
name = "peak"
gravity = [0.0, 0.0]
[contact]
tol = 1e-12
max_sweeps = 10000
[[rigid_bodies]]
name = "block"
group = "block"
vertices = [[0.0, 0.0], [{L}, 0.0], [{L}, 0.1], [0.0, 0.1]]
thickness = {T}
[rigid_bodies.drivers]
x = {{kind = "velocity", history = 0.0}}
y = {{kind = "displacement", history = {{times = [0.0, 1.0], values = [0.0, {4.5 * UC!r}]}}}}
rz = {{kind = "velocity", history = 0.0}}
[[rigid_bodies]]
name = "base"
group = "base"
vertices = [[-0.1, -0.1], [0.3, -0.1], [0.3, 0.0], [-0.1, 0.0]]
thickness = {T}
[rigid_bodies.drivers]
x = {{kind = "velocity", history = 0.0}}
y = {{kind = "velocity", history = 0.0}}
rz = {{kind = "velocity", history = 0.0}}
[[interfaces]]
name = "joint"
between = ["block", "base"]
law = "fremond"
mu = 0.5
c_N = {CN!r}
c_T = 5e9
w = {W!r}
placement = "positions"
positions = [0.25, 0.75]
[[stages]]
name = "pull"
duration = 0.6
h = 0.01
theta = 1.0
output_every = 100
[stages.stop_after_peak]
body = "block"
dof = "y"
drop = 0.3
min_steps = 5
"""


def test_run_stops_after_peak_at_hand_computed_step(tmp_path):
    path = tmp_path / "peak.toml"
    path.write_text(CASE)
    summary = run_case(load_case(str(path)), str(tmp_path / "out"), progress=False)
    with open(tmp_path / "out" / "history.csv") as f:
        rows = list(csv.DictReader(f))
    F = np.array([abs(float(r["block.Ry"])) for r in rows])
    steps = [int(r["step"]) for r in rows]
    assert steps[-1] == 26, steps[-1]                      # not the 60 steps of the stage
    peak = np.sqrt(W * CN) * A
    assert F.max() == pytest.approx(0.99 * peak, rel=1e-9)
    assert steps[int(np.argmax(F))] == 22
    assert F[-1] == pytest.approx(peak / 1.17 ** 3, rel=1e-9)
    assert F[-2] == pytest.approx(peak / 1.125 ** 3, rel=1e-9) and F[-2] >= 0.7 * F.max()
    assert "force dropped by 30% after its peak" in repr(summary), summary
