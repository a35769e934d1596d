"""Frictional dissipation of a contact step (numba, one loop over the contacts; docs/laws.md "Energy convention").

The interface laws are written with the change of variables r̃ = r + r_adh (thesis §6.3.4, laws.py): friction is
Coulomb on the transformed tangential reaction r̃_T with μ r̃_N, the adhesive part r_adh,T = k_T(x) u_T works as a
(damaging) spring, whose energy goes to the joint's elastic energy and to the laws' `dissipated` (decohesion). The
friction's work in the step [t_i, t_{i+1}] is the transformed tangential impulse against the tangential jump
increment the θ-scheme integrates (the one the law state S_UT holds, docs/method.md §4):

    ΔD_f = -r̃_T · Δu_T = -P̃_T · Δu_T / h,    P̃_T = P_T + h A k_T(x) u_T,{i+1},    Δu_T = h [(1 - θ) v_T,i + θ v_T,{i+1}]

with P the step's impulses, A the contact's tributary area, k_T(x) the tangential stiffness of the adhesive part at
the committed internal variable (laws.linear_part: 0 for Coulomb and broken joints, c_T elastic / intact brittle,
β² c_T Frémond–Cangémi, (1 - D) k_s mixed) and u_T,{i+1} the committed jump (3D: the same on both tangents).

Sign: Coulomb on the end-of-step velocity (the implicit step) gives P̃_T · v_T,{i+1} = -μ P̃_N ‖v_T,{i+1}‖ ≤ 0
(stick: v_T = 0; slip: P̃_T = -μ P̃_N v_T/‖v_T‖, P̃_N ≥ 0; at a crushing cap P̃_N is the capped value), so for θ = 1
(every quasi-static stage) ΔD_f = μ P̃_N h ‖v_T,{i+1}‖ ≥ 0 up to the solver's tolerance. For θ < 1 the (1 - θ) part
-h(1 - θ) P̃_T · v_T,i is ≥ 0 too while the slip keeps its direction over the step; only a step in which the slip
reverses can make it negative, by at most h (1 - θ) μ P̃_N ‖v_T,i‖. This is the work that makes the step's energy
balance close with the θ-rule displacement increments (the drivers' work uses the same increments).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..laws import COULOMB, S_BETA, S_US, S_UT, linear_part


@njit(cache=True)
def friction_work(law, par, state, P, v, vi, area, h, theta):
    """Per-contact frictional dissipation of the step [J] (module docstring). law (nc,), par (nc, NPAR), state
    (nc, NSTATE | NSTATE3) committed at the end of the step, P (nc, d) impulses, v (nc, d) end-of-step local velocities
    (the normal one shifted: not used), vi (nc, d) local velocities at the start of the step, area (nc,)."""
    nc, d = P.shape
    out = np.zeros(nc)
    for a in range(nc):
        kT = 0.0
        if law[a] != COULOMB:
            kT = linear_part(law[a], par[a], state[a], state[a, S_BETA], False)[1]
        w = 0.0
        for j in range(1, d):
            ut = state[a, S_UT] if j == 1 else state[a, S_US]
            Pt = P[a, j] + h * area[a] * kT * ut
            w -= Pt * ((1.0 - theta) * vi[a, j] + theta * v[a, j])  # -r̃_T Δu_T = -P̃_T Δu_T / h
        out[a] = w
    return out
