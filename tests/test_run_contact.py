"""End to end: a case file with a [wall] prism on a foundation, interfaces, an equilibrium stop; outputs."""
import json
import os
import subprocess
import sys

import meshio
import numpy as np
import pytest

from fem_blocks.case import load_case
from fem_blocks.errors import InputError
from fem_blocks.output.history import read_history

pytestmark = pytest.mark.dolfinx
from _paths import ROOT  # noqa: E402

CASE = """
name = "prism"
[materials.brick]
E = 5e9
nu = 0.2
rho = 2000.0
thickness = 0.1
[wall]
type = "prism"
material = "brick"
brick_length = 0.2
brick_height = 0.05
bricks = 3
mesh_size = 0.05
[wall.foundation]
depth = 0.05
[contact]
tol = 1e-10
max_sweeps = 100000
[[interfaces]]
name = "bed"
between = ["bricks", "bricks"]
mu = 0.6
[[interfaces]]
name = "base"
between = ["bricks", "foundation"]
mu = 0.6
[[stages]]
name = "gravity"
duration = 1.0
h = 1e-3
theta = 1.0
velocity_reset = true
output_every = 100
[stages.stop_at_equilibrium]
max_velocity = 1e-9
min_steps = 5
"""


def test_prism_case_runs_to_equilibrium_with_contact_outputs(tmp_path, cli):
    case = tmp_path / "prism.toml"
    case.write_text(CASE)
    out = tmp_path / "out"
    p = cli("run", case, "--out", out, "--quiet")  # in this process (conftest.cli)
    assert p.returncode == 0, p.stderr
    s = json.loads((out / "summary.json").read_text())
    st = s["stages"][0]
    assert st["stopped"].startswith("equilibrium") and st["steps"] < 1000
    assert s["contact"]["unconverged"] == 0
    h = read_history(out / "history.csv")
    weight = 2000.0 * 3 * 0.2 * 0.05 * 0.1 * 9.81
    assert h["foundation.Ry"][-1] == pytest.approx(weight, rel=1e-6)
    assert h["contacts"][-1] == 3 * 5  # default placement "overlap": the 5 nodes of each of the 3 bed faces
    assert set(np.unique(h["converged"][1:])) == {1.0}
    pvd = (out / "paraview" / "contacts.pvd").read_text()
    assert pvd.count("<DataSet") == pvd_count(out / "paraview" / "blocks.pvd")
    last = sorted(os.listdir(out / "paraview"))
    m = meshio.read(out / "paraview" / [f for f in last if f.startswith("contacts_")][-1])
    assert len(m.points) == 15
    for field in ("reaction", "r_N", "r_T", "normal", "gap", "status", "interface", "area"):
        assert field in m.point_data
    rN = np.asarray(m.point_data["r_N"]).ravel()
    iface = np.asarray(m.point_data["interface"]).ravel()
    assert rN[iface == 1].sum() == pytest.approx(weight, rel=1e-6)  # base joint carries the whole prism
    Ry = np.asarray(m.point_data["reaction"])[:, 1]
    assert Ry[iface == 1].sum() == pytest.approx(weight, rel=1e-6)  # force of the foundation on the bricks, upward
    # tributary length x thickness: half an element (0.025 m) at the 2 corners of a face, one (0.05 m) inside
    assert np.sort(np.asarray(m.point_data["area"]).ravel()) == pytest.approx([0.025 * 0.1] * 6 + [0.05 * 0.1] * 9)


def pvd_count(path):
    return path.read_text().count("<DataSet")


@pytest.mark.parametrize("edit, message", [
    (("mu = 0.6\n[[interfaces]]", "mu = -0.6\n[[interfaces]]"), r"interfaces\[0\]\.mu: = -0\.6: expected a number >= 0"),
    (('between = ["bricks", "bricks"]', 'between = ["bricks", "mortar"]'), r"interfaces\[0\]\.between: group 'mortar'"),
    (("bricks = 3", "bricks = 0"), r"wall\.bricks: = 0: expected an integer >= 1"),
    (("[contact]\ntol = 1e-10", "[contact]\ntol = -1.0"), r"contact\.tol: = -1\.0: expected a number > 0"),
    (("mesh_size = 0.05", "mesh_size = 0.05\nopenings = [[0, 0, 1, 1]]"), r"wall\.openings: unknown key|wall: unknown"),
])
def test_contact_case_errors(tmp_path, edit, message):
    case = tmp_path / "c.toml"
    case.write_text(CASE.replace(*edit))
    with pytest.raises(InputError, match=message):
        load_case(str(case))


def test_interface_law_keys_validated_with_units(tmp_path):
    base = CASE.replace('name = "bed"\nbetween = ["bricks", "bricks"]\nmu = 0.6',
                        'name = "bed"\nbetween = ["bricks", "bricks"]\nlaw = "fremond"\nmu = 0.6\nc_N = 1e10\n'
                        'c_T = 5e9\nw = 20.0')
    case = tmp_path / "c.toml"
    case.write_text(base)
    c = load_case(str(case))
    assert c.interfaces[0].law == "fremond" and c.interfaces[0].params == {"c_N": 1e10, "c_T": 5e9, "w": 20.0}
    case.write_text(base.replace("w = 20.0", "w = -2.0"))
    with pytest.raises(InputError, match=r"c\.toml: interfaces\[0\]\.w = -2\.0: expected adhesion energy w > 0"):
        load_case(str(case))
    case.write_text(base.replace("w = 20.0", "w = 20.0\nG_I = 3.0"))
    with pytest.raises(InputError, match=r"interfaces\[0\]\.G_I: unknown parameter for law 'fremond'"):
        load_case(str(case))
    mm = base.replace('name = "prism"', 'name = "prism"\nunits = "mm-N-MPa"').replace("c_N = 1e10", "c_N = 10.0")
    mm = mm.replace("c_T = 5e9", "c_T = 5.0").replace("w = 20.0", "w = 0.02")
    case.write_text(mm)
    with pytest.raises(InputError, match=r"materials\.brick\.rho: = 2000\.0 .*check `units`"):
        load_case(str(case))  # SI density in a mm-N-MPa file: 2e15 kg/m^3, a unit mix-up
    mm = mm.replace("E = 5e9", "E = 5000.0").replace("rho = 2000.0", "rho = 2e-9").replace("thickness = 0.1",
                                                                                          "thickness = 100.0")
    case.write_text(mm)
    c = load_case(str(case))
    assert c.interfaces[0].params["c_N"] == pytest.approx(1e10)  # 10 MPa/mm = 1e10 N/m^3
    assert c.interfaces[0].params["w"] == pytest.approx(20.0)    # 0.02 N/mm = 20 J/m^2


def test_cohesive_case_writes_law_state_to_paraview_and_checkpoint(tmp_path, cli):
    from fem_blocks.output.checkpoint import read_checkpoint
    text = CASE.replace('name = "bed"\nbetween = ["bricks", "bricks"]\nmu = 0.6',
                        'name = "bed"\nbetween = ["bricks", "bricks"]\nlaw = "fremond"\nmu = 0.6\nc_N = 1e10\n'
                        'c_T = 5e9\nw = 20.0').replace("[[stages]]", "[output]\ncheckpoint_every = 5\n\n[[stages]]")
    case = tmp_path / "c.toml"
    case.write_text(text)
    out = tmp_path / "out"
    p = cli("run", case, "--out", out, "--quiet")
    assert p.returncode == 0, p.stderr
    ck = read_checkpoint(out / "checkpoint.npz")
    h = read_history(out / "history.csv")
    assert int(ck["sim.step"]) == int(h["step"][-1])  # written at the end of the stage
    assert ck["contact.state"].shape == (15, 7) and np.array_equal(np.unique(ck["contact.law"]), [0, 4])
    assert np.allclose(ck["contact.state"][ck["contact.law"] == 4, 0], 1.0)  # beta intact under gravity
    files = sorted(f for f in os.listdir(out / "paraview") if f.startswith("contacts_"))
    m = meshio.read(out / "paraview" / files[-1])
    for field in ("law", "damage", "opening", "slip", "dissipated"):
        assert field in m.point_data
    assert np.allclose(np.asarray(m.point_data["damage"]).ravel(), 0.0)


def test_arch_case_stands_under_gravity(tmp_path, cli):
    """[arch] builder: 15 voussoirs of one block type (rotated instances) on rigid piers; t/R = 0.26 stands."""
    from fem_blocks.case import load_case
    from fem_blocks.expand import expand
    c = load_case(os.path.join(ROOT, "demos", "arch.toml"))
    assert c.blocks == [] and c.rigid_bodies == [] and len(c.generators) == 1  # parsed: the [arch] as given
    c = expand(c)
    assert len(c.blocks) == 15 and len(c.block_types) == 1 and [r.name for r in c.rigid_bodies] == ["pier0", "pier1"]
    assert len({b.angle for b in c.blocks}) == 15
    out = tmp_path / "arch"
    p = cli("run", os.path.join(ROOT, "demos", "arch.toml"), "--out", out, "--quiet")
    assert p.returncode == 0, p.stderr
    h = read_history(out / "history.csv")
    assert h["max_velocity"][-1] < 1e-4  # at rest: the arch stands
    weight = 2000.0 * 9.81 * 15 * 0.5 * (np.pi / 15) * (1.3 ** 2 - 1.0 ** 2)
    assert h["pier0.Ry"][-1] + h["pier1.Ry"][-1] == pytest.approx(weight, rel=0.01)  # polygonal arcs: ~0.1 %


def test_stage_forces_and_drivers(tmp_path, cli):
    """A later stage applies a force on a previously driven dof of the beam (freed), and freeing a dof of a
    massless body is a clear error."""
    text = CASE.replace("[wall.foundation]\ndepth = 0.05", "[wall.foundation]\ndepth = 0.05\n[wall.beam]\ndepth = 0.05\n"
                        "rho = 7800.0\n[wall.beam.drivers]\nx = {kind = \"velocity\", history = 0.0}\n"
                        "y = {kind = \"velocity\", history = 0.0}\nrz = {kind = \"velocity\", history = 0.0}")
    text = text.replace('''[[interfaces]]
name = "base"''', '''[[interfaces]]
name = "top"
between = ["bricks", "beam"]
mu = 0.6

[[interfaces]]
name = "base"''')
    text += '''
[[stages]]
name = "load"
duration = 0.05
h = 1e-3
theta = 1.0
velocity_reset = true
[stages.forces.beam]
y = -500.0
'''
    case = tmp_path / "c.toml"
    case.write_text(text)
    out = tmp_path / "out"
    p = cli("run", case, "--out", out, "--quiet")
    assert p.returncode == 0, p.stderr
    h = read_history(out / "history.csv")
    weight = 2000.0 * 3 * 0.2 * 0.05 * 0.1 * 9.81 + 7800.0 * 0.05 * 0.2 * 0.1 * 9.81
    assert h["beam.Ry"][-1] == 0.0  # y is free in stage 2: no driver reaction
    assert h["foundation.Ry"][-1] == pytest.approx(weight + 500.0, rel=1e-4)
    bad = text.replace("[stages.forces.beam]", "[stages.forces.foundation]")
    case.write_text(bad)  # its own process: one line on stderr, nothing else (no warning, no traceback)
    p = subprocess.run([sys.executable, "-m", "fem_blocks.cli", "run", str(case), "--out", str(out), "--quiet"],
                       capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1
    assert "stages[1].forces.foundation.y: body 'foundation' has no mass" in p.stderr
