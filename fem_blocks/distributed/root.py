"""Rank 0 does it, every rank gets its value or its exception: `on_root`. What the ranks found, agreed: `least_found`.

On N > 1 ranks every rank builds the whole model but rank 0 alone touches the output directory (opens the
history, the ParaView series, the checkpoint; writes the summary). A failure there must stop every rank the same
way (no rank left waiting in the next collective call), and a value rank 0 found there (the checkpoint to resume,
the number of frames already written, the summary) must reach the others.

A check made by each rank on its own contacts (a NaN impulse, a penetration, a missed contact) must name what one
process would name over the whole set: every rank's finding (key, contact, payload) or None, the one with the
smallest (key, contact) (`least_found`: one all-gather; the contact a number or id in the whole set's order).

No import of the rest of fem_blocks here: runner.py, output/ and contact/step.py import this module.
"""
from __future__ import annotations

import pickle


def least_found(comm, found):
    """Of every rank's finding `found` — (key, contact, payload) or None — the one with the smallest (key, contact),
    or None if no rank found one; COLLECTIVE (one all-gather) when comm is given, else `found` itself."""
    every = [found] if comm is None else comm.allgather(found)
    found = [x for x in every if x is not None]
    return min(found, key=lambda x: (x[0], x[1])) if found else None


def _round_trip(obj):
    """(pickled bytes, the object loaded back from them, None) when `obj` pickles and loads back; (None, None,
    the exception raised) otherwise."""
    try:
        data = pickle.dumps(obj, pickle.HIGHEST_PROTOCOL)
        return data, pickle.loads(data), None
    except Exception as e:  # noqa: BLE001 - any failure to send: the caller sends a RuntimeError instead
        return None, None, e


def _as_runtime_error(exc: BaseException) -> RuntimeError:
    return RuntimeError(f"{type(exc).__name__}: {exc}")


def on_root(comm, fn, *args, share: bool = True, **kw):
    """fn(*args, **kw) called on rank 0 of `comm` alone; its value returned, or its exception raised, on every rank.

    comm None or of size 1: returns fn(*args, **kw); an exception propagates unchanged (the serial run).

    comm of N > 1 ranks: COLLECTIVE, every rank of comm must call on_root at the same point (the others do not
    call fn; they wait in one broadcast from rank 0). Rank 0 calls fn, then broadcasts (pickled) either its value
    or the exception it raised (any BaseException, KeyboardInterrupt included), so no rank is left waiting:
    - fn returned: rank 0 returns fn's own object; the other ranks return an unpickled copy of it, or None when
      share=False (then the value is not sent at all: for a value only rank 0 uses);
    - fn raised: rank 0 re-raises its own exception (its traceback kept) and every other rank raises an unpickled
      copy: the same type and message (str), and the same instance attributes (e.g. RunStopped.code), whatever
      `share` is;
    - an exception that does not survive the pickle round trip, tried on rank 0 before sending (pickling fails,
      its class cannot be rebuilt from the pickle, e.g. an __init__ with other arguments than its args, or the
      copy differs in type or str), is replaced on EVERY rank, rank 0 included, by
      RuntimeError("<type name>: <message>") (on rank 0 raised from the original); likewise a value (share=True)
      that does not survive it: RuntimeError("on_root: the value of <fn> cannot be sent to the other ranks
      (<type name>: <message>)") on every rank.
    `share` is on_root's own keyword: fn cannot receive a keyword argument named `share` through it."""
    if comm is None or comm.Get_size() == 1:
        return fn(*args, **kw)
    if comm.Get_rank() != 0:
        ok, obj = pickle.loads(comm.bcast(None, root=0))
        if ok:
            return obj
        raise obj
    try:
        value = fn(*args, **kw)
    except BaseException as e:
        data, back, bad = _round_trip((False, e))
        if bad is None and type(back[1]) is type(e) and str(back[1]) == str(e):
            comm.bcast(data, root=0)
            raise
        err = _as_runtime_error(e)
        comm.bcast(pickle.dumps((False, err), pickle.HIGHEST_PROTOCOL), root=0)
        raise err from e
    data, _, bad = _round_trip((True, value if share else None))
    if bad is not None:
        name = getattr(fn, "__qualname__", None) or repr(fn)
        err = RuntimeError(f"on_root: the value of {name} cannot be sent to the other ranks "
                           f"({type(bad).__name__}: {bad})")
        comm.bcast(pickle.dumps((False, err), pickle.HIGHEST_PROTOCOL), root=0)
        raise err from bad
    comm.bcast(data, root=0)
    return value
