"""Fuzzing the case-file validator: `load_case` either accepts a mutated case or raises InputError.

A seeded mutator (no hypothesis) takes valid case files (demos/vibrating_block.toml,
demos/wall_settlement.toml, demos/arch.toml and a small inline case with rigid bodies, stage
drivers, stop criteria, a cohesive interface and a force curve), applies one or two random
mutations (delete / rename a key, change a value's type, negative / zero / huge / NaN / inf values,
empty lists, duplicated table entries, values swapped between keys), writes the result as TOML
with the small serializer below and calls `load_case` and `expand` (validation and the generated geometry;
nothing is meshed or simulated).
Any exception other than InputError, or a variant taking more than a few seconds, is a failure
reported with the mutation.
"""
import copy
import json
import math
import os
import random
import re
import signal
import time
import tomllib

import pytest

from fem_blocks.case import load_case
from fem_blocks.errors import InputError
from fem_blocks.expand import expand

from _paths import ROOT  # noqa: E402
DEMOS = ["vibrating_block.toml", "wall_settlement.toml", "arch.toml"]
VARIANTS_PER_BASE = 600          # 4 bases -> 2400 variants
SEED = 20240611
TIME_LIMIT = 3                   # seconds per variant (a hang is a failure)

# Former validator gaps found by this fuzzer (non-number wall.openings items crashed, unbounded block counts hung)
# are regression-tested by test_former_gaps_rejected.


INLINE_CASE = """
name = "fuzz_inline"
units = "SI"
gravity = [0.0, -9.81]

[materials.m]
E = 1e9
nu = 0.2
rho = 1000.0
thickness = 0.1
rayleigh = [0.0, 1e-5]

[block_types.t]
geometry = "rectangle"
lx = 1.0
ly = 0.2
mesh_size = 0.2
material = "m"
cell = "quad"
mass = "lumped"

[block_types.p]
geometry = "polygon"
vertices = [[0.0, 0.0], [0.4, 0.0], [0.2, 0.3]]
mesh_size = 0.1
material = "m"

[[blocks]]
name = "a"
type = "t"
position = [0.0, 0.0]
angle = 0.0
group = "blocks"
[[blocks.clamps]]
box = [0.0, 0.05, 0.0, 0.2]
components = "xy"
[[blocks.tractions]]
tag = "top"
value = [0.0, -1e3]
history = {times = [0.0, 0.01], values = [0.0, 1.0]}

[[blocks]]
name = "b"
type = "p"
position = [0.2, 0.2]

[[rigid_bodies]]
name = "base"
vertices = [[0.0, -0.2], [1.0, -0.2], [1.0, 0.0], [0.0, 0.0]]
rho = 1000.0
thickness = 0.1
group = "rigid"
[rigid_bodies.drivers]
x = {kind = "velocity", history = 0.0}
y = {kind = "displacement", history = {times = [0.0, 1.0], values = [0.0, -0.001]}}
rz = {kind = "velocity", history = 0.0}

[[rigid_bodies]]
name = "cap"
vertices = [[0.0, 0.5], [1.0, 0.5], [1.0, 0.6], [0.0, 0.6]]
mass = 10.0
inertia = 1.0
[rigid_bodies.forces]
y = -100.0

[contact]
geometry = "frozen"
tol = 1e-6
max_sweeps = 100
omega = 1.0
order = "shuffled"
seed = 3
criterion = "residual"
check_every = 5
on_nonconvergence = "warn"

[[interfaces]]
name = "joint"
between = ["blocks", "blocks"]
law = "fremond"
mu = 0.5
c_N = 1e10
c_T = 1e10
w = 10.0
friction = "damage"
mu_r = 0.3
g0 = 0.0
alert = 1e-3
placement = "positions"
positions = [0.25, 0.75]

[[interfaces]]
name = "base"
between = ["blocks", "rigid"]
mu = 0.6
candidate = "blocks"
placement = "nodes"

[[stages]]
name = "load"
duration = 0.002
h = 0.001
theta = 1.0
velocity_reset = true
output_every = 1
tol = 1e-5
max_sweeps = 50
[stages.drivers.base]
x = {kind = "displacement", history = {times = [0.0, 1.0], values = [0.0, 0.01]}}
rz = "free"
[stages.forces.cap]
x = 5.0
[stages.stop_after_peak]
body = "base"
dof = "x"
drop = 0.2
min_steps = 2
[stages.stop_at_displacement]
body = "cap"
dof = "y"
value = 0.01

[[stages]]
name = "rest"
duration = 0.002
h = 0.001
[stages.stop_at_equilibrium]
max_velocity = 1e-6
min_steps = 1

[output]
paraview = false
stress = true
checkpoint_every = 0
crack_pattern = false
[output.curve]
body = "base"
force = "x"
displacement = "x"
"""


# ----------------------------------------------------------------------------- a tiny TOML writer
_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE.match(k) else json.dumps(k, ensure_ascii=False)


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)  # '1e+300', '0.1', '-0.0': all valid TOML floats
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)  # JSON string escapes are valid TOML basic-string escapes
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} as TOML")


def dumps(doc: dict) -> str:
    """TOML text of a dict: top-level keys as `key = value`, nested tables as inline tables."""
    return "".join(f"{_key(k)} = {_value(v)}\n" for k, v in doc.items())


# ----------------------------------------------------------------------------- the mutator
def _paths(node, prefix=()):
    """Every (path, value) below the root, containers included."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for k, v in items:
        yield prefix + (k,), v
        yield from _paths(v, prefix + (k,))


def _get(doc, path):
    for k in path:
        doc = doc[k]
    return doc


def _fmt(path):
    return "".join(f"[{k}]" if isinstance(k, int) else f".{k}" for k in path).lstrip(".") or "<root>"


OPS = ["delete", "rename", "to_string", "to_int", "to_float", "to_bool", "to_list", "to_table", "negative", "zero",
       "huge", "huge_int", "nan", "inf", "neg_inf", "empty_list", "duplicate", "swap"]
NAMES = ["E", "nu", "rho", "h", "theta", "mu", "tol", "omega", "type", "material", "name", "body", "dof", "group",
         "between", "history", "times", "values", "kind", "x", "y", "rz", "blocks", "stages", "free", "", "é",
         "a b", "courses", "voussoirs", "mesh_size", "file"]


def mutate_once(doc: dict, rng: random.Random) -> str:
    """Apply one random mutation to doc in place; return its description."""
    paths = list(_paths(doc))
    path, val = paths[rng.randrange(len(paths))]
    parent = _get(doc, path[:-1])
    k = path[-1]
    op = rng.choice(OPS)
    where = _fmt(path)
    if op == "delete":
        del parent[k]
    elif op == "rename":
        if isinstance(parent, dict):
            new = rng.choice(NAMES + [k + "_", k.upper(), k[:-1]])
            parent[new] = parent.pop(k)
            return f"rename {where} -> {new!r}"
        parent.insert(rng.randrange(len(parent) + 1), parent.pop(k))  # list: move the item
        return f"move {where}"
    elif op == "to_string":
        parent[k] = rng.choice(["", "x", "1.0", "free", "velocity", "rectangle", "m", str(val)[:20]])
    elif op == "to_int":
        parent[k] = rng.choice([0, 1, -1, 2, 3, 7])
    elif op == "to_float":
        parent[k] = rng.choice([0.0, 0.5, 1.0, -1.0, 1e-12, 0.25, 2.0])
    elif op == "to_bool":
        parent[k] = rng.choice([True, False])
    elif op == "to_list":
        parent[k] = rng.choice([[val], [1.0, 2.0], [[0.0, 0.0]], ["a", "b"], [True], [{}]])
    elif op == "to_table":
        parent[k] = rng.choice([{}, {"value": val}, {"times": [0.0, 1.0], "values": [0.0, 1.0]},
                                {"kind": "velocity", "history": 0.0}])
    elif op in ("negative", "zero", "huge", "huge_int", "nan", "inf", "neg_inf"):
        num = {"zero": 0, "huge": 1e300, "huge_int": 2 ** 62, "nan": float("nan"), "inf": float("inf"),
               "neg_inf": float("-inf")}
        if op == "negative":
            if isinstance(val, bool) or not isinstance(val, (int, float)):
                parent[k] = -1.0
            else:
                parent[k] = -val if val else -1
        else:
            parent[k] = num[op]
    elif op == "empty_list":
        parent[k] = []
    elif op == "duplicate":
        if isinstance(parent, list):
            parent.insert(k, copy.deepcopy(val))
        elif isinstance(val, list) and val:
            val.append(copy.deepcopy(val[rng.randrange(len(val))]))
            return f"duplicate an entry of {where}"
        else:
            parent[f"{k}_copy" if isinstance(k, str) else k] = copy.deepcopy(val)
    elif op == "swap":
        others = [(p, v) for p, v in paths if p != path and not _is_prefix(p, path) and not _is_prefix(path, p)]
        if not others:
            return "no-op"
        p2, v2 = others[rng.randrange(len(others))]
        _get(doc, p2[:-1])[p2[-1]] = copy.deepcopy(val)
        parent[k] = copy.deepcopy(v2)
        return f"swap {where} <-> {_fmt(p2)}"
    return f"{op} {where}"


def _is_prefix(a, b):
    return len(a) <= len(b) and b[:len(a)] == a


def variants(base: dict, n: int, seed: int):
    rng = random.Random(seed)
    for i in range(n):
        doc = copy.deepcopy(base)
        steps = [mutate_once(doc, rng) for _ in range(1 if rng.random() < 0.7 else 2)]
        yield i, doc, "; ".join(steps)


# ----------------------------------------------------------------------------- tests
def _bases():
    out = []
    for f in DEMOS:
        with open(os.path.join(ROOT, "demos", f), "rb") as fh:
            out.append((f, tomllib.load(fh)))
    out.append(("inline", tomllib.loads(INLINE_CASE)))
    return out


BASES = _bases()


class _Timeout(Exception):
    pass


def _alarm(signum, frame):
    raise _Timeout()


@pytest.mark.parametrize("name, base", BASES, ids=[b[0] for b in BASES])
def test_writer_round_trip_and_base_valid(tmp_path, name, base):
    text = dumps(base)
    assert tomllib.loads(text) == base
    p = tmp_path / "base.toml"
    p.write_text(text, encoding="utf-8")
    expand(load_case(str(p)))


def test_writer_special_values():
    doc = {"a b": {"": [float("inf"), -float("inf"), 1e300, -0.0, 2 ** 62, True, "q\"\\\n\t é"], "t": {}},
           "l": [], "m": [[1, "x"], {"k": []}]}
    back = tomllib.loads(dumps({"n": float("nan"), **doc}))
    assert math.isnan(back.pop("n")) and back == doc


@pytest.mark.parametrize("name, base", BASES, ids=[b[0] for b in BASES])
def test_fuzz_load_case(tmp_path, name, base):
    """load_case on VARIANTS_PER_BASE mutations of one base case: accepted or InputError, nothing else."""
    failures = []
    counts = {"accepted": 0, "rejected": 0}
    old = signal.signal(signal.SIGALRM, _alarm)
    t0 = time.perf_counter()
    try:
        for i, doc, what in variants(base, VARIANTS_PER_BASE, SEED + hash_name(name)):
            path = tmp_path / f"v{i:04d}.toml"
            path.write_text(dumps(doc), encoding="utf-8")
            signal.alarm(TIME_LIMIT)
            try:
                expand(load_case(str(path)))
                counts["accepted"] += 1
            except InputError as e:
                counts["rejected"] += 1
                msg = str(e)
                if "\n" in msg or not msg.startswith(str(path)):
                    failures.append(f"variant {i} ({what}): InputError not one line naming the file: {msg!r}")
            except _Timeout:
                failures.append(f"variant {i} ({what}): load_case took more than {TIME_LIMIT} s")
            except Exception as e:  # noqa: BLE001 - the point of the test
                failures.append(f"variant {i} ({what}): {type(e).__name__}: {e}"[:400])
            finally:
                signal.alarm(0)
            path.unlink()
    finally:
        signal.signal(signal.SIGALRM, old)
    elapsed = time.perf_counter() - t0
    print(f"{name}: {VARIANTS_PER_BASE} variants in {elapsed:.1f} s: {counts}")
    assert counts["rejected"] > 0 and counts["accepted"] > 0
    assert not failures, f"{name}: {len(failures)} of {VARIANTS_PER_BASE} variants escaped InputError:\n" + \
        "\n".join(failures[:40])


def hash_name(name: str) -> int:
    """A stable (not salted) small integer per base name, for the per-base seed."""
    return sum((i + 1) * ord(c) for i, c in enumerate(name))


def _wall_doc():
    return copy.deepcopy(dict(BASES)["wall_settlement.toml"])


def _arch_doc():
    return copy.deepcopy(dict(BASES)["arch.toml"])


FORMER_GAP_CASES = [
    ("opening_item_string", lambda: {**_wall_doc(), "wall": {**_wall_doc()["wall"], "openings": [[0.45, "a", 0.75, 0.4]]}}),
    ("opening_item_table", lambda: {**_wall_doc(), "wall": {**_wall_doc()["wall"], "openings": [[0.45, {}, 0.75, 0.4]]}}),
    ("voussoirs_huge", lambda: {**_arch_doc(), "arch": {**_arch_doc()["arch"], "voussoirs": 2 ** 62}}),
]


@pytest.mark.parametrize("name, make", FORMER_GAP_CASES, ids=[c[0] for c in FORMER_GAP_CASES])
def test_former_gaps_rejected(tmp_path, name, make):
    path = tmp_path / f"{name}.toml"
    path.write_text(dumps(make()), encoding="utf-8")
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(TIME_LIMIT)
    try:
        with pytest.raises(InputError):
            expand(load_case(str(path)))
    except _Timeout:
        pytest.fail(f"{name}: load_case took more than {TIME_LIMIT} s")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
