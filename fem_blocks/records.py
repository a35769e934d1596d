"""Acceleration records (docs/case-files.md "Ground acceleration"): the exact integral of a piecewise-linear record
(the velocity a driver of kind "acceleration" imposes) and the linear baseline correction. Plain numpy, used by the
case reader (the correction is applied when the file is read) and by bodies.Driver."""
from __future__ import annotations

import numpy as np


def record_velocity_knots(times: np.ndarray, values: np.ndarray) -> np.ndarray:
    """V_k = ∫_{t_0}^{t_k} a dt of the piecewise-linear record (a_k at t_k): the trapezoid rule, exact for it."""
    return np.concatenate([[0.0], np.cumsum(np.diff(times) * 0.5 * (values[:-1] + values[1:]))])


def record_velocity(T: np.ndarray, A: np.ndarray, t: float, knots: np.ndarray | None = None) -> float:
    """V(t) = ∫_{-inf}^t a(s) ds of an acceleration record (docs/case-files.md "Ground acceleration"): a(t) is
    the piecewise-linear interpolation of (t_k, a_k) on [t_0, t_N] and 0 outside it (the ground is at rest before
    the record and keeps its final velocity V(t_N) after it); a single value a (a number) is the constant a from
    t_0 on, V = a (t - t_0). Exact (V is piecewise quadratic); `knots`: V_k (record_velocity_knots) if known."""
    if T.size == 1:
        return float(A[0] * max(t - T[0], 0.0))
    if t <= T[0]:
        return 0.0
    V = record_velocity_knots(T, A) if knots is None else knots
    if t >= T[-1]:
        return float(V[-1])
    k = int(np.searchsorted(T, t, side="right")) - 1
    s, dt = t - T[k], T[k + 1] - T[k]
    return float(V[k] + s * A[k] + 0.5 * s * s * (A[k + 1] - A[k]) / dt)


def baseline_linear(times, values) -> tuple[np.ndarray, float, float]:
    """Linear baseline correction of an acceleration record (docs/case-files.md "Ground acceleration"):
    a_c(t) = a(t) - (c0 + c1 s), s = t - t_0, with (c0, c1) the solution of the 2x2 system that makes the final
    velocity v_N and the final displacement d_N of a_c zero, both integrated over the record's own samples with the
    scheme's rule for θ = 1/2 (v_{k+1} = v_k + Δt (a_k + a_{k+1})/2, d_{k+1} = d_k + Δt (v_k + v_{k+1})/2):

        [v_N(1)  v_N(s)] [c0]   [v_N(a)]          uniform Δt, T = t_N - t_0:   v_N(1) = T,      v_N(s) = T²/2,
        [d_N(1)  d_N(s)] [c1] = [d_N(a)],                                      d_N(1) = T²/2,   d_N(s) = T³/6 + Δt² T/12.

    Returns (a_c at the samples, c0, c1). The correction is linear, so the corrected record is again piecewise
    linear on the same samples; a run with h = Δt (steps on the samples) and θ = 1/2 ends at rest at zero
    displacement to rounding."""
    T = np.asarray(times, dtype=float)
    A = np.asarray(values, dtype=float)
    s = T - T[0]

    def vd(a):
        v = record_velocity_knots(T, a)
        return v[-1], float(np.sum(np.diff(T) * 0.5 * (v[:-1] + v[1:])))

    (v1, d1), (vs, ds), (va, da) = vd(np.ones_like(T)), vd(s), vd(A)
    c0, c1 = np.linalg.solve(np.array([[v1, vs], [d1, ds]]), np.array([va, da]))
    return A - (c0 + c1 * s), float(c0), float(c1)
