"""Read-outs of the standard tests: pure functions on arrays (no I/O), each with the formula it implements.

* `check_levels`: a list of at least n numbers >= 0, strictly increasing (pre-compression levels);
* `peak_and_residual`: the peak of a curve and its residual (mean over the last `tail` fraction, an assumed
  definition: the standards record the peak only);
* `fit_line`: the least-squares line through n points, tau = intercept + slope sigma:
  slope = sum (s - s_mean)(t - t_mean) / sum (s - s_mean)^2, intercept = t_mean - slope s_mean,
  R^2 = 1 - sum (t - intercept - slope s)^2 / sum (t - t_mean)^2;
* `triplet_readout`: EN 1052-3's peak and residual lines (docs/lab-tests.md).
"""
from __future__ import annotations

import numpy as np

from ..errors import InputError

MIN_LEVELS = 3   # EN 1052-3 (and issue #23): at least three pre-compression levels


def check_levels(levels, where: str = "lab.precompressions", min_levels: int = MIN_LEVELS) -> np.ndarray:
    """The pre-compression levels [Pa]: a list of at least min_levels numbers >= 0, strictly increasing;
    InputError ``WHERE = VALUE: expected ...`` otherwise."""
    text = f"a list of at least {min_levels} pre-compressions >= 0, strictly increasing, e.g. [0.2, 0.6, 1.0] MPa"
    if not isinstance(levels, (list, tuple)) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                         for v in levels):
        raise InputError(f"{where} = {levels!r}: expected {text}")
    v = np.asarray(levels, dtype=float)
    if len(v) < min_levels:
        raise InputError(f"{where} = {levels!r}: {len(v)} level(s); expected {text}")
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise InputError(f"{where} = {levels!r}: a negative or non-finite level; expected {text}")
    if np.any(np.diff(v) <= 0):
        raise InputError(f"{where} = {levels!r}: not strictly increasing; expected {text}")
    return v


def peak_and_residual(tau, tail: float = 0.1) -> tuple:
    """(τ_peak, index of the peak, τ_res): the largest shear stress of a curve and the mean over its last `tail`
    fraction of rows (at least one row). τ_res is NaN when the peak lies inside that tail (no post-peak branch)."""
    t = np.asarray(tau, dtype=float)
    if t.size == 0:
        raise ValueError("peak_and_residual: empty curve")
    k = int(np.argmax(t))
    n = max(1, int(round(tail * t.size)))
    res = float(np.mean(t[-n:])) if k < t.size - n else float("nan")
    return float(t[k]), k, res


def fit_line(sigma, tau) -> dict:
    """Least-squares line τ = intercept + slope σ through n >= 2 points (module docstring) -> dict(intercept,
    slope, r2, n). r2 is 1.0 when the points do not vary."""
    s, t = np.asarray(sigma, dtype=float), np.asarray(tau, dtype=float)
    if s.size < 2 or s.size != t.size:
        raise ValueError(f"fit_line: expected two equal-length arrays of >= 2 points, got {s.size} and {t.size}")
    ds, dt = s - s.mean(), t - t.mean()
    slope = float(np.dot(ds, dt) / np.dot(ds, ds))
    icpt = float(t.mean() - slope * s.mean())
    ss_tot = float(np.dot(dt, dt))
    ss_res = float(np.sum((t - icpt - slope * s) ** 2))
    return dict(intercept=icpt, slope=slope, r2=1.0 if ss_tot == 0 else 1.0 - ss_res / ss_tot, n=int(s.size))


def triplet_readout(sigma_p, curves: list, tail: float = 0.1) -> dict:
    """The triplet report from the curves of one specimen per level: `sigma_p[i]` the pre-compression [Pa],
    `curves[i]` a dict of per-step arrays "upper" and "lower" (shear stress of each joint [Pa]) and "total"
    (F / 2A of the middle brick [Pa]). Returns per-level peaks and residuals per joint, and the peak and residual
    lines fitted on the points of both joints (2 per level)."""
    levels, sp, tp, sr, tr = [], [], [], [], []
    for s, c in zip(sigma_p, curves):
        row = dict(precompression_Pa=float(s))
        for j in ("upper", "lower", "total"):
            pk, k, res = peak_and_residual(c[j], tail)
            row[f"peak_{j}_Pa"] = pk
            row[f"residual_{j}_Pa"] = res
            if j != "total":
                sp.append(s)
                tp.append(pk)
                if np.isfinite(res):
                    sr.append(s)
                    tr.append(res)
        levels.append(row)
    peak = fit_line(sp, tp)
    resid = fit_line(sr, tr) if len(set(sr)) >= 2 else None
    return dict(levels=levels, peak_line=peak, residual_line=resid)


def diagonal_curves(R, e_v, u_v1, u_v2, u_h1, u_h2, e_h, g: float, A_n: float) -> dict:
    """ASTM E519 diagonal compression from per-row arrays: R (n, 2) the loading shoe's reaction (driver reactions
    less inertia, summed over its plates) [N], e_v the unit vector of the loaded diagonal (the shoe moves along
    -e_v), u_* (n, 2) the displacements of the gauge points V1, V2 (on the loaded diagonal, V2 - V1 along e_v) and
    H1, H2 (on the other, H2 - H1 along e_h) [m], g the gauge length [m], A_n the net area [m²]:

        P = -R · e_v,   S_s = 0.707 P / A_n,
        ΔV = -(u_V2 - u_V1) · e_v  (shortening),   ΔH = (u_H2 - u_H1) · e_h  (lengthening),   γ = (ΔV + ΔH) / g.
    """
    R = np.asarray(R, dtype=float)
    ev, eh = np.asarray(e_v, dtype=float), np.asarray(e_h, dtype=float)
    P = -R @ ev
    dV = -(np.asarray(u_v2, dtype=float) - np.asarray(u_v1, dtype=float)) @ ev
    dH = (np.asarray(u_h2, dtype=float) - np.asarray(u_h1, dtype=float)) @ eh
    return dict(P=P, S_s=0.707 * P / A_n, dV=dV, dH=dH, gamma=(dV + dH) / g)


# ----------------------------------------------------------------------------- secant modulus (compression.py, diagonal.py), peak
def secant_at_fraction(stress, strain, fraction: float = 1.0 / 3.0) -> dict:
    """The secant modulus at `fraction` of the peak of a stress-strain curve (EN 1052-1: E = F_max / (3 A ε_1/3)):
    σ_max = max σ (row k), σ* = fraction σ_max, ε* the strain where the curve first reaches σ* (linear between the
    two rows around the crossing, rows 0..k), E = σ* / ε*. -> dict(peak, peak_index, stress (σ*), strain (ε*),
    modulus). ValueError for a curve that starts at or above σ* or does not rise (σ_max <= 0)."""
    s, e = np.asarray(stress, dtype=float), np.asarray(strain, dtype=float)
    if s.size < 2 or s.size != e.size:
        raise ValueError(f"secant_at_fraction: expected two equal-length arrays of >= 2 rows, got {s.size}, {e.size}")
    k = int(np.nanargmax(s))
    peak = float(s[k])
    if not peak > 0:
        raise ValueError(f"secant_at_fraction: the stress never rises above 0 (max {peak!r})")
    target = fraction * peak
    j = int(np.argmax(s[:k + 1] >= target))
    if j == 0:
        raise ValueError(f"secant_at_fraction: the curve starts at or above {fraction:g} of its peak")
    w = (target - s[j - 1]) / (s[j] - s[j - 1])
    eps = float(e[j - 1] + w * (e[j] - e[j - 1]))
    return dict(peak=peak, peak_index=k, stress=float(target), strain=eps,
                modulus=float(target / eps) if eps != 0 else float("nan"))


def peak_confirmed(force, displacement, drop: float = 0.01, tail: float = 0.1, flat: float = 0.01) -> bool:
    """Whether a monotone loading passed its peak: after the largest force F_max the force fell below
    (1 - drop) F_max, or it ends on a plateau (the slope dF/dd of the last `tail` fraction of rows, least squares,
    below `flat` times the secant F_max / d at the peak). The thresholds are assumed (a plateau of a perfectly
    plastic cap counts as a peak, a force still rising at the end does not)."""
    F, d = np.asarray(force, dtype=float), np.asarray(displacement, dtype=float)
    k = int(np.nanargmax(F))
    if np.nanmin(F[k:]) < (1.0 - drop) * F[k]:
        return True
    n = max(3, int(round(tail * F.size)))
    if F.size < n or d[k] == 0 or np.ptp(d[-n:]) == 0:
        return False
    slope = np.polyfit(d[-n:], F[-n:], 1)[0]
    return bool(abs(slope) < flat * abs(F[k] / d[k]))


def peak_problems(force, no_load: str, still_rising: str) -> list:
    """Why the largest force of a monotone loading is not its peak (failure) load, as messages: `no_load` when it is
    not > 0 (the specimen never carried the load), `still_rising` when it is at the last row (the loading ended
    before the peak); [] when it is a peak."""
    F = np.asarray(force, dtype=float)
    k = int(np.nanargmax(F))
    if not F[k] > 0:
        return [no_load]
    if k == F.size - 1:
        return [still_rising]
    return []
