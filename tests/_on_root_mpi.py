"""Run under mpirun by tests/test_on_root.py: every rank makes the same sequence of on_root calls (CASES) and writes
what it got, case by case, to OUT_DIR/rank<r>.json (its own file: written whatever the other ranks do).

Per case: {"kind": "value", "value" (its repr if not a JSON type), "callable", "same_object": fn's own object
returned?} or {"kind": "raised", "type", "module", "msg", "attrs" (the instance __dict__ and an OSError's errno),
"cause" (type name of __cause__)}, and "calls": how many times this rank called fn.

Usage: mpirun -n 2 python tests/_on_root_mpi.py OUT_DIR
"""
import json
import os
import sys

from mpi4py import MPI

from fem_blocks.distributed.root import on_root
from fem_blocks.errors import InputError


class Stopped(Exception):
    """Like runner.RunStopped: a message and an exit code kept as an attribute."""

    def __init__(self, message, code=1):
        super().__init__(message)
        self.code = code


class BadInit(Exception):
    """Pickles, but cannot be rebuilt from its pickle: Exception unpickles as BadInit(*args), one argument."""

    def __init__(self, a, b):
        super().__init__(f"{a} and {b}")


def main(out_dir):
    comm = MPI.COMM_WORLD
    rank = comm.Get_rank()
    calls = {}
    made = {}

    def counted(name, body):
        def fn(*args, **kw):
            calls[name] = calls.get(name, 0) + 1
            made[name] = body(*args, **kw)
            return made[name]
        return fn

    def raising(exc):
        def body():
            raise exc
        return body

    def unpicklable_exc():
        e = ValueError("holds a lambda")
        e.hook = lambda: None
        return e

    cases = [
        ("value", dict(), lambda: {"built_on": rank, "data": [1, 2.5, "x"]}),
        ("args_kwargs", dict(args=(2, 3), kw=dict(scale=10)), lambda a, b, scale: (a + b) * scale),
        ("input_error", dict(), raising(InputError("case.toml: mu = -0.7: expected mu >= 0"))),
        ("stopped", dict(), raising(Stopped("run stopped by signal 15", code=143))),
        ("keyboard", dict(), raising(KeyboardInterrupt())),
        ("share_false_value", dict(share=False), lambda: ["only", "rank", rank]),
        ("share_false_raise", dict(share=False), raising(OSError(28, "No space left on device"))),
        ("bad_init", dict(), raising(BadInit("x", "y"))),
        ("unpicklable_exc", dict(), raising(unpicklable_exc())),
        ("unpicklable_value", dict(), lambda: (lambda: None)),
        ("unpicklable_value_not_shared", dict(share=False), lambda: (lambda: None)),
        ("after", dict(), lambda: "last"),
    ]
    got = {}
    for name, opts, body in cases:
        fn = counted(name, body)
        try:
            v = on_root(comm, fn, *opts.get("args", ()), share=opts.get("share", True), **opts.get("kw", {}))
        except BaseException as e:  # noqa: BLE001 - recorded
            got[name] = dict(kind="raised", type=type(e).__name__, module=type(e).__module__, msg=str(e),
                             attrs={k: v for k, v in (*vars(e).items(), ("errno", getattr(e, "errno", None)))
                                    if isinstance(v, (int, str))},
                             cause=type(e.__cause__).__name__ if e.__cause__ is not None else None)
        else:
            plain = v is None or isinstance(v, (bool, int, float, str, list, dict, tuple))
            got[name] = dict(kind="value", value=v if plain else repr(v), callable=callable(v),
                             same_object=name in made and v is made[name])
        got[name]["calls"] = calls.get(name, 0)
    with open(os.path.join(out_dir, f"rank{rank}.json"), "w") as f:
        json.dump(got, f)


if __name__ == "__main__":
    main(sys.argv[1])
