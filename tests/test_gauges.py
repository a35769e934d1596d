"""Displacement gauges (`[output] gauges`, fem_blocks/output/gauges.py).

Closed forms: (1) the linear/bilinear/trilinear interpolation of each cell reproduces a linear field exactly, so the
weights of any point inside a distorted cell give f(x) = a + b·x to round-off; (2) a block squeezed between two
frictionless rigid plates is in uniform strain, u_y = -d y / H and u_x = ν d (x - x_c) / H (plane stress), at any
point of any mesh: the gauges read it to 1e-6 of d.
"""
import csv

import numpy as np
import pytest

from fem_blocks.output.gauges import cell_weights, locate


def _linear(x):
    return 0.3 + x @ np.array([1.7, -2.2, 0.9][:len(x)])


@pytest.mark.parametrize("cell_type,X", [
    ("triangle", np.array([[0.0, 0.0], [1.0, 0.1], [0.2, 0.9]])),
    ("quad", np.array([[0.0, 0.0], [1.2, 0.1], [1.0, 0.8], [-0.1, 1.1]])),   # distorted (not a parallelogram)
    ("tetrahedron", np.array([[0.0, 0.0, 0.0], [1.0, 0.1, 0.0], [0.1, 1.0, 0.1], [0.0, 0.2, 1.1]])),
    ("hexahedron", np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                             [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=float)
     + 0.05 * np.sin(np.arange(24.0)).reshape(8, 3)),
])
def test_weights_reproduce_linear_fields(cell_type, X):
    """Inside: Σ N_a = 1 and Σ N_a f(X_a) = f(x) to 1e-12 (catches a wrong node order, a wrong shape function or
    an unconverged inverse map); a point well outside gives None."""
    rng = np.random.default_rng(1)
    f = np.array([_linear(p) for p in X])
    for _ in range(20):
        lam = rng.dirichlet(np.ones(len(X)))   # a convex combination of the nodes: inside the cell
        x = lam @ X
        w = cell_weights(X, x, cell_type)
        assert w is not None
        assert w.sum() == pytest.approx(1.0, abs=1e-12)
        assert w @ f == pytest.approx(_linear(x), abs=1e-12)
        assert np.allclose(w @ X, x, atol=1e-12)
    assert cell_weights(X, X.mean(axis=0) + 5.0, cell_type) is None


def test_locate_finds_the_cell_of_a_point():
    """Two triangles of the unit square: (0.8, 0.1) lies in the lower-right one only."""
    P = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    C = np.array([[0, 2, 3], [0, 1, 2]])
    c, w = locate(P, C, "triangle", [0.8, 0.1])
    assert c == 1 and np.allclose(w @ P[C[1]], [0.8, 0.1])
    assert locate(P, C, "triangle", [1.5, 0.5]) is None


SQUEEZE = """
name = "squeeze"
gravity = [0.0, 0.0]
[materials.stone]
E = 1.0e9
nu = 0.25
rho = 2000.0
thickness = 0.1
[block_types.b]
geometry = "rectangle"
lx = 0.2
ly = 0.4
mesh_size = 0.07
cell = "triangle"
material = "stone"
[[blocks]]
name = "block"
type = "b"
position = [0.0, 0.0]
group = "block"
[[rigid_bodies]]
name = "base"
group = "plates"
vertices = [[-0.1, -0.05], [0.3, -0.05], [0.3, 0.0], [-0.1, 0.0]]
[rigid_bodies.drivers]
x = {kind = "velocity", history = 0.0}
y = {kind = "velocity", history = 0.0}
rz = {kind = "velocity", history = 0.0}
[[rigid_bodies]]
name = "press"
group = "plates"
vertices = [[-0.1, 0.4], [0.3, 0.4], [0.3, 0.45], [-0.1, 0.45]]
[rigid_bodies.drivers]
x = {kind = "velocity", history = 0.0}
y = {kind = "displacement", history = {times = [0.0, 0.5, 2.0], values = [0.0, -1.0e-4, -1.0e-4]}}
rz = {kind = "velocity", history = 0.0}
[[interfaces]]
between = ["block", "plates"]
mu = 0.0
[contact]
solver = "newton"
tol = 1e-12
max_sweeps = 200
[output]
paraview = false
crack_pattern = false
gauges = [{name = "a", block = "block", point = [0.031, 0.057]},
          {name = "b", block = "block", point = [0.163, 0.311]},
          {name = "c", block = "block", point = [0.1, 0.2]}]
[[stages]]
duration = 2.0
h = 0.05
theta = 1.0
velocity_reset = true
"""


@pytest.mark.dolfinx
def test_gauges_read_uniform_strain(tmp_path):
    """Uniform compression by d = 0.1 mm of a 0.2 x 0.4 m block between frictionless plates (triangles, nodes
    not at the gauges): u_y(x) = -d y / H, and u_x(b) - u_x(a) = ν d (x_b - x_a) / H, within 1e-6 d."""
    from fem_blocks.cli import main
    case = tmp_path / "squeeze.toml"
    case.write_text(SQUEEZE)
    out = tmp_path / "out"
    assert main(["run", str(case), "--out", str(out), "--quiet"]) == 0
    last = list(csv.DictReader(open(out / "history.csv")))[-1]
    d, H, nu = 1.0e-4, 0.4, 0.25
    pts = dict(a=(0.031, 0.057), b=(0.163, 0.311), c=(0.1, 0.2))
    for g, (x, y) in pts.items():
        assert float(last[f"{g}.uy"]) == pytest.approx(-d * y / H, abs=1e-6 * d)
    dux = float(last["b.ux"]) - float(last["a.ux"])
    assert dux == pytest.approx(nu * d * (0.163 - 0.031) / H, abs=1e-6 * d)


@pytest.mark.dolfinx
def test_gauge_outside_its_block_is_exit_2(tmp_path, capsys):
    from fem_blocks.cli import main
    case = tmp_path / "squeeze.toml"
    case.write_text(SQUEEZE.replace("point = [0.163, 0.311]", "point = [0.263, 0.311]"))
    assert main(["check", str(case)]) == 2
    err = capsys.readouterr().err
    assert "output.gauges[1].point" in err and "outside block 'block'" in err
