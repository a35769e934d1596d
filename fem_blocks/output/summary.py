"""summary.json: run summary plus `versions` of the software stack and a UTC ISO `timestamp`, written atomically.

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
