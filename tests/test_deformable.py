"""Deformable blocks without contact: vibration period, energy, static cantilever, shared factors,
rotated instances, ParaView output. Closed forms and invariants with stated tolerances."""
import dataclasses
import json
import subprocess
import sys

import meshio
import numpy as np
import pytest
import scipy.sparse.linalg as sla

from fem_blocks.bodies import BlockType, Clamp, DeformableBody, Material, Traction, rotation
from fem_blocks.dynamics import Simulation
from fem_blocks.meshing import mesh_rectangle
from fem_blocks.output.history import read_history

pytestmark = pytest.mark.dolfinx
from _paths import ROOT  # noqa: E402
STONE = Material(E=5e9, nu=0.2, rho=1800.0, thickness=0.1, plane="stress")


def first_mode(bt, clamped):
    free = np.flatnonzero(~clamped)
    K = bt.K[free][:, free].tocsc()
    M = bt.M[free][:, free].tocsc()
    w2, V = sla.eigsh(K, k=1, M=M, sigma=0.0, which="LM")
    phi = np.zeros(bt.ndof)
    phi[free] = V[:, 0]
    return float(np.sqrt(w2[0])), phi


@pytest.fixture(scope="module")
def beam():
    return BlockType(mesh_rectangle(1.0, 0.2, 0.05, cell="quad"), STONE, mass="lumped", name="beam")


def test_free_vibration_period_and_energy(beam):
    """Released from its first mode shape, the clamped block oscillates with the first eigen-period
    of (K, M) (within 1 %), and the theta = 1/2 scheme conserves energy to 1e-8 relative."""
    body = DeformableBody(beam, clamps=[Clamp(tag="left")])
    omega, phi = first_mode(beam, body.clamped)
    T = 2 * np.pi / omega
    h = T / 100
    body.q[:] = 1e-4 * phi / np.abs(phi).max()
    sim = Simulation([body], h=h, theta=0.5, gravity=(0.0, 0.0))
    e0 = sum(sim.energies())
    Mphi = beam.M @ phi
    a = [float(Mphi @ body.q)]
    energies = []
    for _ in range(250):
        sim.step()
        a.append(float(Mphi @ body.q))
        energies.append(sum(sim.energies()))
    a = np.array(a)
    s = np.sign(a)
    idx = np.flatnonzero(s[:-1] * s[1:] < 0)  # zero crossings, linear interpolation
    tz = (idx + a[idx] / (a[idx] - a[idx + 1])) * h
    T_sim = 2 * np.mean(np.diff(tz))
    assert len(tz) >= 4
    assert abs(T_sim - T) / T < 0.01
    assert np.max(np.abs(np.array(energies[:200]) - e0)) / e0 < 1e-8


def test_energy_decreases_with_theta_one(beam):
    body = DeformableBody(beam, clamps=[Clamp(tag="left")])
    omega, phi = first_mode(beam, body.clamped)
    body.q[:] = 1e-4 * phi / np.abs(phi).max()
    sim = Simulation([body], h=2 * np.pi / omega / 50, theta=1.0, gravity=(0.0, 0.0))
    e = [sum(sim.energies())]
    for _ in range(100):
        sim.step()
        e.append(sum(sim.energies()))
    assert np.all(np.diff(e) < 0)
    assert e[-1] < 0.5 * e[0]


def cantilever_tip(size, L=2.0, H=0.2, P=1e4):
    mat = Material(E=1e10, nu=0.25, rho=2000.0, thickness=0.1, plane="stress")
    bt = BlockType(mesh_rectangle(L, H, size, cell="quad"), mat, name="cantilever")
    tau = -P / (H * mat.thickness)
    body = DeformableBody(bt, clamps=[Clamp(tag="left")], tractions=[Traction("right", (0.0, tau), 1.0)])
    sim = Simulation([body], h=1.0, theta=1.0, gravity=(0.0, 0.0), velocity_reset=True)
    for _ in range(30):
        q_old = body.q.copy()
        sim.step()
        if np.abs(body.q - q_old).max() < 1e-14 * np.abs(body.q).max():
            break
    X = bt.mesh.points
    tip = np.flatnonzero(np.isclose(X[:, 0], L))
    v = -body.q[2 * tip + 1].mean()
    E, G, A, I = mat.E, mat.E / (2 * (1 + mat.nu)), H * mat.thickness, mat.thickness * H ** 3 / 12
    return v, P * L ** 3 / (3 * E * I) + P * L / (5 / 6 * G * A)


def test_static_cantilever_timoshenko():
    """Quasi-static (theta = 1, velocity reset) tip deflection of a slender (L/H = 10) clamped block under
    an end shear load: within 2 % of Timoshenko's PL^3/3EI + PL/(kGA) on the fine mesh, converging."""
    errs = []
    for size in (0.1, 0.05, 0.02):
        v, ref = cantilever_tip(size)
        errs.append(abs(v - ref) / ref)
    assert errs[-1] < 0.02
    assert errs[0] > errs[1] > errs[2]


def test_shared_factorization_and_rotated_instance(beam):
    """Instances of one type share one StepOperator (same factor object). A rotated instance gives the
    same global response as a block whose mesh was built rotated (independent K, M), to 1e-10."""
    a = DeformableBody(beam, position=(0, 0), clamps=[Clamp(box=(0, 0, 0, 0.2))])
    b = DeformableBody(beam, position=(3, 0), clamps=[Clamp(box=(3, 3, 0, 0.2))])
    sim = Simulation([a, b], h=1e-4, theta=0.5)
    assert len(sim.groups) == 1
    assert beam.step_operator(1e-4, 0.5, a.clamped) is beam.step_operator(1e-4, 0.5, b.clamped)
    assert beam.step_operator(1e-4, 0.5, a.clamped).factor is sim.groups[0].op.factor

    angle = np.deg2rad(35.0)
    R = rotation(angle)
    rot_inst = DeformableBody(beam, position=(1.0, 2.0), angle=angle, clamps=[Clamp(tag="left")])
    mesh_rot = dataclasses.replace(beam.mesh, points=beam.mesh.points @ R.T)
    bt_rot = BlockType(mesh_rot, STONE, name="rotated")
    indep = DeformableBody(bt_rot, position=(1.0, 2.0), clamps=[Clamp(tag="left")])
    s1 = Simulation([rot_inst], h=1e-4, theta=0.5)
    s2 = Simulation([indep], h=1e-4, theta=0.5)
    for _ in range(20):
        s1.step(); s2.step()
    d1, d2 = rot_inst.displacement_global(), indep.displacement_global()
    assert np.abs(d1 - d2).max() < 1e-10 * np.abs(d2).max()
    assert np.abs(rot_inst.current_points() - indep.current_points()).max() < 1e-12


def test_gravity_load_total_weight(beam):
    f = beam.gravity_load(np.array([0.0, -9.81]))
    mass = STONE.rho * 1.0 * 0.2 * STONE.thickness
    assert f[1::2].sum() == pytest.approx(-9.81 * mass, rel=1e-12)
    assert abs(f[0::2].sum()) < 1e-12 * mass


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "fem_blocks.cli", *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=600)


SMALL_CASE = """
name = "small"
[materials.m]
E = 1e9
nu = 0.25
rho = 2000.0
thickness = 0.2
plane = "strain"
[block_types.b]
geometry = "rectangle"
lx = 0.4
ly = 0.1
mesh_size = 0.05
material = "m"
[[blocks]]
type = "b"
[[blocks.clamps]]
tag = "left"
[[blocks]]
type = "b"
name = "tilted"
position = [1.0, 0.0]
angle = 30.0
[[blocks.clamps]]
tag = "left"
[[rigid_bodies]]
name = "plate"
vertices = [[0, -1], [1, -1], [1, -0.9], [0, -0.9]]
rho = 1000.0
[rigid_bodies.drivers.x]
kind = "displacement"
history = {times = [0.0, 0.01], values = [0.0, 0.001]}
[[stages]]
duration = 0.004
h = 0.001
output_every = 2
"""


def test_run_writes_paraview_history_summary(tmp_path, cli):
    case = tmp_path / "small.toml"
    case.write_text(SMALL_CASE)
    out = tmp_path / "out"
    p = cli("run", case, "--out", out, "--quiet")  # in this process (conftest.cli)
    assert p.returncode == 0, p.stderr
    assert "blocks.pvd" in p.stdout
    pvd = (out / "paraview" / "blocks.pvd").read_text()
    assert pvd.count("<DataSet") == 3  # t = 0, steps 2 and 4
    m = meshio.read(out / "paraview" / "blocks_000002.vtu")
    n_nodes = 2 * 9 * 3
    assert m.points.shape == (n_nodes + 4, 3)
    assert m.point_data["displacement"].shape[0] == n_nodes + 4
    assert m.point_data["velocity"].shape[0] == n_nodes + 4
    ncells = sum(len(c.data) for c in m.cells)
    assert ncells == 2 * 8 * 2 + 1
    stress = np.concatenate(m.cell_data["stress"])
    assert stress.shape[0] == ncells and stress.shape[1] >= 3
    assert np.concatenate(m.cell_data["von_mises"]).size == ncells
    body = np.concatenate(m.cell_data["body_id"]).ravel()
    assert set(body.tolist()) == {0, 1, 2}
    # the driven plate moved by d(t = 0.004) = 0.0004 m
    disp = m.point_data["displacement"]
    assert np.allclose(disp[n_nodes:, 0], 0.0004, rtol=1e-12)
    hist = read_history(out / "history.csv")
    assert len(hist["step"]) == 5 and list(hist["step"]) == [0, 1, 2, 3, 4]
    # driver reaction: the plate (m = 100 kg) jumps from rest to 0.1 m/s in the first step, then moves uniformly
    assert hist["plate.Rx"][1] == pytest.approx(100.0 * 0.1 / 0.001, rel=1e-12)
    assert np.allclose(hist["plate.Rx"][2:], 0.0, atol=1e-9)
    assert hist["plate.ux"][-1] == pytest.approx(0.0004, rel=1e-12)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == 4 and summary["n_block_types"] == 1 and summary["n_bodies"] == 3


def test_cli_rejects_inverted_mesh(tmp_path):
    msh = tmp_path / "bad.msh"
    msh.write_text("""$MeshFormat
2.2 0 8
$EndMeshFormat
$PhysicalNames
1
2 1 "block"
$EndPhysicalNames
$Nodes
4
1 0 0 0
2 1 0 0
3 1 1 0
4 0 1 0
$EndNodes
$Elements
2
1 2 2 1 1 1 2 3
2 2 2 1 1 1 4 3
$EndElements
""")
    case = tmp_path / "c.toml"
    case.write_text(f"""
[materials.m]
E = 1e9
nu = 0.2
rho = 1000.0
[block_types.t]
geometry = "file"
file = "bad.msh"
material = "m"
[[blocks]]
type = "t"
[[stages]]
duration = 0.01
h = 0.01
""")
    p = run_cli("run", str(case), "--out", str(tmp_path / "o"))
    assert p.returncode == 2, p.stderr
    assert "Traceback" not in p.stderr and len(p.stderr.strip().splitlines()) == 1
    assert "block_types.t" in p.stderr and "element 2 is inverted" in p.stderr
