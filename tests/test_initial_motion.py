"""Initial velocity and spin of bodies (docs/case-files.md "Initial velocity and spin"): the initial state's
kinetic energy, momentum and angular momentum against the closed forms of a rectangle / box computed here,
m = ρ a b t, I = m (a² + b²)/12 (box: I = diag(m(b² + c²), m(a² + c²), m(a² + b²))/12 in its axes), KE =
½ m |v|² + ½ I ω² (3D: ½ ωᵀ R I0 Rᵀ ω). The consistent mass matrix integrates the rigid field exactly (it is linear in
x, so the Q4/hex interpolation reproduces it), hence 1e-12; the lumped one has the exact mass and momentum only."""
import copy
import math

import numpy as np
import pytest

from fem_blocks.case import parse_case
from fem_blocks.dynamics import Simulation
from fem_blocks.model import build_model

pytestmark = pytest.mark.dolfinx

A, B, T, RHO = 0.4, 0.2, 0.1, 2500.0
V, W = (1.0, -0.5), 3.0

CASE2D = {
    "gravity": [0.0, 0.0],
    "materials": {"stone": {"E": 1e10, "nu": 0.2, "rho": RHO, "thickness": T}},
    "block_types": {"r": {"geometry": "rectangle", "lx": A, "ly": B, "mesh_size": 0.05, "material": "stone",
                          "mass": "consistent"}},
    "blocks": [{"type": "r", "name": "blk", "position": [0.3, 0.7], "angle": 30.0,
                "initial_velocity": list(V), "initial_spin": W}],
    "rigid_bodies": [{"name": "rb", "vertices": [[2, 0], [2 + A, 0], [2 + A, B], [2, B]], "rho": RHO,
                      "thickness": T, "initial_velocity": list(V), "initial_spin": W}],
    "stages": [{"name": "s", "duration": 1e-3, "h": 1e-4}],
}


def _sim(data):
    case = parse_case(copy.deepcopy(data), "init.toml")
    model = build_model(case)
    st = case.stages[0]
    return model, Simulation(model.bodies, h=st.h, theta=0.5, gravity=model.gravity)


def _momenta_2d(body):
    """(m, p, L about the mass centre, KE) of a deformable body's state, from its mass matrix."""
    M = body.type.M
    u = body.u
    Mu = (M @ u).reshape(-1, 2) @ body.R.T  # global nodal momenta
    ex = np.zeros(body.type.ndof)
    ex[0::2] = 1.0
    w = (M @ ex)[0::2]
    m = w.sum()
    c = w @ body.reference_points / m
    r = body.reference_points - c
    return m, Mu.sum(axis=0), float(np.sum(r[:, 0] * Mu[:, 1] - r[:, 1] * Mu[:, 0])), 0.5 * float(u @ (M @ u))


def test_initial_state_2d_closed_form():
    model, sim = _sim(CASE2D)
    blk, rb = model.bodies
    m = RHO * A * B * T
    I = m * (A ** 2 + B ** 2) / 12
    ke = 0.5 * m * (V[0] ** 2 + V[1] ** 2) + 0.5 * I * W ** 2
    mm, p, L, k = _momenta_2d(blk)
    assert mm == pytest.approx(m, rel=1e-12)
    assert p == pytest.approx(m * np.array(V), rel=1e-12)
    assert L == pytest.approx(I * W, rel=1e-12)
    assert k == pytest.approx(ke, rel=1e-12)
    assert rb.u == pytest.approx([V[0], V[1], W], rel=1e-15)
    assert rb.mass == pytest.approx([m, m, I], rel=1e-12)
    kin = sim.energies()[0]
    assert kin == pytest.approx(2 * ke, rel=1e-12)


def test_free_block_keeps_its_momentum_and_the_rigid_body_flies():
    model, sim = _sim(CASE2D)
    blk, rb = model.bodies
    m = RHO * A * B * T
    for _ in range(10):
        sim.step()
    _, p, _, _ = _momenta_2d(blk)
    assert p == pytest.approx(m * np.array(V), rel=1e-12)  # 1ᵀ K = 0: no net internal force
    assert rb.q == pytest.approx([V[0] * 1e-3, V[1] * 1e-3, W * 1e-3], rel=1e-12)


def test_lumped_mass_has_the_exact_momentum():
    data = copy.deepcopy(CASE2D)
    data["block_types"]["r"]["mass"] = "lumped"
    model, _ = _sim(data)
    m = RHO * A * B * T
    mm, p, _, _ = _momenta_2d(model.bodies[0])
    assert mm == pytest.approx(m, rel=1e-12) and p == pytest.approx(m * np.array(V), rel=1e-12)


def test_initial_state_3d_closed_form():
    a, b, c = 0.3, 0.2, 0.1
    v, w = np.array([0.5, -0.2, 0.1]), np.array([1.0, 2.0, -0.5])
    data = {
        "dimension": 3,
        "gravity": [0.0, 0.0, 0.0],
        "materials": {"stone": {"E": 1e10, "nu": 0.2, "rho": RHO}},
        "block_types": {"bx": {"geometry": "box", "size": [a, b, c], "divisions": [2, 2, 1], "material": "stone",
                               "mass": "consistent"}},
        "blocks": [{"type": "bx", "position": [0.0, 0.0, 0.0], "rotation_axis": [1.0, 1.0, 0.0],
                    "rotation_angle": 40.0, "initial_velocity": v.tolist(), "initial_spin": w.tolist()}],
        "stages": [{"name": "s", "duration": 1e-3, "h": 1e-4}],
    }
    model, sim = _sim(data)
    blk = model.bodies[0]
    m = RHO * a * b * c
    I0 = m / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    Ig = blk.R @ I0 @ blk.R.T
    ke = 0.5 * m * v @ v + 0.5 * w @ Ig @ w
    assert sim.energies()[0] == pytest.approx(ke, rel=1e-12)
    M = blk.type.M
    Mu = (M @ blk.u).reshape(-1, 3) @ blk.R.T
    assert Mu.sum(axis=0) == pytest.approx(m * v, rel=1e-12)
    ex = np.zeros(blk.type.ndof)
    ex[0::3] = 1.0
    wn = (M @ ex)[0::3]
    r = blk.reference_points - wn @ blk.reference_points / wn.sum()
    assert np.cross(r, Mu).sum(axis=0) == pytest.approx(Ig @ w, rel=1e-11, abs=1e-12 * m)
