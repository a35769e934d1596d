"""on_root (fem_blocks/distributed/root.py): rank 0 calls fn; every rank returns its value or raises its exception.

Expectations, written from the contract and not from the code: on one process (comm None, or a communicator of
size 1) on_root IS fn: the same object returned, the same exception object raised, fn called once, no
communication. On 2 ranks (ONE mpirun launch, tests/_on_root_mpi.py, every case in sequence): fn runs on rank 0
only; a value built there (it records the rank that built it) reaches rank 1 equal; an exception raised there is
raised on both ranks with the same type, message and attributes; share=False gives rank 1 None but still the
exception; an exception or value that cannot make the pickle round trip becomes the same RuntimeError on both
ranks; the calls stay paired (a value after all of that arrives intact), and nothing hangs (launch timeout).

One-line bugs, each made in root.py and seen to fail here (what fails in brackets):
- every rank acting as rank 0, calling fn itself (`if False and comm.Get_rank() != 0`: rank 1's value says
  built_on 1 and calls 1);
- rank 0 not broadcasting its exception before re-raising it (rank 1 waits forever: the launch times out);
- only Exception caught on rank 0, not BaseException (keyboard: rank 1 waits forever: the launch times out);
- rank 1 returning the received exception instead of raising it (kind "value" for input_error on rank 1);
- share ignored, the value always sent (share_false_value: rank 1 gets the list, not None);
- share=False also dropping the exception (share_false_raise: rank 1 returns None instead of raising OSError);
- no load of the pickle on rank 0 before sending (bad_init: rank 0 raises BadInit, not the RuntimeError);
- a communicator of size 1 not taken as one process (the size-1 serial case: comm.Get_rank used).
- root.py importing a fem_blocks module (`from ..errors import InputError`: the import test).
"""
import json
import os

import pytest

from fem_blocks.distributed.root import on_root
from fem_blocks.errors import InputError


class _Size1:
    """A communicator of one rank that must not be used for anything but its size."""

    def Get_size(self):
        return 1

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        raise AssertionError(f"comm.{name} used on one rank")


@pytest.mark.parametrize("comm", [None, _Size1()])
def test_one_process_is_a_plain_call(comm):
    calls = []
    obj = {"a": [1, 2]}

    def fn(a, b=0):
        calls.append((a, b))
        return obj

    assert on_root(comm, fn, 1, b=2) is obj and calls == [(1, 2)]
    assert on_root(comm, fn, 3, share=False) is obj and calls[-1] == (3, 0)  # no other rank: the value itself
    err = InputError("x.toml: mu = -1: expected mu >= 0")

    def bad():
        raise err

    with pytest.raises(InputError) as info:
        on_root(comm, bad)
    assert info.value is err and info.value.__cause__ is None  # unchanged, not wrapped
    unpicklable = ValueError("holds a lambda")
    unpicklable.hook = lambda: None

    def bad2():
        raise unpicklable

    with pytest.raises(ValueError) as info:  # one process: nothing is pickled, nothing replaced
        on_root(comm, bad2)
    assert info.value is unpicklable


@pytest.fixture(scope="module")
def ranks(tmp_path_factory):
    """What rank 0 and rank 1 got, case by case (one mpirun -n 2 launch)."""
    from _mpi import run_helper
    d = tmp_path_factory.mktemp("on_root")
    run_helper(2, "_on_root_mpi.py", d)
    return [json.loads((d / f"rank{r}.json").read_text()) for r in (0, 1)]


def _raised(type_name, msg, module=None, **attrs):
    def check(g):
        assert g["kind"] == "raised", g
        assert (g["type"], g["msg"]) == (type_name, msg), g
        if module:
            assert g["module"] == module, g
        assert {k: g["attrs"].get(k) for k in attrs} == attrs, g
    return check


def test_value_built_on_rank_0_reaches_every_rank(ranks):
    r0, r1 = ranks
    want = {"built_on": 0, "data": [1, 2.5, "x"]}
    assert r0["value"] == dict(kind="value", value=want, callable=False, same_object=True, calls=1)
    assert r1["value"] == dict(kind="value", value=want, callable=False, same_object=False, calls=0)
    for r in ranks:  # positional and keyword arguments reach fn: (2 + 3) * 10
        assert (r["args_kwargs"]["kind"], r["args_kwargs"]["value"]) == ("value", 50)
    assert r1["args_kwargs"]["calls"] == 0


def test_exception_on_rank_0_is_raised_on_every_rank(ranks):
    for r in ranks:
        _raised("InputError", "case.toml: mu = -0.7: expected mu >= 0", module="fem_blocks.errors")(r["input_error"])
        _raised("Stopped", "run stopped by signal 15", code=143)(r["stopped"])
        _raised("KeyboardInterrupt", "")(r["keyboard"])
        assert r["input_error"]["cause"] is None
    assert [r["input_error"]["calls"] for r in ranks] == [1, 0]


def test_share_false_value_on_rank_0_only_but_the_exception_everywhere(ranks):
    r0, r1 = ranks
    assert (r0["share_false_value"]["value"], r0["share_false_value"]["same_object"]) == (["only", "rank", 0], True)
    assert r1["share_false_value"] == dict(kind="value", value=None, callable=False, same_object=False, calls=0)
    for r in ranks:
        _raised("OSError", "[Errno 28] No space left on device", errno=28)(r["share_false_raise"])


def test_what_cannot_be_pickled_is_the_same_runtime_error_on_every_rank(ranks):
    r0, r1 = ranks
    for r in ranks:
        _raised("RuntimeError", "BadInit: x and y")(r["bad_init"])
        _raised("RuntimeError", "ValueError: holds a lambda")(r["unpicklable_exc"])
        g = r["unpicklable_value"]
        assert g["kind"] == "raised" and g["type"] == "RuntimeError", g
        assert g["msg"].startswith("on_root: the value of ") and "cannot be sent to the other ranks" in g["msg"], g
    # rank 0 raises the replacement from the original (its traceback kept)
    assert (r0["bad_init"]["cause"], r0["unpicklable_exc"]["cause"]) == ("BadInit", "ValueError")
    # not shared: nothing to send, rank 0 keeps its value
    assert (r0["unpicklable_value_not_shared"]["callable"], r0["unpicklable_value_not_shared"]["same_object"]) == \
        (True, True)
    assert (r1["unpicklable_value_not_shared"]["value"], r1["unpicklable_value_not_shared"]["callable"]) == \
        (None, False)


def test_calls_stay_paired_after_failures(ranks):
    for r in ranks:
        assert (r["after"]["kind"], r["after"]["value"]) == ("value", "last")
    assert sum(g["calls"] for g in ranks[1].values()) == 0  # rank 1 never called fn


def test_root_module_imports_nothing_of_fem_blocks():
    """runner.py and output/pvd.py import root.py: it must import no fem_blocks module (no import cycle)."""
    from test_imports import PKG, imports_of, modules
    mods = modules()
    assert imports_of("fem_blocks.distributed.root", os.path.join(PKG, "distributed", "root.py"), set(mods)) == set()
