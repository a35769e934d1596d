"""Errors raised on bad user input.

Every message names the field (or file and element) and the expected range, in one line;
the CLI prints it and exits with status 2.
"""


class InputError(ValueError):
    """Invalid user input: a parameter, a case-file key, a mesh or a geometry."""


class ConvergenceError(RuntimeError):
    """A solver did not converge and the run policy says to stop."""


class RankMismatchError(RuntimeError):
    """N MPI ranks that should hold the same model do not (raised on every rank alike; the CLI exits with 1)."""


def check_range(name, value, lo=None, hi=None, lo_open=False, hi_open=False, expected=None):
    """Raise InputError unless lo (<|<=) value (<|<=) hi; returns float(value)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a number, got {value!r}") from None
    ok = v == v  # not NaN
    if lo is not None:
        ok = ok and (v > lo if lo_open else v >= lo)
    if hi is not None:
        ok = ok and (v < hi if hi_open else v <= hi)
    if not ok:
        if expected is None:
            left = "" if lo is None else (f"{lo} <{'' if lo_open else '='} ")
            right = "" if hi is None else (f" <{'' if hi_open else '='} {hi}")
            expected = f"{left}{name.split('.')[-1]}{right}"
        raise InputError(f"{name} = {value!r}: expected {expected}")
    return v
