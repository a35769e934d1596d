"""Options of the contact solver: one dataclass, each field's default, meaning and valid range written once.

`SolverOptions` is what `solver.solve(problem, options)` reads (solver/driver.py); `contact.step.ContactOptions`
extends it with the time stepper's own fields. The range, choices and meaning of each field live in its
`metadata` (keys: "doc", "choices", or "lo"/"hi"/"lo_open"/"hi_open" and "expected"); `__post_init__` checks
every field from it (one generic rule), then the combinations (fallback and coarse need the NLGS residual path).
Error messages name the key as `<section>.<field>` (section "contact", the case-file table of these keys).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import ClassVar

from ..errors import InputError, check_range


def option(default, doc: str, *, choices=None, note: str = "", lo=None, hi=None, lo_open=False, hi_open=False,
           expected=None):
    """A dataclass field whose metadata holds its meaning and valid values (read by `check_fields`); `note` ends
    the message of a value outside `choices`."""
    md = {"doc": doc}
    if choices is not None:
        md.update(choices=tuple(choices), note=note)
    if lo is not None or hi is not None:
        md.update(lo=lo, hi=hi, lo_open=lo_open, hi_open=hi_open, expected=expected)
    return field(default=default, metadata=md)


def _quoted_list(choices) -> str:
    q = [repr(c) for c in choices]
    return q[0] if len(q) == 1 else f"{', '.join(q[:-1])} or {q[-1]}"


def check_fields(obj, section: str):
    """InputError for the first field of dataclass `obj` outside the choices or range of its metadata:
    "<section>.<name> = <value>: expected ..."."""
    for f in dataclasses.fields(obj):
        md = f.metadata
        v = getattr(obj, f.name)
        key = f"{section}.{f.name}"
        if "choices" in md and v not in md["choices"]:
            raise InputError(f"{key} = {v!r}: expected {_quoted_list(md['choices'])}{md.get('note', '')}")
        if "lo" in md:
            check_range(key, v, md["lo"], md["hi"], lo_open=md["lo_open"], hi_open=md["hi_open"],
                        expected=md["expected"])


@dataclass
class SolverOptions:
    """How the contact problem u = W r + q (Signorini–Coulomb or interface laws per contact) is solved."""

    section: ClassVar[str] = "contact"

    solver: str = option("nlgs", "nonlinear Gauss-Seidel, or the global semismooth Newton (NLGS start and "
                         "fallback)", choices=("nlgs", "newton"))
    tol: float = option(1e-6, "tolerance of the stopping criterion (relative, dimensionless)",
                        lo=0.0, lo_open=True, expected="tol > 0")
    max_sweeps: int = option(2000, "NLGS: most Gauss-Seidel sweeps; Newton: most fallback sweeps in a step",
                             lo=1, expected="max_sweeps >= 1")
    omega: float = option(1.0, "NLGS relaxation r <- omega r_local + (1 - omega) r",
                          lo=0.0, hi=2.0, lo_open=True, hi_open=True, expected="0 < omega < 2")
    order: str = option("given", "NLGS order of the contacts in a sweep (shuffled: seeded by `seed`)",
                        choices=("given", "reversed", "shuffled"))
    seed: int = option(0, "seed of the shuffled order (the contact step adds its step count)")
    criterion: str = option("change", "NLGS stop: relative change ‖Δr‖/‖r‖ between sweeps, or the FCLIB "
                            "natural-map residual ‖F‖/‖q‖", choices=("change", "residual"))
    check_every: int = option(10, "sweeps between two residual evaluations (criterion = 'residual')",
                              lo=1, expected="check_every >= 1")
    fallback: str = option("none", "'newton': NLGS hands over to the global Newton when a window of 200 sweeps "
                           "does not halve the residual (Coulomb contacts; interface laws: not used)",
                           choices=("none", "newton"))
    coarse: str = option("none", "'interfaces': two-level NLGS, a coarse correction per interface "
                         "(solver/coarse.py; 2D Coulomb)", choices=("none", "interfaces"))
    coarse_every: int = option(10, "sweeps between two coarse corrections", lo=1, expected="coarse_every >= 1")

    def __post_init__(self):
        s = self.section
        check_fields(self, s)
        if self.fallback == "newton" and (self.solver != "nlgs" or self.criterion != "residual"):
            raise InputError(f"{s}.fallback = 'newton': expected solver = 'nlgs' and criterion = 'residual' "
                             "(stagnation is measured on the residual)")
        if self.coarse != "none" and (self.solver != "nlgs" or self.fallback != "none"):
            raise InputError(f"{s}.coarse = {self.coarse!r}: expected solver = 'nlgs' and fallback = 'none' (the "
                             "coarse correction is a step of the Gauss-Seidel solver)")
