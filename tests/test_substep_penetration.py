"""A sub-step clears an existing penetration at the nominal step's rate (contact/step.py, `gs`).

Closed form: a free rigid block of mass m penetrating a fixed base by p, no gravity, θ: the shifted Signorini
condition v_N + gs / (h θ) >= 0 with the contact active gives the block's upward velocity after one step
v = -gs / (h θ): with gs = gbar = -p for a nominal step (v = p / (h θ)) and gs = (h / hn) gbar for a sub-step of a
nominal step hn (v = p / (hn θ), whatever h). Before the fix a sub-step h = hn / 16 threw the block out at 16 times
that speed (256 times the kinetic energy): the energy the runner's "refine" policy created in a collapsing arch.
"""
import numpy as np
import pytest

from fem_blocks.bodies import Driver, RigidBody
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation

P, H, THETA = 1.0e-4, 1.0e-3, 0.5


def _penetrated(h, nominal=None):
    hold = {k: Driver("velocity", 0.0) for k in ("x", "y", "rz")}
    base = RigidBody([(-0.2, -0.1), (0.4, -0.1), (0.4, 0.0), (-0.2, 0.0)], thickness=0.1, drivers=hold)
    block = RigidBody([(0.0, 0.0), (0.2, 0.0), (0.2, 0.1), (0.0, 0.1)], rho=2000.0, thickness=0.1)
    cs = ContactStep([InterfaceSpec("bed", ("b", "r"), mu=0.5)], ["b", "r"], ContactOptions(tol=1e-13, max_sweeps=200))
    sim = Simulation([block, base], h=H, theta=THETA, contact=cs, gravity=(0.0, 0.0))
    if nominal is not None or h != H:
        sim.set_step(h, THETA, nominal=nominal)
    block.q[1] = -P   # a penetration left by an earlier step
    sim.step()
    return block


@pytest.mark.parametrize("k", [1, 4, 16])
def test_substep_pushes_out_at_the_nominal_rate(k):
    """h = H / k as a sub-step of H: the block leaves at p / (H θ) (1e-9), for every k. Bug caught: the sub-step's
    own rate p / (h θ) (k times faster), or a penetration left in place (v = 0)."""
    b = _penetrated(H / k, nominal=H)
    assert b.u[1] == pytest.approx(P / (H * THETA), rel=1e-9)
    assert abs(b.u[0]) < 1e-12 and abs(b.u[2]) < 1e-9


def test_nominal_step_is_the_shifted_signorini_of_its_own_step():
    """Without sub-stepping (nominal = h) a step of h = H / 16 clears the penetration at p / (h θ), as before."""
    b = _penetrated(H / 16)
    assert b.u[1] == pytest.approx(16 * P / (H * THETA), rel=1e-9)
