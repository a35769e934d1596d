"""The Moreau–Jean θ-method away from θ = ½ and 1, where every term of the free velocity counts.

Expectations are closed forms derived here (docstrings), never values produced by fem_blocks:
* a deformable block released from one eigenmode φ of (K, M) (scipy.linalg.eigh, independent of the stepper)
  stays in that mode; its modal coordinates follow the N-th power of the θ-scheme's 2×2 amplification matrix,
  undamped and with Rayleigh damping C = αM + βK (modal damping c = α + βω²);
* a free rigid body under force and moment histories linear in time follows the hand-summed recurrence.
"""
import numpy as np
import pytest
import scipy.linalg

from fem_blocks.bodies import BlockType, DeformableBody, History, Material, RigidBody
from fem_blocks.dynamics import Simulation
from fem_blocks.meshing import mesh_rectangle

STONE = dict(E=5e9, nu=0.2, rho=1800.0, thickness=0.1, plane="stress")


def amplification(h, theta, omega2, c):
    """Amplification matrix A of the θ-scheme on one mode: (a, b)_{n+1} = A (a, b)_n.

    With φ M-normalised (φᵀMφ = 1, Kφ = ω²Mφ, Cφ = cMφ, c = α + βω² for C = αM + βK), q = a φ, u = b φ, the
    free velocity (no contact, no load)

        (M + hθC + h²θ²K) u1 = M u0 − h(1−θ)C u0 − hK q0 − h²θ(1−θ)K u0,   q1 = q0 + h((1−θ)u0 + θu1)

    projected on φ (multiply by φᵀ) gives, with d = 1 + hθc + h²θ²ω²,

        b1 = (−hω² a0 + (1 − h(1−θ)c − h²θ(1−θ)ω²) b0) / d
        a1 = a0 + h(1−θ) b0 + hθ b1

    so A = [[1 − h²θω²/d, h(1−θ) + hθ e/d], [−hω²/d, e/d]] with e = 1 − h(1−θ)c − h²θ(1−θ)ω².
    The subspace span(φ) is invariant (φ is an eigenvector of every matrix above), so q_n = a_n φ exactly.
    """
    d = 1.0 + h * theta * c + (h * theta) ** 2 * omega2
    e = 1.0 - h * (1 - theta) * c - h * h * theta * (1 - theta) * omega2
    return np.array([[1.0 - h * h * theta * omega2 / d, h * (1 - theta) + h * theta * e / d],
                     [-h * omega2 / d, e / d]])


@pytest.fixture(scope="module")
def block_modes():
    """A free 0.2 m x 0.1 m stone block (4 x 2 Q1 cells, lumped mass): its first elastic mode by dense eigh."""
    mesh = mesh_rectangle(0.2, 0.1, 0.05, cell="quad")
    bt = BlockType(mesh, Material(**STONE), mass="lumped", name="free")
    w2, V = scipy.linalg.eigh(bt.K.toarray(), bt.M.toarray())
    assert w2[2] < 1e-6 * w2[3]  # three rigid modes (ω² ~ 0), then the elastic ones
    return mesh, w2[3], V[:, 3]  # eigh normalises V to Vᵀ M V = I


def run_mode(bt, phi, h, theta, n):
    body = DeformableBody(bt)
    sim = Simulation([body], h=h, theta=theta, gravity=(0.0, 0.0))
    body.q[:] = phi
    Mphi = bt.M @ phi
    ab = [(float(Mphi @ body.q), float(Mphi @ body.u))]
    for _ in range(n):
        sim.step()
        ab.append((float(Mphi @ body.q), float(Mphi @ body.u)))
        # the motion stays in the mode: q = a φ (the rest is round-off)
        assert np.abs(body.q - ab[-1][0] * phi).max() <= 1e-9 * np.abs(phi).max()
    return np.array(ab)


@pytest.mark.parametrize("theta", [0.6, 0.7, 0.85])
def test_undamped_mode_follows_theta_amplification(block_modes, theta):
    """θ ∈ (½, 1): the h²θ(1−θ)K u term matters (at θ = ½ it equals h²θ²K u, at θ = 1 it vanishes).
    30 steps of h = 0.8/ω from (a, b) = (1, 0): a_n, b_n equal A^n (1, 0) to 1e-9 of the amplitude."""
    mesh, w2, phi = block_modes
    bt = BlockType(mesh, Material(**STONE), mass="lumped")
    omega = np.sqrt(w2)
    h, n = 0.8 / omega, 30
    ab = run_mode(bt, phi, h, theta, n)
    A = amplification(h, theta, w2, 0.0)
    ref = np.array([np.linalg.matrix_power(A, k) @ [1.0, 0.0] for k in range(n + 1)])
    assert np.abs(ab[:, 0] - ref[:, 0]).max() <= 1e-9
    assert np.abs(ab[:, 1] - ref[:, 1]).max() <= 1e-9 * omega
    assert np.abs(ref[:, 0]).min() < 0.5  # it does oscillate (amplitude decays by numerical damping for θ > ½)


@pytest.mark.parametrize("theta", [0.5, 0.7, 1.0])
def test_rayleigh_damped_mode_decays_as_theta_amplification(block_modes, theta):
    """C = αM + βK with α = 0.2ω [1/s], β = 0.1/ω [s]: modal damping c = α + βω² = 0.3ω (swapping α and β gives
    c = 0.1/ω + 0.2ω³, a different decay by orders of magnitude). The modal coordinates follow A(c)^n."""
    mesh, w2, phi = block_modes
    omega = np.sqrt(w2)
    alpha, beta = 0.2 * omega, 0.1 / omega
    bt = BlockType(mesh, Material(**STONE, alpha=alpha, beta=beta), mass="lumped")
    h, n = 0.8 / omega, 30
    ab = run_mode(bt, phi, h, theta, n)
    A = amplification(h, theta, w2, alpha + beta * w2)
    ref = np.array([np.linalg.matrix_power(A, k) @ [1.0, 0.0] for k in range(n + 1)])
    assert np.abs(ab[:, 0] - ref[:, 0]).max() <= 1e-9
    assert np.abs(ab[:, 1] - ref[:, 1]).max() <= 1e-9 * omega
    undamped = np.array([np.linalg.matrix_power(amplification(h, theta, w2, 0.0), k) @ [1.0, 0.0]
                         for k in range(n + 1)])
    assert np.abs(ref[-1]).max() < 0.5 * np.abs(undamped[-1]).max()  # damping is visible in the reference


def test_rigid_force_and_moment_linear_in_time_theta_weights():
    """Free rigid body (m = 3 kg, I = 0.4 kg m², no gravity), forces F_x(t) = 2 + 50 t [N], F_y = 0, moment
    M(t) = 1 − 30 t [N m], θ = 0.75, h = 0.01 s. F_θ = (1−θ)F(t_k) + θF(t_{k+1}) = F(t_k + θh) for a linear F, so

        u_n = u_0 + (h/m) Σ_{k<n} F(t_k + θh) = u_0 + (h/m) [n F(0) + F' h (n(n−1)/2 + nθ)],
        q_n = Σ_{k<n} h ((1−θ) u_k + θ u_{k+1}),

    every step compared to 1e-12 relative."""
    m, inertia, h, theta, n = 3.0, 0.4, 0.01, 0.75, 50
    fx0, fx1, mz0, mz1 = 2.0, 50.0, 1.0, -30.0
    T = 2 * n * h
    b = RigidBody([(0, 0), (0.4, 0), (0.4, 0.2), (0, 0.2)], mass=m, inertia=inertia,
                  forces={"x": History([0, T], [fx0, fx0 + fx1 * T]), "rz": History([0, T], [mz0, mz0 + mz1 * T])})
    u0 = np.array([0.3, -0.2, 0.5])
    b.u[:] = u0
    sim = Simulation([b], h=h, theta=theta, gravity=(0.0, 0.0))
    k = np.arange(n + 1)
    s = k * (k - 1) / 2 + k * theta
    u_ref = np.column_stack([u0[0] + h / m * (k * fx0 + fx1 * h * s), np.full(n + 1, u0[1]),
                             u0[2] + h / inertia * (k * mz0 + mz1 * h * s)])
    q_ref = np.vstack([np.zeros(3), np.cumsum(h * ((1 - theta) * u_ref[:-1] + theta * u_ref[1:]), axis=0)])
    for i in range(1, n + 1):
        sim.step()
        np.testing.assert_allclose(b.u, u_ref[i], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(b.q, q_ref[i], rtol=1e-12, atol=1e-14)
