"""summary.json: run summary with versions and a UTC timestamp, written atomically."""
from __future__ import annotations

import datetime
import json
import math
import platform
import sys

import numpy as np

from .atomic import atomic_write_text


def _clean(v):
    if isinstance(v, dict):
        return {str(k): _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    if isinstance(v, np.ndarray):
        return _clean(v.tolist())
    if isinstance(v, (np.bool_, bool)):
        return bool(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        f = float(v)
        return f if math.isfinite(f) else None
    return v


def versions() -> dict:
    out = {"python": platform.python_version()}
    from .. import __version__
    out["fem_blocks"] = __version__
    for mod in ("numpy", "scipy", "numba", "petsc4py", "gmsh", "meshio", "dolfinx"):
        m = sys.modules.get(mod)
        if m is None:
            continue  # report only what this run imported (importing dolfinx here would cost seconds)
        out[mod] = getattr(m, "__version__", None) or getattr(m, "GMSH_API_VERSION", None)
    return out


def write_summary(path: str, data: dict) -> dict:
    d = dict(data)
    d.setdefault("versions", versions())
    d.setdefault("written_at", datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"))
    d = _clean(d)
    atomic_write_text(path, json.dumps(d, indent=2, sort_keys=False, allow_nan=False) + "\n")
    return d
