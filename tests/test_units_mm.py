"""`units = "mm-N-MPa"`: the same model written in SI and in mm, N, MPa (mass unit the tonne = N s²/mm) runs the
same history. Every converted quantity enters the run: lengths (vertices, block size, mesh size, position,
thickness, alert), E, rho, rigid `mass` and `inertia`, a force history, a moment history (N m / N mm) of a rigid body and one
set by a stage, a displacement-driver history, gravity, and the interface parameters c_N, c_T (stiffness), w (energy) and b
(Frémond viscosity, decohesion under way).

The mm file is written from the SI values with the factors stated here (independent of case.py's table):
length 1e3 mm/m, stress 1e-6 MPa/Pa, density 1e-12 (t/mm³)/(kg/m³), mass 1e-3 t/kg, inertia 1e3 t mm²/(kg m²),
stiffness 1e-9 (MPa/mm)/(Pa/m), energy and viscosity 1e-3 (N/mm)/(N/m), moment 1e3 N mm/(N m); forces in N and
times in s unchanged.
The outputs (history.csv) are SI in both runs: every column agrees to 1e-9 of its largest value (measured: 3e-12;
solver diagnostics excepted). Sensitivity (measured, SI run): doubling b moves the top block by 8e-5 relative,
doubling its inertia by 8 %, its mass by 70 %, so a missing or wrong factor on any of them fails."""
import csv

import numpy as np
import pytest

from fem_blocks.case import load_case
from fem_blocks.runner import run_case

pytestmark = pytest.mark.dolfinx

TEMPLATE = """
name = "units"
{units}
gravity = [0.0, {g}]
[contact]
tol = 1e-12
max_sweeps = 100000
[materials.stone]
E = {E}
nu = 0.2
rho = {rho}
thickness = {t}
[block_types.slab]
geometry = "rectangle"
lx = {lx}
ly = {ly}
mesh_size = {ms}
material = "stone"
[[blocks]]
name = "slab"
type = "slab"
position = [{x0}, 0.0]
[[rigid_bodies]]
name = "base"
group = "base"
vertices = [[{bx0}, {by0}], [{bx1}, {by0}], [{bx1}, 0.0], [{bx0}, 0.0]]
thickness = {t}
[rigid_bodies.drivers]
x = {{kind = "velocity", history = 0.0}}
y = {{kind = "displacement", history = {{times = [0.0, 0.01], values = [0.0, {settle}]}}}}
rz = {{kind = "velocity", history = 0.0}}
[[rigid_bodies]]
name = "top"
group = "top"
vertices = [[{x0}, {ly}], [{tx1}, {ly}], [{tx1}, {ty1}], [{x0}, {ty1}]]
thickness = {t}
mass = {mass}
inertia = {inertia}
[rigid_bodies.forces]
x = {{times = [0.0, 0.01], values = [0.0, 1500.0]}}
rz = {{times = [0.0, 0.01], values = [0.0, {mz}]}}
[[interfaces]]
name = "bed"
between = ["blocks", "base"]
mu = 5.0
alert = {alert}
[[interfaces]]
name = "glue"
between = ["top", "blocks"]
law = "fremond"
mu = 0.5
c_N = {cN}
c_T = {cT}
w = {w}
b = {b}
alert = {alert}
[[stages]]
name = "push"
duration = 0.01
h = 1e-3
theta = 0.7
output_every = 100
[[stages]]
name = "turn"
duration = 0.005
h = 1e-3
theta = 0.7
output_every = 100
[stages.forces.top]
rz = {{times = [0.01, 0.015], values = [{mz}, {mz2}]}}
"""

SI = dict(units="", g=-9.81, E=1e10, rho=2000.0, t=0.1, lx=0.4, ly=0.2, ms=0.2, x0=0.05, bx0=-0.1, by0=-0.1,
          bx1=0.6, settle=-2e-5, tx1=0.4, ty1=0.3, mass=40.0, inertia=0.5, alert=1e-3, cN=1e10, cT=5e9, w=0.01,
          b=0.01, mz=20.0, mz2=60.0)
LENGTHS = ("g", "t", "lx", "ly", "ms", "x0", "bx0", "by0", "bx1", "settle", "tx1", "ty1", "alert")
FACTORS = dict({k: 1e3 for k in LENGTHS}, E=1e-6, rho=1e-12, mass=1e-3, inertia=1e3, cN=1e-9, cT=1e-9, w=1e-3,
               b=1e-3, mz=1e3, mz2=1e3)


def run(tmp_path, name, values):
    path = tmp_path / f"{name}.toml"
    path.write_text(TEMPLATE.format(**{k: (repr(v) if not isinstance(v, str) else v) for k, v in values.items()}))
    out = tmp_path / name
    run_case(load_case(str(path)), str(out), progress=False)
    with open(out / "history.csv") as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) if r[k] not in ("", "None") else np.nan for r in rows]) for k in rows[0]}


def test_mm_n_mpa_case_runs_the_same_history_as_si(tmp_path):
    mm = {k: (v * FACTORS[k] if k in FACTORS else v) for k, v in SI.items()}
    mm["units"] = 'units = "mm-N-MPa"'
    a = run(tmp_path, "si", SI)
    b = run(tmp_path, "mm", mm)
    assert a.keys() == b.keys() and len(a["step"]) == 16
    for k in a:
        if k in ("sweeps", "change", "residual"):  # solver diagnostics: round-off changes a sweep count by 1
            continue
        scale = np.nanmax(np.abs(a[k])) if np.any(np.isfinite(a[k])) else 0.0
        np.testing.assert_allclose(b[k], a[k], rtol=0, atol=1e-9 * scale + 1e-300, equal_nan=True, err_msg=k)
    # the load is carried through the joints: the top block slides on the glue, which is decohering
    assert a["top.ux"][-1] > 1e-6 and a["slip"][-1] > 0
