"""summary.json: run summary plus `versions` of the software stack and a UTC ISO `timestamp`, written atomically;
`cycles_block`, the `cycles` entry of a cyclic test (per cycle ∮ F du = Σ F_{k+1} Δu_k and the extremes).

numpy scalars and arrays become JSON numbers and lists, non-finite floats (NaN, ±inf) become null, paths
become strings; any other non-JSON object raises InputError naming its key."""
from __future__ import annotations

import datetime
import importlib.metadata
import importlib.util
import json
import math
import os
import platform
import sys

import numpy as np

from ..errors import InputError
from .atomic import atomic_write_text

# module name -> distribution name (for the version without importing the module)
_STACK = {"numpy": "numpy", "scipy": "scipy", "numba": "numba", "dolfinx": "fenics-dolfinx",
          "petsc4py": "petsc4py", "gmsh": "gmsh", "meshio": "meshio"}


def _clean(v, where: str):
    if isinstance(v, dict):
        return {str(k): _clean(x, f"{where}.{k}" if where else str(k)) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x, f"{where}[{i}]") for i, x in enumerate(v)]
    if isinstance(v, np.ndarray):
        return _clean(v.tolist(), where)
    if v is None or isinstance(v, (str, np.str_)):
        return None if v is None else str(v)
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        f = float(v)
        return f if math.isfinite(f) else None
    if isinstance(v, np.generic):  # e.g. complex: not JSON
        raise InputError(f"summary[{where}]: cannot write a {type(v).__name__} to JSON")
    if isinstance(v, os.PathLike):
        return os.fspath(v)
    raise InputError(f"summary[{where}]: cannot write a {type(v).__name__} to JSON; expected a number, string, "
                     "bool, None, list, dict or numpy array")


def _version(mod: str):
    m = sys.modules.get(mod)
    if m is not None:
        v = getattr(m, "__version__", None) or getattr(m, "GMSH_API_VERSION", None)
        if v:
            return str(v)
    try:
        return importlib.metadata.version(_STACK[mod])
    except importlib.metadata.PackageNotFoundError:
        pass
    try:
        if importlib.util.find_spec(mod) is None:
            return None  # not importable
    except (ImportError, ValueError):
        return None
    if mod == "gmsh":  # gmsh imports quickly (no MPI/JIT): ask it
        try:
            import gmsh
            return str(getattr(gmsh, "__version__", None) or gmsh.GMSH_API_VERSION)
        except Exception:
            return None
    return "unknown"  # importable, version not found without importing it (importing dolfinx costs seconds)


def versions() -> dict:
    """Versions of python, fem_blocks and the stack; a module that is not importable maps to None.

    Read from the imported module when the run imported it, else from the package metadata, so this never
    imports dolfinx/petsc4py (seconds of MPI start-up) and never fails."""
    from .. import __version__
    out = {"fem_blocks": __version__, "python": platform.python_version()}
    for mod in _STACK:
        try:
            out[mod] = _version(mod)
        except Exception:  # a broken installation must not stop the summary
            out[mod] = None
    return out


def write_summary(path, data: dict) -> dict:
    """Write `data` + {"versions": versions(), "timestamp": UTC ISO 8601} to `path` as JSON, atomically;
    returns the dict written (keys given in `data` win)."""
    if not isinstance(data, dict):
        raise InputError(f"summary data: expected a dict, got {type(data).__name__}")
    d = dict(data)
    d.setdefault("versions", versions())
    d.setdefault("timestamp", datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"))
    d = _clean(d, "")
    atomic_write_text(path, json.dumps(d, indent=2, allow_nan=False) + "\n")
    return d


def reference_comparison(x, y, ref: dict, force_unit: str = "kN", disp_unit: str = "mm",
                         disp_name: str = "displacement") -> dict:
    """summary.json "reference" entry: the model's peak against one reference (a dict of figures.reference_data),
    both in the figure's units. Peaks are magnitudes: model peak F_m = max |y| at d_m = |x| there (finite points);
    reference peak F_r = max |F| of its curve (d_r = |d| there) or its `peak`. Band [F_lo, F_hi]: `peak_band`,
    F_r (1 ± band), or (max |lower|, max |upper|). ratio = F_m / F_r, or F_m / ((F_lo + F_hi) / 2) when the
    reference has a band and no peak (`ratio_to` says which); `inside_band`: F_lo <= F_m <= F_hi (None without a
    band). Keys carry the units, e.g. `model_peak_kN`, `reference_displacement_at_peak_mm`."""
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    ok = np.isfinite(x) & np.isfinite(y)
    Fm = dm = None
    if ok.any():
        k = int(np.flatnonzero(ok)[np.argmax(np.abs(y[ok]))])
        Fm, dm = float(abs(y[k])), float(abs(x[k]))
    Fr, dr, band = ref.get("peak"), ref.get("displacement_at_peak"), ref.get("peak_band")
    if ref.get("curve") is not None:
        d, F = (np.asarray(a, dtype=float) for a in ref["curve"])
        j = int(np.argmax(np.abs(F)))
        Fr, dr = float(abs(F[j])), float(abs(d[j]))
        if ref.get("lower") is not None:
            band = tuple(sorted(float(np.max(np.abs(np.asarray(ref[k][1], dtype=float)))) for k in ("lower", "upper")))
    if band is None and Fr is not None and ref.get("band") is not None:
        band = (max(Fr * (1.0 - ref["band"]), 0.0), Fr * (1.0 + ref["band"]))
    if Fr is not None:
        target, to = Fr, "peak"
    else:
        target, to = 0.5 * (band[0] + band[1]), "band middle"
    return {"label": ref["label"], f"reference_peak_{force_unit}": Fr,
            f"reference_band_{force_unit}": None if band is None else [float(band[0]), float(band[1])],
            f"reference_{disp_name}_at_peak_{disp_unit}": dr,
            f"model_peak_{force_unit}": Fm, f"model_{disp_name}_at_peak_{disp_unit}": dm,
            "ratio": None if Fm is None or not target > 0 else Fm / target, "ratio_to": to,
            "inside_band": None if band is None or Fm is None else bool(band[0] <= Fm <= band[1])}


# ----------------------------------------------------------------------------- cyclic tests: the `cycles` block
def _crossings(du: np.ndarray, tol: float) -> list:
    """Cycles of a displacement record du = u - u_ref (rows in time order): [(start, end, complete)], start and
    end as (row k, fraction a) = the point row k + a (row k+1 - row k). A cycle starts where du leaves 0 upwards
    (s_k <= 0 < s_k+1, s = sign(du) with |du| <= tol counted as 0) and ends where it returns to 0 from below
    (s_k < 0 <= s_k+1) after a negative excursion; the next cycle starts there or later."""
    s = np.where(du > tol, 1, np.where(du < -tol, -1, 0))
    n = len(du)
    out, k = [], 0

    def frac(j):  # where du (linear between rows j and j + 1) is 0
        d = du[j + 1] - du[j]
        return 0.0 if d == 0 else min(1.0, max(0.0, -du[j] / d))

    while k < n - 1:
        up = next((j for j in range(k, n - 1) if s[j] <= 0 < s[j + 1]), None)
        if up is None:
            break
        neg = next((j for j in range(up + 1, n) if s[j] < 0), None)
        back = None if neg is None else next((j for j in range(neg, n - 1) if s[j] < 0 <= s[j + 1]), None)
        if back is None:
            out.append(((up, frac(up)), (n - 1, 0.0), False))
            break
        out.append(((up, frac(up)), (back, frac(back)), True))
        k = back
    return out


def _segment(a: np.ndarray, start, end) -> np.ndarray:
    """Column `a` from the point `start` to the point `end` ((row, fraction) as in _crossings), rows between."""
    (k0, a0), (k1, a1) = start, end
    p = lambda k, f: a[k] + f * (a[k + 1] - a[k]) if f > 0 else a[k]  # noqa: E731
    return np.concatenate([[p(k0, a0)], a[k0 + 1:k1 + 1], [p(k1, a1)]])


def _work(u: np.ndarray, F: np.ndarray, start, end) -> float:
    """Σ F_{k+1} Δu_k from the point `start` to the point `end` ((row, fraction)): each step's increment (cut at
    the two points) times the reaction at the end of that step."""
    uu = _segment(u, start, end)
    k0, k1 = start[0], end[0]
    f = F[k0 + 1:min(k1 + 2, len(F))]
    du = np.diff(uu)[:len(f)]
    return float(np.sum(f * du))


def cycles_block(t, u, F, *, u_scale: float = 1e3, u_unit: str = "mm", f_scale: float = 1e-3, f_unit: str = "kN",
                 dissipated=None, stored=None, friction=None) -> dict | None:
    """summary.json `cycles`: the cycles of a force–displacement record (history rows in time order, SI: t [s],
    u the driven displacement [m or rad], F its reaction [N or N m]); None when the displacement never goes
    both ways (a monotone test).

    A cycle runs from an upward zero crossing of u - u_0 (u_0 = the first value) to its return to zero from below
    (crossings interpolated linearly between rows): with a cyclic protocol 0 -> +a -> -a -> +a ..., one cycle per
    (+a, -a) pair; |u - u_0| <= 1e-4 max|u - u_0| counts as zero. Per cycle: its times, the extreme displacements
    and forces of its positive and negative halves (signed, in u_unit/f_unit), and

        energy_J = ∮ F du = Σ F_{k+1} (u_{k+1} - u_k)   over the steps of the cycle (the part of a step on
                             either side of a crossing with its increment cut there): the work the driver does on
                             the model in the cycle, with the step rule of the engine's `driver_work` (the
                             reaction of a step times its increment, exact for the implicit θ = 1 step), = the
                             energy dissipated when the state at the cycle's end is the state at its start

    `dissipated` (per row, cumulative [J], e.g. the contacts' damage and crushing energy) gives dissipated_J, its
    increment in the cycle; `friction` (per row, cumulative [J], the contacts' frictional dissipation) gives
    friction_J; `stored` (per row [J], e.g. elastic + kinetic + gravity energy of the bodies) gives
    stored_change_J. Then energy_J = stored_change_J + the energy the interfaces took (dissipated_J + friction_J +
    the joints' elastic energy change + the step rule's excess) - the work of the other drivers and of the applied
    forces."""
    t, u, F = (np.asarray(x, dtype=float).ravel() for x in (t, u, F))
    ok = np.isfinite(t) & np.isfinite(u) & np.isfinite(F)
    extra = {k: np.asarray(v, dtype=float).ravel()[ok] for k, v in (("dissipated", dissipated), ("stored", stored),
                                                                     ("friction", friction)) if v is not None}
    t, u, F = t[ok], u[ok], F[ok]
    if len(u) < 3:
        return None
    du = u - u[0]
    scale = float(np.abs(du).max())
    tol = 1e-4 * scale  # drift below 1e-4 of the largest excursion (e.g. a free dof before the test) is no cycle
    if scale == 0.0 or du.max() <= tol or du.min() >= -tol:
        return None
    cyc = _crossings(du, tol)
    if not cyc:
        return None
    rows = []
    for i, (a, b, complete) in enumerate(cyc):
        tt, uu, ff = (_segment(x, a, b) for x in (t, u, F))
        pos, neg = uu >= u[0], uu <= u[0]
        r = dict(index=i + 1, complete=complete, t_start=float(tt[0]), t_end=float(tt[-1]),
                 **{f"displacement_pos_{u_unit}": float(uu.max() * u_scale),
                    f"displacement_neg_{u_unit}": float(uu.min() * u_scale),
                    f"peak_force_pos_{f_unit}": float(ff[pos].max() * f_scale),
                    f"peak_force_neg_{f_unit}": float(ff[neg].min() * f_scale)},
                 energy_J=_work(u, F, a, b))
        if "dissipated" in extra:
            d = _segment(extra["dissipated"], a, b)
            r["dissipated_J"] = float(d[-1] - d[0])
        if "friction" in extra:
            f = _segment(extra["friction"], a, b)
            r["friction_J"] = float(f[-1] - f[0])
        if "stored" in extra:
            e = _segment(extra["stored"], a, b)
            r["stored_change_J"] = float(e[-1] - e[0])
        rows.append(r)
    done = [r for r in rows if r["complete"]]
    return dict(count=len(done), energy_total_J=float(sum(r["energy_J"] for r in done)), cycles=rows)
