"""Contact solvers. The face: `solve(ContactProblem(W, q, mu, laws=...), SolverOptions(...), r0)` -> SolverResult
(driver.py: the dispatch table). Kernels: nlgs.py (Gauss–Seidel), newton.py (semismooth Newton), local.py (3D local
solver), coarse.py (two-level NLGS), parallel.py (colour-parallel NLGS); W is a linalg.BlockCSR.

SolverOptions is defined with the other case-file fields in fem_blocks/specs.py (the schema) and re-exported here.
The names load on first use (PEP 562): importing the package does not compile the kernels."""
from __future__ import annotations

import importlib

__all__ = ["ContactProblem", "InterfaceLaws", "SolverOptions", "SolverResult", "solve"]

_HOME = {"ContactProblem": "problem", "InterfaceLaws": "problem", "SolverResult": "problem",
         "solve": "driver"}


def __getattr__(name):
    if name == "SolverOptions":
        from ..specs import SolverOptions
        return SolverOptions
    if name in _HOME:
        return getattr(importlib.import_module(f"{__name__}.{_HOME[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + __all__)
