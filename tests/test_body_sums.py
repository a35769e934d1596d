"""Sums over bodies (fem_blocks/dynamics.py, module docstring): the energies and the step's works are exact sums
of per-body terms, each term from its body's arrays alone. So they are the same doubles whatever the grouping and
order of the bodies, and the sum over a set of bodies is math.fsum of the single bodies' values, bitwise. (On N > 1
ranks each rank adds its own bodies' terms: tests/test_dist_run.py compares the histories' energy columns of 1, 2
and 3 ranks bit for bit.)

Catches: a sum over a group's whole (ndof, k) array with NumPy (its order of addition follows the array's shape:
the bits change with the members' order and number), a per-body reduction by NumPy's own `sum(axis=0)` (pairwise
for one body, row by row for several), a body's term dropped or counted twice, a term added outside the exact sum."""
import math

import numpy as np
import pytest

from fem_blocks.bodies import BlockType, DeformableBody, Driver, Material, RigidBody, Traction
from fem_blocks.dynamics import Simulation
from fem_blocks.meshing import mesh_rectangle

from _mpi import run_helper

pytestmark = pytest.mark.dolfinx

MAT = Material(E=1e9, nu=0.2, rho=2000.0, thickness=0.1)
SQUARE = [[0.0, 0.0], [0.3, 0.0], [0.3, 0.2], [0.0, 0.2]]


@pytest.fixture(scope="module")
def types():
    return (BlockType(mesh_rectangle(0.2, 0.1, 0.05, cell="quad"), MAT, mass="lumped", name="q4"),
            BlockType(mesh_rectangle(0.3, 0.1, 0.1, cell="quad"), MAT, mass="consistent", name="q4c"))


def bodies(types, order, corotational=False):
    """Six deformable bodies of two types (two with a traction) and two rigid bodies (one loaded, one driven), each
    body's q and u drawn from a generator seeded by its number, listed in `order`."""
    out = []
    for i in order:
        rng = np.random.default_rng(100 + i)
        if i < 6:
            tractions = [Traction("top", (1e5 * i, -2e5))] if i in (1, 4) else []
            b = DeformableBody(types[i % 2], position=(0.4 * i, 0.1 * i), angle=0.3 * i, tractions=tractions)
            b.q[:] = 1e-4 * rng.standard_normal(b.q.shape)
            b.u[:] = rng.standard_normal(b.u.shape)
        else:
            drivers = {"x": Driver("velocity", 0.25), "rz": Driver("velocity", 0.0)} if i == 7 else None
            b = RigidBody([[x + i, y] for x, y in SQUARE], rho=1500.0, thickness=0.1, drivers=drivers,
                          forces={"x": 40.0, "rz": 3.0} if i == 6 else None)
            b.q[:] = 1e-3 * rng.standard_normal(3)
            b.u[:] = rng.standard_normal(3)
        out.append(b)
    return out


def sums(sim):
    """The energies, then one step's external, driver and inertia work."""
    e = sim.energies()
    sim.step()
    return (*e, sim.external_work, sim.driver_work, sim.inertia_work)


@pytest.mark.parametrize("shape", [(30, 1), (375, 4), (54, 127), (54, 128), (7, 300), (1, 5), (0, 3)])
def test_column_sums_add_each_column_in_row_order(shape):
    """dynamics.column_sums: each column's sum is the rows added one by one in order (a Python loop of float
    additions here), for few and many columns (its two ways) and a column alone."""
    from fem_blocks.dynamics import column_sums
    X = np.random.default_rng(3).standard_normal(shape) * 10.0 ** np.random.default_rng(4).integers(-8, 8, shape)
    want = []
    for j in range(shape[1]):
        s = 0.0
        for i in range(shape[0]):
            s = s + float(X[i, j])
        want.append(s)
    assert column_sums(X).tolist() == want


ORDERS = [list(range(8)), [7, 5, 3, 1, 6, 4, 2, 0], [2, 6, 0, 4, 1, 7, 3, 5]]


@pytest.mark.parametrize("corotational", [False, True])
def test_sums_do_not_depend_on_the_bodies_order_or_grouping(types, corotational):
    """The same eight bodies listed in three orders (the groups' members in other orders), and each body alone in
    its own simulation: every sum is the same double, and is math.fsum of the single bodies' values."""
    def run(order):
        return sums(Simulation(bodies(types, order, corotational), h=1e-3, theta=0.5, corotational=corotational))
    ref = run(ORDERS[0])
    for order in ORDERS[1:]:
        assert run(order) == ref
    alone = np.array([run([i]) for i in range(8)])
    assert ref == tuple(math.fsum(alone[:, k]) for k in range(alone.shape[1]))
    assert all(math.isfinite(x) and x != 0.0 for x in ref[:5])  # (a term of each kind was added)


def test_kinetic_energy_of_a_translation_closed_form(types):
    """Every body translating at v (no deformation, lumped and consistent mass): kinetic energy ½ Σ m_b |v|² with
    m_b = ρ t A_b (1e-13 relative: the rounding of the per-dof products), elastic energy 0."""
    v = np.array([0.6, -0.8])
    bs = bodies(types, range(6))
    for b in bs:
        b.q[:] = 0.0
        b.u[:] = np.tile(b.R.T @ v, len(b.u) // 2)  # the type frame's components of v
    kin, ela, _ = Simulation(bs, h=1e-3).energies()
    mass = MAT.rho * MAT.thickness * sum(0.2 * 0.1 if i % 2 == 0 else 0.3 * 0.1 for i in range(6))
    assert kin == pytest.approx(0.5 * mass * (v @ v), rel=1e-13)
    assert ela == 0.0


@pytest.mark.parametrize("n", [2, 3])
def test_each_rank_adds_its_own_bodies_terms(n):
    """The same bodies partitioned over N ranks (tests/_body_sums_mpi.py; on 3 ranks rank 0 owns none, the two
    rigid bodies on different ranks): every rank's energies and works are one process's sums, bitwise. Catches a
    rank adding every body's terms (each counted N times after the all-reduce), the rigid bodies' terms added on
    every rank, the all-reduce left out (each rank its part)."""
    p = run_helper(n, "_body_sums_mpi.py")
    assert "same bits on every rank" in p.stdout
