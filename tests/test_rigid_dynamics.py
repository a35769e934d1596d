"""Rigid bodies under the theta-method without contact: closed forms (no dolfinx needed)."""
import numpy as np
import pytest

from fem_blocks.bodies import Driver, History, RigidBody, polygon_properties
from fem_blocks.dynamics import Simulation
from fem_blocks.errors import InputError

SQUARE = [(0, 0), (2, 0), (2, 1), (0, 1)]


def test_polygon_properties_rectangle():
    A, c, J = polygon_properties(np.array(SQUARE, float))
    assert A == pytest.approx(2.0, rel=1e-15)
    assert np.allclose(c, [1.0, 0.5], rtol=1e-15)
    assert J == pytest.approx(2.0 * (4 + 1) / 12, rel=1e-14)  # m (a^2 + b^2) / 12


def test_free_flight_exact_theta_half():
    """x(t) = x0 + v0 t + g t^2 / 2 is reproduced exactly by the trapezoidal (theta = 1/2) rule."""
    g = np.array([0.0, -9.81])
    b = RigidBody(SQUARE, rho=2000.0, thickness=0.2)
    b.u[:] = [1.5, 4.0, 0.7]
    sim = Simulation([b], h=1e-3, theta=0.5, gravity=g)
    for _ in range(500):
        sim.step()
    t = sim.time
    expected = np.array([1.5 * t, 4.0 * t - 0.5 * 9.81 * t * t, 0.7 * t])
    assert np.allclose(b.q, expected, rtol=1e-12, atol=0)
    assert np.allclose(b.u, [1.5, 4.0 - 9.81 * t, 0.7], rtol=1e-12)
    assert np.allclose(b.center, np.array([1.0, 0.5]) + expected[:2], rtol=1e-12)


def test_free_flight_energy_conserved():
    b = RigidBody(SQUARE, rho=1000.0)
    b.u[:] = [0.0, 3.0, 2.0]
    sim = Simulation([b], h=1e-3, theta=0.5)
    e0 = sum(sim.energies())
    for _ in range(300):
        sim.step()
    assert sum(sim.energies()) == pytest.approx(e0, rel=1e-12)


def test_driven_dof_reaction_is_weight():
    """A body held by a driver (zero velocity) under gravity: the driver reaction balances m g."""
    b = RigidBody(SQUARE, rho=1000.0, thickness=0.5, drivers={"y": Driver("velocity", 0.0)})
    m = 1000.0 * 2.0 * 0.5
    sim = Simulation([b], h=1e-2, theta=1.0)
    sim.step()
    assert b.reaction[1] == pytest.approx(m * 9.81, rel=1e-14)
    assert b.q[1] == 0.0
    assert b.u[0] == 0.0 and b.reaction[0] == 0.0  # free dof: no reaction


def test_displacement_driver_followed_exactly_and_reaction():
    """Prescribed displacement d(t) = a t^2/2 (piecewise linear samples): position exact at step ends;
    the reaction on the driven dof equals m * (velocity change)/h - applied force."""
    times = np.linspace(0.0, 1.0, 11)
    hist = History(times, 0.1 * times ** 2)
    b = RigidBody(SQUARE, mass=10.0, drivers={"x": Driver("displacement", hist)},
                  forces={"y": 5.0})
    sim = Simulation([b], h=0.05, theta=0.5, gravity=(0.0, 0.0))
    for _ in range(20):
        u0 = b.u.copy()
        sim.step()
        assert b.q[0] == pytest.approx(hist(sim.time), abs=1e-15)
        assert b.reaction[0] == pytest.approx(10.0 * (b.u[0] - u0[0]) / 0.05, rel=1e-12, abs=1e-12)
    # the free y dof carries the applied force: v = F t / m, trapezoidal rule exact
    assert b.u[1] == pytest.approx(5.0 / 10.0 * sim.time, rel=1e-12)
    assert b.q[1] == pytest.approx(0.5 * 5.0 / 10.0 * sim.time ** 2, rel=1e-12)


def test_velocity_reset_quasi_static():
    b = RigidBody(SQUARE, rho=1000.0)
    sim = Simulation([b], h=0.1, theta=1.0, velocity_reset=True)
    sim.step(); sim.step()
    # with reset, each step starts at rest: u = h g, dq = h^2 g (theta = 1)
    assert b.u[1] == pytest.approx(-0.981, rel=1e-14)
    assert b.q[1] == pytest.approx(-2 * 0.1 * 0.981, rel=1e-14)


@pytest.mark.parametrize("kwargs, field", [
    (dict(h=0.0), "h"), (dict(h=-1.0), "h"), (dict(theta=0.4), "theta"), (dict(theta=1.2), "theta"),
])
def test_bad_step_parameters(kwargs, field):
    b = RigidBody(SQUARE, rho=1000.0)
    args = dict(h=1e-3, theta=0.5)
    args.update(kwargs)
    with pytest.raises(InputError, match=rf"^{field} = .*expected"):
        Simulation([b], **args)


def test_bad_rigid_inputs():
    with pytest.raises(InputError, match="rho = -1.0: expected rho > 0"):
        RigidBody(SQUARE, rho=-1.0)
    with pytest.raises(InputError, match="vertices"):
        RigidBody([(0, 0), (1, 0)], rho=1.0)
    with pytest.raises(InputError, match="zero area"):
        RigidBody([(0, 0), (1, 0), (2, 0)], rho=1.0)
    with pytest.raises(InputError, match="dof 'z'"):
        RigidBody(SQUARE, rho=1.0, forces={"z": 1.0})
    with pytest.raises(InputError, match="driven"):
        RigidBody(SQUARE, rho=1.0, drivers={"x": Driver("velocity", 0.0)}, forces={"x": 1.0})
    with pytest.raises(InputError, match="kind"):
        Driver("jerk", 1.0)
    with pytest.raises(InputError, match="strictly increasing"):
        History([0.0, 0.0], [1.0, 2.0])
