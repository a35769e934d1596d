"""Case files (TOML): parse and validate everything before anything runs.

Every error is an `InputError` with one line naming the file, the key path (e.g.
``blocks[2].position``) and what was expected; the CLI prints it and exits with status 2.
The key-by-key reference is `docs/case-files.md`.

A case describes materials, block types (meshed once, instanced many times), deformable block
instances, rigid bodies, and a load protocol of stages. Units are SI unless ``units = "mm-N-MPa"``
(lengths in mm, forces in N, stresses and moduli in MPa, densities in t/mm^3... see docs), in
which case values are converted to SI at load.
"""
from __future__ import annotations

import dataclasses
import difflib
import hashlib
import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import casefile
from .errors import InputError
from .geometry import box_corners, check_hex_corners, rotation3d
from .specs import (DRIVER_KINDS, LAW_PARAMS, NONCONV, ChecksSpec, ContactOptions, DriverSpec,  # noqa: F401
                    InterfaceSpec, MaterialSpec, OutputSpec, ReferenceSpec, StageSpec, controls_at, default_of,
                    schema_fields, toml_key)

NUMBER = (int, float)


def _finite(x) -> bool:
    """A finite TOML number (int or float, not a bool)."""
    return isinstance(x, NUMBER) and not isinstance(x, bool) and math.isfinite(x)

# unit systems: factor to SI per physical dimension
UNIT_SYSTEMS = {
    "SI": dict(length=1.0, force=1.0, stress=1.0, density=1.0, time=1.0, mass=1.0, moment=1.0),
    # mm, N, MPa, s -> mass unit tonne (N s^2/mm), density t/mm^3, moment N mm
    "mm-N-MPa": dict(length=1e-3, force=1.0, stress=1e6, density=1e12, time=1.0, mass=1e3, moment=1e-3),
}


_SI, _MM = UNIT_SYSTEMS["SI"], UNIT_SYSTEMS["mm-N-MPa"]
STANDARD_GRAVITY = 9.80665  # [m/s^2] g_n, exact by definition (3rd CGPM, 1901): the unit "g" of acceleration records
# Unit names of a CSV history's `time_unit` / `value_unit`: name -> (quantity, factor to SI). The factors are those
# of UNIT_SYSTEMS (one home: "mm" is the length unit of "mm-N-MPa", "N mm" its moment unit...).
UNIT_NAMES = {
    "s": ("time", _SI["time"]), "ms": ("time", 1e-3 * _SI["time"]),
    "m": ("length", _SI["length"]), "mm": ("length", _MM["length"]),
    "m/s": ("velocity", _SI["length"] / _SI["time"]), "mm/s": ("velocity", _MM["length"] / _MM["time"]),
    "m/s2": ("acceleration", _SI["length"] / _SI["time"] ** 2),
    "mm/s2": ("acceleration", _MM["length"] / _MM["time"] ** 2), "g": ("acceleration", STANDARD_GRAVITY),
    "rad": ("angle", 1.0), "deg": ("angle", math.pi / 180.0),
    "rad/s": ("angular velocity", 1.0 / _SI["time"]), "deg/s": ("angular velocity", math.pi / 180.0 / _SI["time"]),
    "N": ("force", _SI["force"]), "kN": ("force", 1e3 * _SI["force"]),
    "N m": ("moment", _SI["moment"]), "N mm": ("moment", _MM["moment"]), "kN m": ("moment", 1e3 * _SI["moment"]),
    "1": ("dimensionless", 1.0),
}


def history_files(obj, out: set | None = None) -> set:
    """The CSV files of every history read from a file ({times, values, file}) anywhere in a case (its specs,
    stages, generators): what `fingerprint` adds to the case's digest."""
    out = set() if out is None else out
    if isinstance(obj, dict):
        if "file" in obj and "times" in obj and isinstance(obj["file"], str):
            out.add(obj["file"])
        for v in obj.values():
            history_files(v, out)
    elif isinstance(obj, (list, tuple)):
        for v in obj:
            if isinstance(v, (dict, list, tuple)) or dataclasses.is_dataclass(v):
                history_files(v, out)
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        for f in dataclasses.fields(obj):
            history_files(getattr(obj, f.name), out)
    return out


class Table:
    """A validated view of one TOML table: typed getters that record used keys.

    `done()` raises on any key that was not read (unknown or misspelt key)."""

    def __init__(self, data: dict, path: str, source: str, units: dict):
        if not isinstance(data, dict):
            raise InputError(f"{source}: {path}: expected a table, got {_tname(data)}")
        self.data, self.path, self.source, self.units = data, path, source, units
        self.used: set[str] = set()

    def key(self, k: str) -> str:
        return f"{self.path}.{k}" if self.path else k

    def error(self, k: str, msg: str) -> InputError:
        return InputError(f"{casefile.origin(self.source, self.key(k))}: {self.key(k)}: {msg}")

    def missing(self, k: str, expected: str) -> InputError:
        """The error for a required key `k` that is absent: "KEY: missing; EXPECTED", or, when the table holds an
        unknown key close to `k` (a misspelling, difflib), an error naming that key and suggesting `k`."""
        close = self.misspelt(k)
        if close is not None:
            return InputError(f"{casefile.origin(self.source, self.key(close))}: {self.key(close)}: unknown key "
                              f"{close!r} — did you mean {k!r}? ({self.key(k)} is required: {expected})")
        return self.error(k, f"missing; {expected}")

    def misspelt(self, k: str) -> str | None:
        """An unread key of this table that looks like a misspelling of `k` (same letters up to case, or a
        difflib similarity >= 0.75), or None."""
        others = [x for x in self.data if isinstance(x, str) and x != k and x not in self.used]
        for x in others:
            if x.lower() == k.lower():
                return x
        low = {x.lower(): x for x in others}
        close = difflib.get_close_matches(k.lower(), list(low), n=1, cutoff=0.75)
        return low[close[0]] if close else None

    def has(self, k: str) -> bool:
        return k in self.data

    def raw(self, k: str, default=None):
        self.used.add(k)
        return self.data.get(k, default)

    def number(self, k: str, default=None, lo=None, hi=None, lo_open=False, hi_open=False,
               dim: str | None = None, required: bool = False, integer: bool = False) -> float | None:
        """A number in [lo, hi] (bounds in SI after conversion are the same as in the file when dim is None)."""
        self.used.add(k)
        if k not in self.data:
            if required or default is _REQUIRED:
                raise self.missing(k, "expected " + _range_text(lo, hi, lo_open, hi_open, integer))
            return default
        v = self.data[k]
        if isinstance(v, bool) or not isinstance(v, NUMBER) or (isinstance(v, float) and not math.isfinite(v)):
            raise self.error(k, f"expected a finite number, got {v!r}")
        if integer and not isinstance(v, int):
            raise self.error(k, f"expected an integer, got {v!r}")
        ok = (lo is None or (v > lo if lo_open else v >= lo)) and (hi is None or (v < hi if hi_open else v <= hi))
        if not ok:
            raise self.error(k, f"= {v!r}: expected {_range_text(lo, hi, lo_open, hi_open, integer)}")
        return int(v) if integer else float(v) * (self.units[dim] if dim else 1.0)

    def integer(self, k: str, default=None, lo=None, hi=None, required=False) -> int | None:
        return self.number(k, default, lo, hi, required=required, integer=True)

    def string(self, k: str, default=None, choices=None, required=False) -> str | None:
        self.used.add(k)
        if k not in self.data:
            if required:
                raise self.missing(k, f"expected one of {list(choices)}" if choices else "expected a string")
            return default
        v = self.data[k]
        if not isinstance(v, str):
            raise self.error(k, f"expected a string, got {v!r}")
        if choices is not None and v not in choices:
            raise self.error(k, f"= {v!r}: expected one of {list(choices)}")
        return v

    def boolean(self, k: str, default=False) -> bool:
        self.used.add(k)
        v = self.data.get(k, default)
        if not isinstance(v, bool):
            raise self.error(k, f"expected true or false, got {v!r}")
        return v

    def vector(self, k: str, n: int, default=None, dim: str | None = None, required=False,
               lo=None) -> tuple | None:
        self.used.add(k)
        if k not in self.data:
            if required:
                raise self.missing(k, f"expected a list of {n} numbers")
            return default
        v = self.data[k]
        if not isinstance(v, list) or len(v) != n or not all(_finite(x) for x in v):
            raise self.error(k, f"expected a list of {n} finite numbers, got {v!r}")
        if lo is not None and any(x < lo for x in v):
            raise self.error(k, f"= {v!r}: expected values >= {lo}")
        f = self.units[dim] if dim else 1.0
        return tuple(float(x) * f for x in v)

    def points(self, k: str, dim: str = "length", min_count: int = 3, required=True, n: int = 2,
               exact: bool = False):
        """A list of points of n coordinates ([x, y] or [x, y, z]); at least `min_count` (exactly, if exact)."""
        self.used.add(k)
        xyz = "[x, y]" if n == 2 else "[x, y, z]"
        count = f"{'exactly' if exact else 'at least'} {min_count}"
        if k not in self.data:
            if required:
                raise self.missing(k, f"expected a list of {count} {xyz} points")
            return None
        v = self.data[k]
        ok = isinstance(v, list) and (len(v) == min_count if exact else len(v) >= min_count) and all(
            isinstance(p, list) and len(p) == n and all(_finite(x) for x in p) for p in v)
        if not ok:
            raise self.error(k, f"expected a list of {count} {xyz} points of finite numbers")
        f = self.units[dim]
        return [tuple(float(x) * f for x in p) for p in v]

    def dimension_keys(self, D: int, only: dict):
        """Keys that exist in one dimension only (`only`: key -> its dimension) are an error in the other one,
        naming the key and the dimension."""
        for k, d in only.items():
            if k in self.data and d != D:
                raise self.error(k, f"not used in dimension {D} (a key of dimension {d} case files); "
                                    f"see docs/case-files.md, 'dimension'")

    def history(self, k: str, dim: str | None, default=None, required=False, protocol: bool = False,
                quantity: str | None = None):
        """A number or {times = [...], values = [...]} (times strictly increasing); with `protocol` (a displacement
        driver) also a cyclic protocol {protocol = "cyclic", ...} (specs.CyclicProtocol), returned expanded
        (cyclic_history); or a CSV file {file = ..., time, value, time_unit, value_unit, scale} (`_history_csv`,
        returned as {times, values, file}): every caller gets a number or {times, values}. `quantity`: what the
        values are ("length", "velocity", "acceleration", "force", "moment", "angle", "angular velocity",
        "dimensionless"; default from `dim`), the kind a CSV file's `value_unit` must have."""
        self.used.add(k)
        if k not in self.data:
            if required:
                raise self.missing(k, "expected a number or {times = [...], values = [...]}")
            return default
        v = self.data[k]
        f = self.units[dim] if dim else 1.0
        if _finite(v):
            return float(v) * f
        if isinstance(v, dict) and "protocol" in v:
            if not protocol:
                raise self.error(k + ".protocol", "a cyclic protocol is a displacement history: expected it in a "
                                                  "driver with kind = \"displacement\" (here: a number or "
                                                  "{times = [...], values = [...]})")
            return self._protocol(k, dim)
        if isinstance(v, dict) and "file" in v:
            q = quantity or {None: "dimensionless", "length": "length", "force": "force", "moment": "moment"}.get(dim)
            return self._history_csv(k, dim, q)
        if isinstance(v, dict):
            t = Table(v, self.key(k), self.source, self.units)
            times = t.raw("times")
            values = t.raw("values")
            t.done()
            good = (isinstance(times, list) and isinstance(values, list) and len(times) == len(values) >= 1
                    and all(_finite(x) for x in times + values))
            if not good:
                raise self.error(k, "expected {times = [...], values = [...]} of equal non-zero length")
            if any(b <= a for a, b in zip(times, times[1:])):
                raise self.error(k + ".times", "expected strictly increasing times")
            tf = self.units["time"]
            return {"times": [float(x) * tf for x in times], "values": [float(x) * f for x in values]}
        raise self.error(k, f"expected a number or {{times = [...], values = [...]}}, got {v!r}")

    def _history_csv(self, k: str, dim: str | None, quantity: str | None) -> dict:
        """`history = {file = "record.csv", time = "t", value = "a", time_unit = "s", value_unit = "m/s2",
        scale = 1.0}` -> {times, values, file} in SI (docs/case-files.md "Histories from CSV files"). The file is
        relative to the case file; cells separated by commas (else semicolons, else blanks); blank lines and lines
        starting with '#' skipped; a first row holding a non-number is the header; `time`, `value`: column names
        (need the header) or 0-based indices (default 0 and 1); units: UNIT_NAMES (default: the case's units);
        value = scale x cell x unit. Errors name the file, the line and the column."""
        t = Table(self.data[k], self.key(k), self.source, self.units)
        f = t.string("file", required=True)
        base = os.path.dirname(os.path.abspath(self.source)) if os.path.exists(self.source) else os.getcwd()
        full, rows, header = _csv_rows(t, f, base)
        idx = []
        for key, dflt in (("time", 0), ("value", 1)):
            t.used.add(key)
            c = t.data.get(key, dflt)
            if isinstance(c, bool) or not isinstance(c, (int, str)) or (isinstance(c, int) and c < 0):
                raise t.error(key, f"= {c!r}: expected a column name (string) or a 0-based column index")
            if isinstance(c, str):
                if header is None:
                    raise t.error(key, f"= {c!r}: {f!r} has no header line naming its columns (give a 0-based "
                                       f"index instead)")
                if c not in header:
                    raise t.error(key, f"= {c!r}: no column {c!r} in {f!r} (its columns: {header})")
                c = header.index(c)
            idx.append(c)
        units = {}
        for key, q, dflt in (("time_unit", "time", self.units["time"]), ("value_unit", quantity, None)):
            u = t.string(key)
            if u is None:
                units[key] = dflt
                continue
            ok = [n for n, (qq, _) in UNIT_NAMES.items() if qq == q]
            if u not in UNIT_NAMES or UNIT_NAMES[u][0] != q:
                if q == "dimensionless":
                    raise t.error(key, f"= {u!r}: this history is a dimensionless factor: expected no {key} (or '1')")
                raise t.error(key, f"= {u!r}: expected a unit of {q} ({', '.join(map(repr, ok))})")
            units[key] = UNIT_NAMES[u][1]
        scale = t.number("scale", 1.0)
        t.done()
        vf = (units["value_unit"] if units["value_unit"] is not None else (self.units[dim] if dim else 1.0)) * scale
        times, values = [], []
        for n, cells in rows:
            for key, j in zip(("time", "value"), idx):
                if len(cells) <= j:
                    raise t.error("file", f"= {f!r}, line {n}: expected at least {j + 1} columns (column {j}, the "
                                          f"{key}), got {len(cells)}")
                c = cells[j]
                if not (_is_number(c) and math.isfinite(float(c))):
                    raise t.error("file", f"= {f!r}, line {n}, column {j} ({key}): expected a finite number, "
                                          f"got {c!r}")
            tt, vv = float(cells[idx[0]]) * units["time_unit"], float(cells[idx[1]]) * vf
            if times and tt <= times[-1]:
                raise t.error("file", f"= {f!r}, line {n}, column {idx[0]} (time): expected strictly increasing "
                                      f"times, got {cells[idx[0]]} after {times[-1] / units['time_unit']:g}")
            times.append(tt)
            values.append(vv)
        if not times:
            raise t.error("file", f"= {f!r}: expected at least one data row (time, value)")
        return {"times": times, "values": values, "file": os.path.abspath(full)}

    def _protocol(self, k: str, dim: str | None) -> dict:
        """The cyclic protocol table at key `k` (fields of specs.CyclicProtocol; amplitudes and rate in the unit
        `dim` of the driven dof) -> the expanded {times, values} (cyclic_history)."""
        from .specs import CyclicProtocol
        t = Table(self.data[k], self.key(k), self.source, self.units)
        f = read_fields(t, CyclicProtocol, ("protocol", "cycles", "start"))
        md = {x.name: x.metadata for x in schema_fields(CyclicProtocol)}
        rate = t.number("rate", required=True, lo=md["rate"]["lo"], lo_open=True, dim=dim)
        t.used.add("amplitudes")
        if "amplitudes" not in t.data:
            raise t.missing("amplitudes", "expected " + md["amplitudes"]["expected"])
        a = t.data["amplitudes"]
        if (not isinstance(a, list) or not a or not all(_finite(x) for x in a)
                or any(x <= 0 for x in a) or any(y <= x for x, y in zip(a, a[1:]))):
            raise t.error("amplitudes", f"= {a!r}: expected {md['amplitudes']['expected']}")
        t.done()
        scale = self.units[dim] if dim else 1.0
        return cyclic_history([float(x) * scale for x in a], f["cycles"], rate, f["start"])

    def table(self, k: str, required=False) -> "Table | None":
        self.used.add(k)
        if k not in self.data:
            if required:
                raise self.missing(k, "expected a table")
            return None
        return Table(self.data[k], self.key(k), self.source, self.units)

    def tables(self, k: str, required=False, min_count: int = 0) -> list["Table"]:
        """An array of tables ([[k]])."""
        self.used.add(k)
        v = self.data.get(k)
        if v is None:
            if required or min_count:
                raise self.missing(k, f"expected at least {max(1, min_count)} [[{k}]] entries")
            return []
        if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
            raise self.error(k, f"expected an array of tables [[{k}]]")
        if len(v) < min_count:
            raise self.error(k, f"expected at least {min_count} entries, got {len(v)}")
        return [Table(x, f"{self.key(k)}[{i}]", self.source, self.units) for i, x in enumerate(v)]

    def named_tables(self, k: str) -> dict[str, "Table"]:
        """A table of tables ([k.name])."""
        t = self.table(k)
        if t is None:
            return {}
        out = {}
        for name in t.data:
            t.used.add(name)
            out[name] = Table(t.data[name], t.key(name), self.source, self.units)
        return out

    def done(self):
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            k = unknown[0]
            low = {x.lower(): x for x in self.used}
            close = [x for x in self.used if x.lower() == k.lower()] or \
                [low[c] for c in difflib.get_close_matches(k.lower(), list(low), n=1, cutoff=0.75)]
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise self.error(k, "unknown key" + hint + (f" (expected one of {sorted(self.used)})" if self.used
                                                        else ""))


_REQUIRED = object()


def cyclic_history(amplitudes, cycles: int, rate: float, start: float = 0.0) -> dict:
    """The one expansion of a cyclic displacement protocol (specs.CyclicProtocol) into a piecewise-linear history
    with a knot at every reversal: values 0, then (+a, -a) `cycles` times for each amplitude a in order, then 0;
    times from t_0 = start at the constant rate |du/dt| = rate, t_{j+1} = t_j + |u_{j+1} - u_j| / rate (SI in,
    {times, values} out; the duration is sum_i 4 cycles a_i / rate)."""
    values = [0.0]
    for a in amplitudes:
        for _ in range(int(cycles)):
            values += [float(a), -float(a)]
    values.append(0.0)
    times = [float(start)]
    for u0, u1 in zip(values, values[1:]):
        times.append(times[-1] + abs(u1 - u0) / rate)
    return {"times": times, "values": values}


def _tname(v) -> str:
    return type(v).__name__


def _range_text(lo, hi, lo_open, hi_open, integer) -> str:
    kind = "an integer" if integer else "a number"
    parts = []
    if lo is not None:
        parts.append(f"{'>' if lo_open else '>='} {lo:g}")
    if hi is not None:
        parts.append(f"{'<' if hi_open else '<='} {hi:g}")
    return kind + (" " + " and ".join(parts) if parts else "")


def read_fields(t: "Table", cls, names, defaults: dict | None = None) -> dict:
    """The one TOML -> schema mapper: read the fields `names` (in that order) of the schema class `cls`
    (specs.py) from table t with their metadata (TOML key, default, unit kind, range or choices, required)
    -> {field name: value in SI}. `defaults`: field -> default where it depends on other keys."""
    fields = {f.name: f for f in schema_fields(cls)}
    out = {}
    for name in names:
        f = fields[name]
        md, k = f.metadata, toml_key(f)
        d = (defaults or {}).get(name, None if f.default is dataclasses.MISSING else f.default)
        base = str(f.type).split("|")[0].strip()
        req = md["required"]
        if md["choices"] is not None:
            v = t.string(k, d, choices=tuple(c for c in md["choices"] if c is not None), required=req)
        elif base == "bool":
            v = t.boolean(k, d)
        elif base == "str":
            v = t.string(k, d, required=req)
        elif base == "int":
            v = t.integer(k, d, lo=md["lo"], hi=md["hi"], required=req)
        elif base == "float":
            unit = md["unit"]
            v = t.number(k, d, lo=md["lo"], hi=md["hi"], lo_open=md["lo_open"], hi_open=md["hi_open"],
                         dim=None if unit in DERIVED else unit, required=req)
            if unit in DERIVED and v is not None and k in t.data:
                v *= DERIVED[unit](t.units)
        else:
            raise TypeError(f"{cls.__name__}.{name}: no TOML reader for type {f.type}")
        out[name] = v
    return out


# ----------------------------------------------------------------------------- case objects
@dataclass
class BlockTypeSpec:
    name: str
    geometry: str  # rectangle | polygon | file
    material: str
    mesh_size: float
    cell: str
    mass: str
    lx: float = 0.0
    ly: float = 0.0
    vertices: list | None = None
    file: str | None = None
    lz: float = 0.0                   # 3D box: size (lx, ly, lz)
    divisions: tuple | None = None    # 3D box/hexahedron: hexahedra along the 3 edges (instead of mesh_size)
    corners: list | None = None       # 3D hexahedron: 8 corners, gmsh order


@dataclass
class ClampSpec:
    box: tuple | None
    tag: str | None
    components: str


@dataclass
class TractionSpec:
    tag: str
    value: tuple
    history: Any


@dataclass
class BlockSpec:
    name: str
    type: str
    position: tuple
    angle: float  # radians
    group: str = "blocks"
    clamps: list = field(default_factory=list)
    tractions: list = field(default_factory=list)
    parent: int = -1  # split_bricks: the two halves of one brick share a parent id (crack interface)
    R: Any = None     # 3D: rotation matrix (x = R X + position); None in 2D (angle)
    initial_velocity: tuple | None = None  # [m/s] of the mass centre (global)
    initial_spin: Any = None               # [rad/s]: 2D a float, 3D (wx, wy, wz)


@dataclass
class RigidSpec:
    name: str
    vertices: list          # 2D: polygon; 3D: the 8 corners of a hexahedron (gmsh order)
    rho: float | None
    mass: float | None
    inertia: Any            # 2D: float [kg m^2]; 3D: 3 principal values or None
    thickness: float
    drivers: dict
    forces: dict
    group: str = "rigid"
    initial_velocity: tuple | None = None  # [m/s] of the centre of mass (global), free translation dofs
    initial_spin: Any = None               # [rad/s]: 2D a float, 3D (wx, wy, wz), free rotation dofs


# ----------------------------------------------------------------------------- generated geometry (expand.py)
@dataclass(kw_only=True)
class GeneratorSpec:
    """A [wall], [arch], [wall3d] or [dome] section as given in the file (SI, validated): expand.py turns it into
    block types, blocks and rigid bodies. `key` is the section's key path (errors and notes of expand name
    "SOURCE: KEY.FIELD"). `rigid` lists the rigid bodies it makes (name, group, mass, drivers, forces) with
    vertices None: expand adds their geometry, so their names and drivers are known before it (stage checks)."""
    key: str
    material: str
    group: str
    mesh_size: float | None      # element size [m] (2D; 3D: or divisions)
    cell: str
    mass: str
    divisions: tuple | None = None

    @property
    def rigid(self) -> list:
        return []


@dataclass
class SlabSpec:
    """A rigid foundation or top beam under/over a generated wall: `bodies` its RigidSpec(s) without vertices
    (a 2D foundation cut at `cuts` [m, absolute x] is one body per part)."""
    depth: float
    overhang: float
    bodies: list
    cuts: list = field(default_factory=list)


@dataclass(kw_only=True)
class SlabbedSpec(GeneratorSpec):
    """A wall generator with an optional rigid foundation and top beam (2D [wall], 3D [wall3d])."""
    foundation: SlabSpec | None = None
    beam: SlabSpec | None = None

    @property
    def rigid(self) -> list:
        return [r for s in (self.foundation, self.beam) if s is not None for r in s.bodies]


@dataclass(kw_only=True)
class WallSpec(SlabbedSpec):
    """[wall] (2D): running bond, explicit courses or a stacked prism (builders), optionally split bricks."""
    kind: str                          # running_bond | courses | prism
    brick_length: float
    brick_height: float
    joint: float
    expanded: bool
    position: tuple
    courses: int | None = None         # running_bond
    bricks_per_course: int | None = None
    half_bricks: bool = True
    openings: list = field(default_factory=list)  # [x0, y0, x1, y1] [m]
    rows: list | None = None           # courses: items (brick lengths or {"gap": w [m]})
    bricks: int | None = None          # prism
    split_bricks: bool = False


@dataclass(kw_only=True)
class ArchSpec(GeneratorSpec):
    """[arch] (2D): semicircular arch of identical voussoirs on two fixed rigid piers."""
    span: float
    ring_depth: float
    voussoirs: int
    pier_height: float
    pier_width: float
    joint: float
    piers: list = field(default_factory=list)  # the two pier RigidSpecs (no vertices)

    @property
    def rigid(self) -> list:
        return list(self.piers)


@dataclass(kw_only=True)
class Wall3DSpec(SlabbedSpec):
    """[wall3d]: running-bond wall of hexahedral bricks (builders3d), optional foundation and top beam."""
    brick_length: float
    brick_height: float
    brick_width: float
    joint: float
    position: tuple
    angle: float                       # [rad] about z
    leaves: int
    openings: list                     # [x0, z0, x1, z1] [m], wall frame
    courses: int
    bricks_per_course: int
    half_bricks: bool
    stagger_leaves: bool


@dataclass(kw_only=True)
class DomeSpec(GeneratorSpec):
    """[dome]: spherical dome of hexahedral voussoirs (builders3d.dome), optional fixed rigid piers."""
    span: float
    thickness: float
    courses: int
    blocks_per_course: int
    joint: float
    top_elevation: float | None        # [rad]
    running_bond: bool
    piers: int
    pier_blocks: int
    pier_height: float
    pier_bodies: list = field(default_factory=list)

    @property
    def rigid(self) -> list:
        return list(self.pier_bodies)


DERIVED = {"stiffness": lambda U: U["stress"] / U["length"], "energy": lambda U: U["force"] / U["length"],
           "viscosity": lambda U: U["force"] / U["length"] * U["time"]}


@dataclass
class Case:
    source: str
    name: str
    units: str
    gravity: tuple
    materials: dict
    block_types: dict
    blocks: list
    rigid_bodies: list
    stages: list
    output: dict
    contact: ContactOptions = field(default_factory=ContactOptions)
    interfaces: list = field(default_factory=list)  # of specs.InterfaceSpec
    checks: dict = field(default_factory=lambda: dataclasses.asdict(ChecksSpec()))  # specs.ChecksSpec
    variant: str = ""  # "" or "quick x2" (reduced-resolution variant, part of the fingerprint)
    dimension: int = 2
    warnings: list = field(default_factory=list)  # one line each, "FILE: KEY ...": printed at the start of a run,
    #                                                in summary.json "warnings" and by `fem-blocks check`
    notes: list = field(default_factory=list)     # what was built where it may differ from the file (openings)
    allow_no_interface: list = field(default_factory=list)  # group pairs (sorted tuples) meant to have no interface
    history_times: str = "absolute"  # stage driver/force history times: "absolute" (run time) or "stage" (from the
    #                                  stage's actual start)
    generators: list = field(default_factory=list)  # WallSpec, ArchSpec, Wall3DSpec, DomeSpec: expand.py
    expanded: bool = False  # True once expand() has added the generated block types, blocks and rigid bodies
    references: list = field(default_factory=list)  # of specs.ReferenceSpec ([[reference]], SI)

    @property
    def dofs(self) -> tuple:
        return dofs_of(self.dimension)


DOFS_2D = ("x", "y", "rz")
DOFS_3D = ("x", "y", "z", "rx", "ry", "rz")


def dofs_of(D: int) -> tuple:
    """Rigid-body dofs of dimension D: x, y, rz (2D); x, y, z, rx, ry, rz (3D). A dof "r*" is a rotation."""
    return DOFS_2D if D == 2 else DOFS_3D


def _dof_text(D: int) -> str:
    return "x, y or rz" if D == 2 else "x, y, z, rx, ry or rz (dimension 3)"


def _dof_error(t, dof, D):
    other = [d for d in dofs_of(5 - D) if d not in dofs_of(D)]
    hint = f" ({', '.join(other)}: dofs of dimension {5 - D} only)" if dof in other else ""
    return t.error(dof, f"unknown dof; expected {_dof_text(D)}{hint}")


def rotation_matrix(axis, angle: float) -> np.ndarray:
    """R = exp(angle [a]x), a = axis/|axis| (right-hand rule, angle in radians): Rodrigues' formula
    R = I + sin(angle) [a]x + (1 - cos(angle)) [a]x^2."""
    return rotation3d(np.asarray(axis, dtype=float), float(angle))


def _check_simple_polygon(t, key, verts):
    """Edges of a polygon must not cross each other (a bow-tie has no inside)."""
    if verts is None:
        return
    P = np.asarray(verts, dtype=float)
    n = len(P)

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    for i in range(n):
        a, b = P[i], P[(i + 1) % n]
        for j in range(i + 1, n):
            if j == i or (j + 1) % n == i or j == (i + 1) % n:
                continue  # adjacent edges share a vertex
            c, d = P[j], P[(j + 1) % n]
            d1, d2, d3, d4 = cross(c, d, a), cross(c, d, b), cross(a, b, c), cross(a, b, d)
            if d1 * d2 < 0 and d3 * d4 < 0:
                raise t.error(key, f"edges {i} and {j} of the polygon cross each other: expected a simple polygon "
                                   "(vertices in order around the boundary)")


def _plausible(t, key, v_si, lo, hi, unit, units):
    """A value far outside what any building material has is a unit-system mix-up, not a material."""
    if not (lo <= v_si <= hi):
        raise t.error(key, f"= {t.data[key]!r} ({v_si:.3g} {unit} in SI): expected {lo:g} to {hi:g} {unit} for a "
                           f"building material; check `units` (this file: {units!r}; mm-N-MPa takes E in MPa and "
                           "rho in t/mm^3, e.g. 2.5e-9 for 2500 kg/m^3)")


# plausible ranges (SI) of what masonry models hold; outside them a value is most likely in the other unit system
PLAUSIBLE = dict(E=(1e8, 1e12, "stress", "Pa", "MPa"), rho=(100.0, 2e4, "density", "kg/m^3", "t/mm^3"),
                 length=(1e-3, 20.0, "length", "m", "mm"))


def _warn_implausible(warnings: list, t, key, v_si, what: str, units: str, label: str | None = None):
    """Append a warning (not an error) when v_si [SI] is outside the plausible range PLAUSIBLE[what] of a masonry
    model: E = 10000 meant in MPa in an SI file, or brick lengths in mm in an SI file, and the reverse."""
    lo, hi, dim, si_unit, mm_unit = PLAUSIBLE[what]
    if lo <= v_si <= hi:
        return
    f = UNIT_SYSTEMS[units][dim]
    unit = si_unit if units == "SI" else mm_unit
    shown = f" = {t.data[key]!r}" if label is None else f" ({label})"
    warnings.append(f"{t.source}: {t.key(key)}{shown}: implausible for a masonry model (expected {lo / f:g} "
                    f"to {hi / f:g} {unit} with units = {units!r}); check the units of this value "
                    f"(units = 'SI': lengths in m, E in Pa, rho in kg/m^3; 'mm-N-MPa': mm, MPa, t/mm^3)")


def _warn_extent(warnings: list, t, key, points, units: str):
    """Plausibility of a block's size from its points (polygon vertices, hexahedron corners): its smallest and
    largest extent along the axes must lie in PLAUSIBLE['length']."""
    if points is None:
        return
    P = np.asarray(points, dtype=float)
    ext = P.max(axis=0) - P.min(axis=0)
    f = UNIT_SYSTEMS[units]["length"]
    for v in (float(ext.min()), float(ext.max())):
        before = len(warnings)
        _warn_implausible(warnings, t, key, v, "length", units, label=f"block extent {v / f:g}")
        if len(warnings) > before:
            return


def fingerprint(case: Case) -> str:
    """SHA-256 of what determines a run: the case file's bytes, the mesh files it names, the CSV files of its
    histories (history_files), the variant (--quick) and the base files it extends (none: a file without `extends` keeps its digest). A resumed run compares it
    with the checkpoint's."""
    h = hashlib.sha256()
    for path in [case.source] + sorted({bt.file for bt in case.block_types.values() if bt.file}):
        h.update(os.path.abspath(path).encode() if path != case.source else b"case")
        try:
            with open(path, "rb") as f:
                h.update(f.read())
        except OSError:
            h.update(b"<unreadable>")
    for path in getattr(case.source, "files", ())[1:]:  # the base files it extends (casefile.Source)
        try:
            with open(path, "rb") as f:
                h.update(b"base" + f.read())
        except OSError:
            h.update(b"<unreadable>")
    for path in sorted(history_files(case)):  # CSV files of histories (drivers, forces, tractions)
        h.update(b"history" + os.path.abspath(path).encode())
        try:
            with open(path, "rb") as f:
                h.update(f.read())
        except OSError:
            h.update(b"<unreadable>")
    h.update(case.variant.encode())
    return h.hexdigest()


def load_case(path: str) -> Case:
    """Read and validate a TOML case file (with its bases and named laws: casefile.read); raise InputError naming
    the file and the key."""
    from .laws import LAW_KEYS
    data, source = casefile.read(path, LAW_KEYS)
    return parse_case(data, source)


def parse_case(data: dict, source: str = "<case>") -> Case:
    """Parse and validate a case (the TOML data of `source`), section by section; InputError naming the key."""
    if any(k in data for k in casefile.KEYS):  # a table as written (extends, unset, [laws]): compose it first
        from .laws import LAW_KEYS
        data, source = casefile.compose(data, source, LAW_KEYS)
    base = os.path.dirname(os.path.abspath(source)) if os.path.exists(source) else os.getcwd()
    root = Table(data, "", source, UNIT_SYSTEMS["SI"])
    if "lab" in data:
        raise root.error("lab", "a standard laboratory test: its specimens are generated cases; load the file with "
                                "fem_blocks.lab.load_lab (the command line does)")
    units = root.string("units", "SI", choices=list(UNIT_SYSTEMS))
    U = UNIT_SYSTEMS[units]
    root.units = U
    name = root.string("name", os.path.splitext(os.path.basename(source))[0])
    D = root.raw("dimension", 2)
    if isinstance(D, bool) or D not in (2, 3):
        raise root.error("dimension", f"= {D!r}: expected 2 or 3")
    root.dimension_keys(D, dict(wall=2, arch=2, wall3d=3, dome=3))
    gravity = root.vector("gravity", D)
    gravity = ((0.0, -9.81) if D == 2 else (0.0, 0.0, -9.81)) if gravity is None else \
        tuple(g * U["length"] / U["time"] ** 2 for g in gravity)

    warnings: list = []  # plausibility warnings, one line each (expand.py adds those of what was built)
    materials = _parse_materials(root, D, units, warnings)
    block_types = _parse_block_types(root, D, materials, base, units, warnings)
    names: set = set()
    blocks = _parse_blocks(root, D, block_types, names)
    rigid = _parse_rigid_bodies(root, D, U, units, names, warnings)
    generators = _parse_builders(root, U, materials, warnings, units)
    rigid_all = rigid + [r for g in generators for r in g.rigid]  # with the generated ones (names, drivers, mass)
    if not blocks and not rigid and not generators:
        raise root.error("blocks", "missing; expected at least one [[blocks]] or [[rigid_bodies]] entry")
    stages = _parse_stages(root, D)
    contact = _parse_contact(root, source)
    all_groups = {b.group for b in blocks} | {g.group for g in generators} | {r.group for r in rigid_all}
    interfaces = _parse_interfaces(root, D, all_groups, warnings, source)
    history_times = root.string("history_times", "absolute", choices=("absolute", "stage"))
    allow_pairs = _parse_allow_no_interface(root, all_groups)
    _check_interface_pairs(source, interfaces, blocks)
    checks = _parse_checks(root)
    output = _parse_output(root, D)
    ref_tables = root.tables("reference")  # parsed below, once [output.curve] is known (3D: chosen below)
    root.done()
    _check_stages(source, stages, rigid_all)
    if "curve" in output:
        cb = output["curve"]["body"]
        if cb not in {r.name for r in rigid_all}:
            raise InputError(f"{source}: output.curve.body = {cb!r}: expected a rigid body among "
                             f"{sorted(r.name for r in rigid_all)}")
    if D == 3:
        if "curve" not in output:  # 3D: the force-displacement curve of the first dof a stage drives
            for st in stages:
                drv = [(b, d) for b, dofs in st.drivers.items() for d, spec in dofs.items() if spec is not None]
                if drv:
                    output["curve"] = dict(body=drv[0][0], force=drv[0][1], displacement=drv[0][1])
                    break
    references = _parse_reference(ref_tables, output.get("curve"), U, base)
    case = Case(source=source, name=name, units=units, gravity=gravity, materials=materials,
                block_types=block_types, blocks=blocks, rigid_bodies=rigid, stages=stages, output=output,
                contact=contact, interfaces=interfaces, checks=checks, dimension=D, warnings=warnings,
                allow_no_interface=allow_pairs, history_times=history_times, generators=generators,
                references=references)
    case.warnings += stage_history_warnings(case) + reversal_warnings(case)
    return case


def _parse_materials(root: Table, D: int, units: str, warnings: list) -> dict:
    """[materials.NAME] -> specs.MaterialSpec (SI), with the unit-system plausibility checks."""
    materials = {}
    for mname, t in root.named_tables("materials").items():
        t.dimension_keys(D, dict(thickness=2, plane=2))
        ray = t.vector("rayleigh", 2, default=(0.0, 0.0), lo=0.0)
        materials[mname] = MaterialSpec(name=mname, alpha=ray[0], beta=ray[1],
                                        **read_fields(t, MaterialSpec, ("E", "nu", "rho", "thickness", "plane")))
        _plausible(t, "rho", materials[mname].rho, 1.0, 1e5, "kg/m^3", units)
        _plausible(t, "E", materials[mname].E, 1e3, 1e13, "Pa", units)
        _warn_implausible(warnings, t, "E", materials[mname].E, "E", units)
        _warn_implausible(warnings, t, "rho", materials[mname].rho, "rho", units)
        if "thickness" in t.data:
            _warn_implausible(warnings, t, "thickness", materials[mname].thickness, "length", units)
        t.done()
    return materials


def _parse_block_types(root: Table, D: int, materials: dict, base: str, units: str, warnings: list) -> dict:
    """[block_types.NAME] -> BlockTypeSpec (2D: rectangle, polygon, file; 3D: _parse_block_type_3d)."""
    block_types = {}
    for tname, t in root.named_tables("block_types").items():
        if D == 3:
            block_types[tname] = _parse_block_type_3d(t, tname, materials, base)
            _warn_extent(warnings, t, "size" if "size" in t.data else "corners", type_corners(block_types[tname]),
                         units)
            t.done()
            continue
        _check_geometry_dimension(t, D)
        t.dimension_keys(D, dict(size=3, corners=3, divisions=3))
        geom = t.string("geometry", required=True, choices=("rectangle", "polygon", "file"))
        mat = t.string("material", required=True)
        if mat not in materials:
            raise t.error("material", f"= {mat!r}: expected one of the [materials] {sorted(materials)}")
        bt = BlockTypeSpec(name=tname, geometry=geom, material=mat,
                           mesh_size=t.number("mesh_size", None if geom == "file" else _REQUIRED,
                                              lo=0, lo_open=True, dim="length"),
                           cell=t.string("cell", "quad" if geom == "rectangle" else "triangle",
                                         choices=("quad", "triangle")),
                           mass=t.string("mass", "lumped", choices=("lumped", "consistent")))
        if geom == "rectangle":
            bt.lx = t.number("lx", lo=0, lo_open=True, dim="length", required=True)
            bt.ly = t.number("ly", lo=0, lo_open=True, dim="length", required=True)
            for k in ("lx", "ly"):
                _warn_implausible(warnings, t, k, getattr(bt, k), "length", units)
        elif geom == "polygon":
            bt.vertices = t.points("vertices")
            _warn_extent(warnings, t, "vertices", bt.vertices, units)
        else:
            bt.file = _mesh_file(t, base)
        t.done()
        block_types[tname] = bt
    return block_types


def _parse_blocks(root: Table, D: int, block_types: dict, names: set) -> list:
    """[[blocks]] -> BlockSpec with their clamps and tractions; body names go into `names`."""
    blocks = []
    for i, t in enumerate(root.tables("blocks")):
        ty = t.string("type", required=True)
        if ty not in block_types:
            raise t.error("type", f"= {ty!r}: expected one of the [block_types] {sorted(block_types)}")
        bname = t.string("name", f"block{i}")
        if bname in names:
            raise t.error("name", f"= {bname!r}: duplicate body name")
        names.add(bname)
        t.dimension_keys(D, dict(angle=2, rotation_axis=3, rotation_angle=3))
        b = BlockSpec(name=bname, type=ty, position=t.vector("position", D, (0.0,) * D, dim="length"),
                      angle=0.0 if D == 3 else math.radians(t.number("angle", 0.0)),
                      group=t.string("group", "blocks"))
        if D == 3:
            b.R = _rotation(t)
        for c in t.tables("clamps"):
            box = c.vector("box", 2 * D, dim="length")
            tag = c.string("tag")
            names_box = "[xmin, xmax, ymin, ymax]" if D == 2 else "[xmin, xmax, ymin, ymax, zmin, zmax]"
            if (box is None) == (tag is None):
                raise c.error("box", f"give exactly one of box = {names_box} or tag")
            if box is not None and any(box[2 * k + 1] < box[2 * k] for k in range(D)):
                raise c.error("box", f"= {list(box)}: expected {names_box} with xmin <= xmax, ymin <= ymax"
                                     + ("" if D == 2 else ", zmin <= zmax"))
            comps = ("x", "y", "xy") if D == 2 else ("x", "y", "z", "xy", "xz", "yz", "xyz")
            b.clamps.append(ClampSpec(box, tag, c.string("components", comps[-1], choices=comps)))
            c.done()
        for c in t.tables("tractions"):
            b.tractions.append(TractionSpec(tag=c.string("tag", required=True),
                                            value=c.vector("value", D, dim="stress", required=True),
                                            history=c.history("history", None, default=1.0)))
            c.done()
        b.initial_velocity, b.initial_spin = _initial_motion(t, D)
        if b.clamps and (b.initial_velocity is not None or b.initial_spin is not None):
            k = "initial_velocity" if b.initial_velocity is not None else "initial_spin"
            raise t.error(k, "a clamped block cannot start moving: expected no non-zero initial velocity or spin on "
                             "a block with [[blocks.clamps]]")
        t.done()
        blocks.append(b)
    return blocks


def _parse_rigid_bodies(root: Table, D: int, U: dict, units: str, names: set, warnings: list) -> list:
    """[[rigid_bodies]] -> RigidSpec (2D polygon or 3D box/corners, mass, drivers, forces)."""
    rigid = []
    for i, t in enumerate(root.tables("rigid_bodies")):
        rname = t.string("name", f"rigid{i}")
        if rname in names:
            raise t.error("name", f"= {rname!r}: duplicate body name")
        names.add(rname)
        t.dimension_keys(D, dict(vertices=2, thickness=2, size=3, origin=3, corners=3))
        if D == 2:
            verts = t.points("vertices")
            _check_simple_polygon(t, "vertices", verts)
        else:
            verts = _solid_corners(t)
        r = _parse_rigid(t, U, rname, verts, D)
        if r.rho is not None:
            _warn_implausible(warnings, t, "rho", r.rho, "rho", units)
        r.initial_velocity, r.initial_spin = _initial_motion(t, D)
        driven = set(r.drivers) | (set(dofs_of(D)[:D]) if _has_pivot(r.drivers) else set())
        for key, vals, dofs in (("initial_velocity", r.initial_velocity, dofs_of(D)[:D]),
                                ("initial_spin", r.initial_spin, dofs_of(D)[D:])):
            if vals is not None:
                bad = [d for d, v in zip(dofs, np.atleast_1d(vals)) if v != 0.0 and d in driven]
                if bad:
                    raise t.error(key, f"dof {bad[0]!r} is driven: expected a zero initial velocity on driven dofs "
                                       "(the driver sets it)")
        r.group = t.string("group", "rigid")
        rigid.append(r)
        t.done()
    return rigid


def _parse_builders(root: Table, U: dict, materials, warnings, units) -> list:
    """[wall], [arch], [wall3d], [dome] -> their specs as given (WallSpec...); expand.py makes their block types,
    blocks and rigid bodies."""
    generators = []
    for key, parse in (("wall", _parse_wall), ("arch", _parse_arch), ("wall3d", _parse_wall3d), ("dome", _parse_dome)):
        tb = root.table(key)
        if tb is not None:
            generators.append(parse(tb, U, materials, warnings, units))
            tb.done()
    return generators


def _parse_stages(root: Table, D: int) -> list:
    """[[stages]] -> StageSpec (fields from specs.StageSpec; drivers, forces and stop criteria)."""
    stages = []
    stage_names = set()
    for i, t in enumerate(root.tables("stages", min_count=1)):
        sname = t.string("name", f"stage{i}")
        if sname in stage_names:
            raise t.error("name", f"= {sname!r}: duplicate stage name")
        stage_names.add(sname)
        f = read_fields(t, StageSpec, ("h", "duration"))
        h, dur = f["h"], f["duration"]
        if dur < h * (1 - 1e-12):
            raise t.error("duration", f"= {dur:g} s: expected at least one time step h = {h:g} s")
        if dur / h > 1e8:
            raise t.error("duration", f"= {dur:g} s: expected at most 1e8 steps of h = {h:g} s")
        f.update(read_fields(t, StageSpec, ("static",)))
        f.update(read_fields(t, StageSpec, ("theta", "velocity_reset", "output_every"),
                             defaults=dict(theta=1.0 if f["static"] else 0.5)))
        st = StageSpec(name=sname, **f)
        if st.static and st.theta != 1.0:
            raise t.error("theta", f"= {st.theta:g}: expected 1 (or no theta) in a stage with static = true: the "
                                   "static step is the backward-Euler step without inertia")
        st.drivers = _stage_drivers(t, D)
        st.forces = _stage_forces(t, D, st.drivers)
        for k, v in read_fields(t, StageSpec, ("tol", "on_nonconvergence", "max_sweeps")).items():
            setattr(st, k, v)
        _stage_stops(t, D, st)
        stages.append(st)
        t.done()
    return stages


def _stage_drivers(t: Table, D: int) -> dict:
    """[stages.drivers.BODY] DOF = {kind, history} | "free" -> body -> dof -> (kind, history) | None."""
    drivers = {}
    dtab = t.table("drivers")
    if dtab is not None:
        for body in list(dtab.data):
            bt_ = dtab.table(body)
            drivers[body] = {}
            for dof in list(bt_.data):
                if dof not in dofs_of(D):
                    raise _dof_error(bt_, dof, D)
                if bt_.data[dof] == "free":
                    bt_.used.add(dof)
                    drivers[body][dof] = None
                    continue
                drivers[body][dof] = _read_driver(bt_.table(dof), dof, D)
            if _has_pivot(drivers[body]):
                _check_pivot(bt_, drivers[body], {}, D)
            bt_.done()
        dtab.done()
    return drivers


def _initial_motion(t: Table, D: int):
    """`initial_velocity` = [vx, vy(, vz)] [m/s] and `initial_spin` = ω [rad/s] (2D a number, 3D [ωx, ωy, ωz]) of a
    block or rigid body -> (velocity tuple | None, spin | None); all-zero values read as None (at rest)."""
    v = t.vector("initial_velocity", D, dim="length")
    if D == 2:
        w = t.number("initial_spin")
        w = None if not w else w
    else:
        w = t.vector("initial_spin", 3)
        w = None if w is None or not any(w) else w
    return (None if v is None or not any(v) else v), w


def _has_pivot(drivers: dict) -> bool:
    return any(getattr(d, "pivot", None) is not None for d in drivers.values())


def _read_driver(d: Table, dof: str, D: int) -> DriverSpec:
    """One driver table {kind, history[, baseline][, pivot]} of dof `dof` -> DriverSpec (docs/case-files.md:
    acceleration records and their baseline correction, rotation about a pivot)."""
    from .records import baseline_linear
    rot = dof[0] == "r"
    kind = d.string("kind", required=True, choices=DRIVER_KINDS)
    if kind == "acceleration" and rot:
        raise d.error("kind", f"= 'acceleration' on the rotation dof {dof!r}: expected a translation dof "
                              f"({', '.join(dofs_of(D)[:D])}); an acceleration record drives a translation")
    quantity = {"displacement": "angle" if rot else "length", "velocity": "angular velocity" if rot else "velocity",
                "acceleration": "acceleration"}[kind]
    hist = d.history("history", None if rot else "length", required=True, protocol=kind == "displacement",
                     quantity=quantity)
    baseline = d.string("baseline", None, choices=("none", "linear"))
    if baseline is not None and kind != "acceleration":
        raise d.error("baseline", f"= {baseline!r}: a baseline correction applies to an acceleration record; expected "
                                  f"it only with kind = \"acceleration\"")
    if baseline == "linear":
        if not isinstance(hist, dict) or len(hist["times"]) < 2:
            raise d.error("baseline", "= 'linear': expected a record of at least 2 samples (a {times, values} or "
                                      "CSV history), not a single value")
        vals, _, _ = baseline_linear(hist["times"], hist["values"])
        hist = dict(hist, values=[float(x) for x in vals])
    pivot = None
    if d.has("pivot"):
        if not rot:
            raise d.error("pivot", f"given on the translation dof {dof!r}: expected a pivot on a rotation dof "
                                   f"({', '.join(dofs_of(D)[D:])})")
        pivot = d.vector("pivot", D, dim="length")
    d.done()
    return DriverSpec(kind, hist, pivot)


def _check_pivot(t: Table, drivers: dict, forces: dict, D: int, where: str = ""):
    """A driver table with a pivot: no own driver or force on the translation dofs; 3D: every rotation dof driven,
    one pivot point."""
    piv = [(dof, s.pivot) for dof, s in drivers.items() if getattr(s, "pivot", None) is not None]
    if not piv:
        return
    dof0, p0 = piv[0]
    for dof in dofs_of(D)[:D]:
        if dof in drivers or dof in forces:
            what = "driver" if dof in drivers else "force"
            raise t.error(f"{dof0}.pivot", f"given together with a {what} on {dof!r}{where}: a pivot drives the "
                                           f"translation dofs {', '.join(dofs_of(D)[:D])}; expected no driver or "
                                           f"force on them")
    for dof, p in piv[1:]:
        if tuple(p) != tuple(p0):
            raise t.error(f"{dof}.pivot", f"= {list(p)}: expected the same pivot as {dof0} ({list(p0)})")
    free = [r for r in dofs_of(D)[D:] if r not in drivers or drivers[r] is None]
    if free:
        raise t.error(f"{dof0}.pivot", f"expected every rotation dof driven with a pivot (not driven here: "
                                       f"{', '.join(free)})")


def _stage_forces(t: Table, D: int, drivers: dict) -> dict:
    """[stages.forces.BODY] DOF = history -> body -> dof -> history (not on a dof the stage drives)."""
    forces = {}
    ftab = t.table("forces")
    if ftab is not None:
        for body in list(ftab.data):
            bt_ = ftab.table(body)
            forces[body] = {}
            for dof in list(bt_.data):
                if dof not in dofs_of(D):
                    raise _dof_error(bt_, dof, D)
                if dof in drivers.get(body, {}) and drivers[body][dof] is not None:
                    raise bt_.error(dof, "this dof is driven in this stage; a driven dof cannot also carry a force")
                if dof in dofs_of(D)[:D] and _has_pivot(drivers.get(body, {})):
                    raise bt_.error(dof, "this stage drives the body about a pivot, which drives its translation "
                                         "dofs; expected no force on them")
                forces[body][dof] = bt_.history(dof, "force" if dof[0] != "r" else "moment",
                                                quantity="force" if dof[0] != "r" else "moment")
            bt_.done()
        ftab.done()
    return forces


def _stage_stops(t: Table, D: int, st: StageSpec):
    """[stages.stop_at_displacement], [stages.stop_at_rotation], [stages.stop_after_peak],
    [stages.stop_at_equilibrium]."""
    sd = t.table("stop_at_displacement")
    if sd is not None:
        body = sd.string("body", required=True)
        dof = sd.string("dof", required=True, choices=dofs_of(D))
        st.stop_displacement = (body, dof, abs(sd.number("value", required=True, dim=None if dof[0] == "r"
                                                         else "length")))
        sd.done()
    sr = t.table("stop_at_rotation")
    if sr is not None:
        st.stop_rotation = (sr.string("body", required=True), sr.string("relative_to"),
                            sr.number("value", required=True, lo=0.0, lo_open=True))
        sr.done()
    sp = t.table("stop_after_peak")
    if sp is not None:
        st.stop_after_peak = (sp.string("body", required=True), sp.string("dof", required=True,
                                                                          choices=dofs_of(D)),
                              sp.number("drop", 0.2, lo=0, hi=1, lo_open=True, hi_open=True),
                              sp.integer("min_steps", 20, lo=1))
        sp.done()
    eq = t.table("stop_at_equilibrium")
    if eq is not None:
        st.stop_at_equilibrium = True
        st.equilibrium_velocity = eq.number("max_velocity", default_of(StageSpec, "equilibrium_velocity"), lo=0,
                                            lo_open=True, dim="length")
        st.min_steps = eq.integer("min_steps", default_of(StageSpec, "min_steps"), lo=1)
        eq.done()


CONTACT_KEYS = tuple(f.name for f in schema_fields(ContactOptions))


def _parse_contact(root: Table, source: str) -> ContactOptions:
    """[contact] -> specs.ContactOptions (its defaults when the table is absent); the options' cross-field rules
    (e.g. fallback = 'newton' needs nlgs + residual) checked here, before any meshing."""
    ct = root.table("contact")
    if ct is None:
        return ContactOptions()
    f = read_fields(ct, ContactOptions, CONTACT_KEYS)
    try:
        opts = ContactOptions(**f)
    except InputError as e:
        raise InputError(f"{source}: {e}") from None
    ct.done()
    return opts


def _law_params(t: Table) -> dict:
    """The interface-law parameters of an [[interfaces]] entry (specs.LAW_PARAMS, without mu), in SI."""
    params = {}
    for key, p in LAW_PARAMS.items():
        if key == "mu" or key not in t.data:
            continue
        if p.choices is not None:
            params[key] = t.string(key)
        else:
            params[key] = t.number(key, dim=p.unit if p.unit in t.units else None)
            if p.unit in DERIVED:
                params[key] *= DERIVED[p.unit](t.units)
    return params


def _parse_interfaces(root: Table, D: int, all_groups: set, warnings: list, source: str) -> list:
    """[[interfaces]] -> specs.InterfaceSpec (the engine's class; validated once, law parameters included)."""
    interfaces = []
    seen_if = set()
    for i, t in enumerate(root.tables("interfaces")):
        iname = t.string("name", f"interface{i}")
        if iname in seen_if:
            raise t.error("name", f"= {iname!r}: duplicate interface name")
        seen_if.add(iname)
        between = t.raw("between")
        if between is None:
            raise t.missing("between", "two body group names, e.g. [\"bricks\", \"bricks\"]")
        if (not isinstance(between, list) or len(between) != 2 or not all(isinstance(g, str) for g in between)):
            raise t.error("between", "expected two body group names, e.g. [\"bricks\", \"bricks\"]")
        for g in between:
            if g not in all_groups:
                raise t.error("between", f"group {g!r} has no body; expected groups among {sorted(all_groups)}")
        cand = t.string("candidate")
        if cand is not None and cand not in between:
            raise t.error("candidate", f"= {cand!r}: expected one of {between}")
        pos = t.raw("positions", [0.25, 0.75])
        if (not isinstance(pos, list) or not pos or
                not all(isinstance(x, NUMBER) and not isinstance(x, bool) and 0 < x < 1 for x in pos)):
            raise t.error("positions", f"= {pos!r}: expected a list of relative positions strictly between 0 and 1")
        placement = read_fields(t, InterfaceSpec, ("placement",))["placement"]
        if placement == "overlap" and D == 3:
            raise t.error("placement", "= 'overlap': expected 'positions' or 'nodes' in 3D")
        used = placement or ("overlap" if D == 2 else "positions")
        if t.has("positions") and used != "positions":
            warnings.append(f"{t.source}: {t.key('positions')} = {pos!r} is not used: the candidate points are placed "
                            f"by placement = {used!r}" + (" (the 2D default)" if placement is None else "")
                            + "; set placement = \"positions\" to use them")
        law = read_fields(t, InterfaceSpec, ("law",))["law"]
        params = _law_params(t)
        mu = t.number("mu", 0.0 if law == "mixed" else None, lo=0, required=law != "mixed")
        f = read_fields(t, InterfaceSpec, ("g0", "alert", "orientation", "reference", "max_angle"))
        try:
            interfaces.append(InterfaceSpec(name=iname, groups=tuple(between), law=law, mu=mu, params=params,
                                            placement=placement, positions=tuple(float(x) for x in pos),
                                            candidate=cand, where=t.path, **f))
        except InputError as e:
            raise InputError(f"{casefile.origin_of_message(source, e)}: {e}") from None
        t.done()
    return interfaces


def _parse_allow_no_interface(root: Table, all_groups: set) -> list:
    """allow_no_interface = [[group, group], ...] -> sorted group pairs."""
    allow_pairs = []
    allow = root.raw("allow_no_interface")
    if allow is not None:
        if not (isinstance(allow, list) and all(isinstance(p, list) and len(p) == 2 and all(isinstance(g, str)
                                                                                        for g in p) for p in allow)):
            raise root.error("allow_no_interface", f"= {allow!r}: expected a list of group pairs, e.g. "
                                                   "[[\"bricks\", \"beam\"]]")
        for p in allow:
            for g in p:
                if g not in all_groups:
                    raise root.error("allow_no_interface", f"group {g!r} has no body; expected groups among "
                                                           f"{sorted(all_groups)}")
            allow_pairs.append(tuple(sorted(p)))
    return allow_pairs


def _check_interface_pairs(source: str, interfaces: list, blocks: list):
    """One interface per group pair (orientation 'any'), or 'bed' + 'head'; a 'crack' interface joins them."""
    pairs = {}
    for itf in interfaces:
        pairs.setdefault(tuple(sorted(itf.groups)), []).append(itf)
    for key, lst in pairs.items():
        orients = sorted(x.orientation for x in lst if x.orientation != "crack")
        n_crack = sum(x.orientation == "crack" for x in lst)
        if n_crack > 1 or (n_crack and not orients):
            raise InputError(f"{source}: interfaces {[x.name for x in lst]}: a 'crack' interface (between the halves "
                             f"of split bricks) needs the joint interface(s) of the same group pair, and one "
                             f"crack interface per pair")
        if not (orients == ["any"] or orients == ["bed", "head"]):
            raise InputError(f"{source}: interfaces {[x.name for x in lst]}: the group pair {list(key)} takes one "
                             f"interface (orientation 'any') or two ('bed' and 'head'), got {orients}")


def _parse_checks(root: Table) -> dict:
    """[checks] -> dict of specs.ChecksSpec: max_penetration, max_energy_growth, accept_unconverged."""
    ck = root.table("checks")
    if ck is None:
        return dataclasses.asdict(ChecksSpec())
    checks = read_fields(ck, ChecksSpec, ("max_penetration", "max_energy_growth", "accept_unconverged"))
    ck.done()
    return checks


def _parse_output(root: Table, D: int) -> dict:
    """[output] -> dict of specs.OutputSpec: paraview, stress, checkpoint_every, crack_pattern, [output.curve]."""
    out = root.table("output")
    output = dataclasses.asdict(OutputSpec())
    del output["curve"]  # present only when given (or chosen in 3D)
    if out is not None:
        output.update(read_fields(out, OutputSpec, ("paraview", "stress", "checkpoint_every")))
        cv = out.table("curve")
        if cv is not None:
            output["curve"] = dict(body=cv.string("body", required=True),
                                   force=cv.string("force", "x", choices=dofs_of(D)),
                                   displacement=cv.string("displacement", "x", choices=dofs_of(D)))
            cv.done()
        output.update(read_fields(out, OutputSpec, ("crack_pattern",)))
        rot = out.raw("rotations", [])  # names matched to the built bodies by the runner (runner.rotation_bodies)
        if not (isinstance(rot, list) and all(isinstance(x, str) and x for x in rot)):
            raise out.error("rotations", f"= {rot!r}: expected a list of block or group names, e.g. [\"bricks\"]")
        output["rotations"] = list(dict.fromkeys(rot))
        jts = out.raw("joints", [])  # names matched to the built bodies by the runner (runner.joint_pairs)
        if not (isinstance(jts, list) and all(isinstance(p, list) and len(p) == 2 and p[0] != p[1]
                                              and all(isinstance(x, str) and x for x in p) for p in jts)):
            raise out.error("joints", f"= {jts!r}: expected a list of pairs of two different body names, e.g. "
                                      "[[\"voussoir6\", \"voussoir7\"]]")
        output["joints"] = [list(p) for p in jts]
        output.update(read_fields(out, OutputSpec, ("joints_paraview", "line_of_thrust")))
        gauges, seen = [], set()  # block names matched to the built bodies by the runner (runner.gauge_points)
        for g in out.tables("gauges"):
            nm = g.string("name", required=True)
            if nm in seen:
                raise g.error("name", f"= {nm!r}: duplicate gauge name")
            seen.add(nm)
            gauges.append(dict(name=nm, block=g.string("block", required=True),
                               point=g.vector("point", D, dim="length", required=True), key=g.path))
            g.done()
        output["gauges"] = gauges
        out.done()
    return output


def _parse_reference(tables: list, curve: dict | None, U: dict, base: str) -> list:
    """[[reference]] -> specs.ReferenceSpec (SI): each a curve (`points` inline or a CSV `file`; optional `band` or
    `lower`/`upper`) or a peak (`peak` and/or `peak_band`, optional `band` with `peak`, `displacement_at_peak`), in
    the quantities of [output.curve] (`curve`): displacement [length; rad for a rotation dof] and force [force;
    moment for a rotation dof], converted with the file's units `U`. `base`: the folder of relative file paths."""
    if not tables:
        return []
    if curve is None:
        t = tables[0]
        raise InputError(f"{casefile.origin(t.source, t.path)}: {t.path}: expected an [output.curve] (body, force, "
                         "displacement): a reference is drawn on that curve and compared with its peak")
    fd = 1.0 if curve["displacement"].startswith("r") else U["length"]
    ff = U["moment"] if curve["force"].startswith("r") else U["force"]
    out = []
    for t in tables:
        if not t.has("label"):
            raise t.missing("label", "expected a text saying where the data come from and how accurate they are")
        label = t.string("label")
        if not label.strip():
            raise t.error("label", f"= {label!r}: expected a non-empty text saying where the data come from and "
                                   "how accurate they are")
        is_curve = t.has("points") or t.has("file")
        is_peak = t.has("peak") or t.has("peak_band")
        if t.has("points") and t.has("file"):
            raise t.error("file", "expected either points (inline) or file (CSV), not both")
        if is_curve and is_peak:
            k = "peak" if t.has("peak") else "peak_band"
            raise t.error(k, "expected either a curve (points or file) or a peak (peak, peak_band), not both")
        if not is_curve and not is_peak:
            raise t.missing("points", "expected a curve (points = [[d, F], ...] or file = \"x.csv\") or a peak "
                                      "(peak = F and/or peak_band = [Fmin, Fmax])")
        v = read_fields(t, ReferenceSpec, ("band", "peak", "displacement_at_peak"))
        r = ReferenceSpec(label=label, band=v["band"], key=t.path)
        if is_curve:
            if t.has("displacement_at_peak"):
                raise t.error("displacement_at_peak", "expected only in a peak-only reference (a curve's peak is "
                                                      "read from the curve)")
            if t.has("columns") and not t.has("file"):
                raise t.error("columns", "expected only with file (the columns of a CSV file)")
            if t.has("file"):
                r.file, r.points = _read_reference_csv(t, base, fd, ff)
                r.columns = t.raw("columns")
            else:
                r.points = _reference_points(t, "points", fd, ff)
            if t.has("lower") or t.has("upper"):
                if not (t.has("lower") and t.has("upper")):
                    k = "upper" if t.has("lower") else "lower"
                    raise t.missing(k, "expected lower and upper together (the two curves of a band)")
                if r.band is not None:
                    raise t.error("band", "expected either band (relative) or lower/upper curves, not both")
                r.lower = _reference_points(t, "lower", fd, ff)
                r.upper = _reference_points(t, "upper", fd, ff)
        else:
            for k in ("columns", "lower", "upper"):
                if t.has(k):
                    raise t.error(k, "expected only with a curve (points or file)")
            r.peak = None if v["peak"] is None else v["peak"] * ff
            r.displacement_at_peak = None if v["displacement_at_peak"] is None else v["displacement_at_peak"] * fd
            if t.has("peak_band"):
                pb = t.raw("peak_band")
                if not isinstance(pb, list) or len(pb) != 2 or not all(_finite(x) for x in pb):
                    raise t.error("peak_band", f"expected [Fmin, Fmax], two finite numbers, got {pb!r}")
                if not 0 <= pb[0] < pb[1]:
                    raise t.error("peak_band", f"= {pb!r}: expected [Fmin, Fmax] with 0 <= Fmin < Fmax")
                if r.band is not None:
                    raise t.error("band", "expected either band (relative) or peak_band, not both")
                r.peak_band = (float(pb[0]) * ff, float(pb[1]) * ff)
            if r.band is not None and r.peak is None:
                raise t.missing("peak", "expected with band (a relative band around peak)")
        t.done()
        out.append(r)
    return out


def _monotone(t: Table, k: str, d: list, where: str = ""):
    """InputError naming `k` unless the displacements d are strictly monotone (increasing or decreasing)."""
    s = [(b > a) - (b < a) for a, b in zip(d, d[1:])]
    bad = next((i for i, x in enumerate(s) if x == 0 or x != s[0]), None)
    if bad is not None:
        raise t.error(k, f"displacements not strictly monotone{where} ({d[bad]:g} then {d[bad + 1]:g}): expected a "
                         "curve along strictly increasing (or decreasing) displacements")


def _reference_points(t: Table, k: str, fd: float, ff: float) -> list:
    """An inline curve [[d, F], ...] of `t` (>= 2 points, finite, d strictly monotone) -> [(d, F)] in SI."""
    v = t.raw(k)
    if not isinstance(v, list) or not all(isinstance(p, list) and len(p) == 2 and all(_finite(x) for x in p)
                                          for p in v):
        raise t.error(k, "expected a list of [displacement, force] pairs of finite numbers")
    if len(v) < 2:
        raise t.error(k, f"expected at least 2 [displacement, force] points, got {len(v)}")
    _monotone(t, k, [p[0] for p in v])
    return [(float(d) * fd, float(F) * ff) for d, F in v]


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _csv_rows(t: Table, f: str, base: str):
    """The CSV file `f` of key `file` of table t (relative to `base`, the case file's folder) -> (its path, [(line
    number, cells)], header cells or None). Cells separated by commas (else semicolons, else blanks), stripped of
    blanks and double quotes; blank lines and lines starting with '#' skipped; a first row holding a non-number is
    the header. Missing or unreadable file: InputError naming the key."""
    full = f if os.path.isabs(f) else os.path.join(base, f)
    if not os.path.isfile(full):
        raise t.error("file", f"= {f!r}: file not found (expected a CSV file, relative to the case file)")
    try:
        with open(full, encoding="utf-8") as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError) as e:
        raise t.error("file", f"= {f!r}: unreadable ({type(e).__name__}): expected a text CSV file") from None
    rows = []
    for n, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if s and not s.startswith("#"):
            sep = "," if "," in s else (";" if ";" in s else None)
            rows.append((n, [c.strip().strip('"').strip() for c in s.split(sep)]))
    header = rows.pop(0)[1] if rows and not all(_is_number(c) for c in rows[0][1]) else None
    return full, rows, header


def _read_reference_csv(t: Table, base: str, fd: float, ff: float):
    """The CSV file of a [[reference]] curve -> (its path, [(d, F)] in SI). Cells separated by commas (else
    semicolons, else blanks); blank lines and lines starting with '#' skipped; a first row holding a non-number
    is the header; `columns` = [displacement, force] header names (default: the first two columns)."""
    f = t.string("file")
    full, rows, header = _csv_rows(t, f, base)
    cols = t.raw("columns")
    if cols is not None:
        if not (isinstance(cols, list) and len(cols) == 2 and all(isinstance(c, str) and c for c in cols)):
            raise t.error("columns", f"expected two column names [displacement, force], got {cols!r}")
        if header is None:
            raise t.error("columns", f"= {cols!r}: {f!r} has no header line naming its columns")
        absent = [c for c in cols if c not in header]
        if absent:
            raise t.error("columns", f"= {cols!r}: no column {absent[0]!r} in {f!r} (its columns: {header})")
        idx = [header.index(c) for c in cols]
    else:
        idx = [0, 1]
    pts = []
    for n, cells in rows:
        if len(cells) <= max(idx):
            raise t.error("file", f"= {f!r}, line {n}: expected at least {max(idx) + 1} columns, got {len(cells)}")
        a, b = cells[idx[0]], cells[idx[1]]
        if not (_is_number(a) and _is_number(b) and math.isfinite(float(a)) and math.isfinite(float(b))):
            raise t.error("file", f"= {f!r}, line {n}: expected finite numbers (displacement, force), got {a!r}, {b!r}")
        pts.append((float(a), float(b)))
    if len(pts) < 2:
        raise t.error("file", f"= {f!r}: expected at least 2 data rows (displacement, force), got {len(pts)}")
    _monotone(t, "file", [p[0] for p in pts], f" in {f!r}")
    return full, [(d * fd, F * ff) for d, F in pts]


def _check_stages(source: str, stages: list, rigid: list):
    """Stage drivers/forces name rigid bodies with a mass where they free or load a dof; stop criteria name rigid
    bodies; stop_after_peak reads a dof that is driven during its stage (specs.controls_at)."""
    rigid_names = {r.name: r for r in rigid}
    for i, st in enumerate(stages):
        for key in ("drivers", "forces"):
            for body, dofs in getattr(st, key).items():
                if body not in rigid_names:
                    raise InputError(f"{source}: stages[{i}].{key}.{body}: expected a rigid body among "
                                     f"{sorted(rigid_names)}")
                r = rigid_names[body]
                for dof, spec in dofs.items():
                    frees = key == "forces" or spec is None
                    if frees and r.rho is None and r.mass is None:
                        raise InputError(f"{source}: stages[{i}].{key}.{body}.{dof}: body {body!r} has no mass "
                                         f"(no rho or mass), so its dof {dof!r} cannot be freed or loaded")
        cur = controls_at(rigid, stages, i)  # a pivot set earlier drives the translations: no driver/force on them
        for (body, dof), c in cur.items():
            if c.pivot is not None:
                for tr in ("x", "y", "z")[:len(c.pivot)]:
                    ct = cur.get((body, tr))
                    if ct is None or ct.kind != "pivot":
                        raise InputError(f"{source}: {ct.label if ct else f'stages[{i}]'}: the dof {tr!r} of {body!r} "
                                         f"is driven by the pivot of {c.label}; expected no driver or force on it "
                                         f"while that pivot applies (free {dof!r} or drive it without a pivot first)")
        for key, ref in (("stop_at_displacement", st.stop_displacement), ("stop_after_peak", st.stop_after_peak)):
            if ref is not None and ref[0] not in rigid_names:
                raise InputError(f"{source}: stages[{i}].{key}.body = {ref[0]!r}: expected a rigid body among "
                                 f"{sorted(rigid_names)}")
        if st.stop_after_peak is not None:
            c = controls_at(rigid, stages, i).get(st.stop_after_peak[:2])
            if c is None or not c.driven:
                raise InputError(f"{source}: stages[{i}].stop_after_peak.dof = {st.stop_after_peak[1]!r}: expected "
                                 f"a driven dof of {st.stop_after_peak[0]!r} (its reaction is the force)")


# ----------------------------------------------------------------------------- stage times and histories
def nominal_stage_times(case: Case) -> list:
    """(t_start, t_end) [s] of each stage when every stage runs its full duration (a stage that stops early at
    equilibrium, a target displacement or after the peak makes the later stages start earlier)."""
    out, t = [], 0.0
    for st in case.stages:
        out.append((t, t + st.duration))
        t += st.duration
    return out


def rigid_specs(case: Case) -> list:
    """The rigid bodies of a case: its [[rigid_bodies]], then those its generators make (before expand.py: without
    vertices; after it, in case.rigid_bodies)."""
    return list(case.rigid_bodies) + [r for g in case.generators for r in g.rigid]


def active_histories(case: Case, si: int) -> dict:
    """Driver and force histories in force during stage `si` (specs.controls_at: stages accumulate in order, as the
    runner applies them): (body, dof) -> (label, kind, history, stage) with kind "displacement", "velocity" or
    "force", stage the index of the stage that set it (-1: the body's own [rigid_bodies] drivers/forces, times from
    the run start)."""
    return {key: (c.label, c.kind, c.history, c.stage)
            for key, c in controls_at(rigid_specs(case), case.stages, si).items()}


def ended_histories(case: Case, si: int) -> list:
    """The histories in force in stage `si` that stop applying when it ends (replaced or freed by the next stage,
    or the run ends): [(label, kind, history, stage, dof)], only those given as {times, values}."""
    act = active_histories(case, si)
    nxt = active_histories(case, si + 1) if si + 1 < len(case.stages) else {}
    return [(lab, kind, h, s, key[1]) for key, (lab, kind, h, s) in act.items()
            if isinstance(h, dict) and (key not in nxt or nxt[key][0] != lab)]


def history_value(hist, t: float) -> float:
    """A {times, values} history at time t (piecewise linear, constant outside), as bodies.History."""
    return float(np.interp(t, hist["times"], hist["values"]))


def _unit_of(kind: str, dof: str) -> str:
    rot = dof.startswith("r")
    return {"displacement": "rad" if rot else "m", "velocity": "rad/s" if rot else "m/s",
            "acceleration": "m/s^2", "force": "N m" if rot else "N", "pivot": "m/s"}[kind]


def stage_history_warnings(case: Case) -> list:
    """Histories that a stage cuts short even when every stage runs its full duration: their last time lies past
    the (nominal) end of the stage after which they no longer apply."""
    out = []
    times = nominal_stage_times(case)
    for si, st in enumerate(case.stages):
        t1 = times[si][1]
        for lab, kind, h, s, dof in ended_histories(case, si):
            off = times[s][0] if (case.history_times == "stage" and s >= 0) else 0.0
            end = h["times"][-1] + off
            if end > t1 + 1e-9 * max(1.0, end):
                u = _unit_of(kind, dof)
                out.append(f"{case.source}: {lab}: the history runs to t = {end:.6g} s but stops applying when stage "
                           f"{st.name!r} ends at t = {t1:.6g} s (the sum of the stage durations): "
                           f"{history_value(h, t1 - off):.4g} of {h['values'][-1]:.4g} {u} applied; lengthen the "
                           f"stage or shorten the history (history_times = {case.history_times!r})")
    return out


def reversal_warnings(case: Case) -> list:
    """Displacement histories set by a stage whose reversals (interior knots where the history changes direction:
    every knot of a cyclic protocol but the first and last) fall between the steps of that stage (nominal times;
    the driven value then turns before the knot's value, a silently smaller amplitude), and stop_after_peak on a
    dof whose driver reverses (it would end the stage at the first unloading)."""
    out = []
    times = nominal_stage_times(case)
    for si, st in enumerate(case.stages):
        t0, t1 = times[si]
        off = t0 if case.history_times == "stage" else 0.0
        for body, dofs in st.drivers.items():
            for dof, d in dofs.items():
                if d is None or d[0] != "displacement" or not isinstance(d[1], dict):
                    continue
                T, V = np.asarray(d[1]["times"]) + off, np.asarray(d[1]["values"])
                lab = f"stages[{si}].drivers.{body}.{dof}"
                rev = [j for j in range(1, len(V) - 1) if (V[j] - V[j - 1]) * (V[j + 1] - V[j]) < 0]
                if rev and st.stop_after_peak is not None and tuple(st.stop_after_peak[:2]) == (body, dof):
                    out.append(f"{case.source}: stages[{si}].stop_after_peak: the driver of {body}.{dof} reverses "
                               f"(at t = {T[rev[0]]:.6g} s): the stage stops at the first unloading once the force "
                               f"falls below (1 - drop) x its peak; remove stop_after_peak for a cyclic test")
                for j in rev:
                    x = (T[j] - t0) / st.h
                    if not (t0 - 1e-9 <= T[j] <= t1 + 1e-9) or abs(x - round(x)) <= 1e-6:
                        continue
                    ts = t0 + st.h * np.array([math.floor(x), math.ceil(x)])
                    reached = np.interp(ts - off, d[1]["times"], V)
                    got = reached.max() if V[j] > V[j - 1] else reached.min()
                    out.append(f"{case.source}: {lab}: the reversal at t = {T[j]:.6g} s (value {V[j]:.4g} "
                               f"{_unit_of('displacement', dof)}) falls between two steps of stage {st.name!r} "
                               f"(h = {st.h:.4g} s): the driven value turns at {got:.4g}; choose the rate (or h) so "
                               f"that every reversal is a whole number of steps from the stage's start")
                    break  # one line per history
    return out


def _parse_rigid(t: Table, U: dict, rname: str, vertices, D: int = 2) -> RigidSpec:
    """Mass, thickness (2D), inertia, drivers and forces of a rigid body table (dofs of dimension D)."""
    rho = t.number("rho", lo=0, lo_open=True, dim="density")
    mass = t.number("mass", lo=0, lo_open=True, dim="mass")
    if D == 2:
        inertia = t.number("inertia", lo=0, lo_open=True)
        if inertia is not None:
            inertia *= U["mass"] * U["length"] ** 2
    else:  # principal moments about axes through the centre of mass parallel to x, y, z
        inertia = t.vector("inertia", 3)
        if inertia is not None:
            if min(inertia) <= 0:
                raise t.error("inertia", f"= {list(inertia)}: expected 3 principal values > 0 [kg m^2]")
            inertia = tuple(v * U["mass"] * U["length"] ** 2 for v in inertia)
    drivers, forces = {}, {}
    dt = t.table("drivers")
    if dt is not None:
        for dof in list(dt.data):
            if dof not in dofs_of(D):
                raise _dof_error(dt, dof, D)
            drivers[dof] = _read_driver(dt.table(dof), dof, D)
        dt.done()
    ft = t.table("forces")
    if ft is not None:
        for dof in list(ft.data):
            if dof not in dofs_of(D):
                raise _dof_error(ft, dof, D)
            if dof in drivers:
                raise ft.error(dof, "this dof is driven; a driven dof cannot also carry a force")
            forces[dof] = ft.history(dof, "force" if dof[0] != "r" else "moment")  # a moment on a rotation dof
        ft.done()
    if dt is not None:
        _check_pivot(dt, drivers, forces, D)
    if rho is not None and mass is not None:
        raise t.error("mass", "given together with rho: give rho [kg/m^3] (mass and inertia from the polygon) or "
                              "mass [kg] (and inertia), not both")
    if rho is not None and inertia is not None:
        raise t.error("inertia", "given together with rho (the inertia then comes from the polygon): give it with "
                                 "mass instead")
    n_driven = len(set(drivers) | (set(dofs_of(D)[:D]) if _has_pivot(drivers) else set()))
    if rho is None and mass is None and not (n_driven == len(dofs_of(D))):
        raise t.missing("rho", "give rho [kg/m^3] or mass [kg] (only a body with all "
                             f"{'three' if D == 2 else 'six'} dofs driven may omit both)")
    return RigidSpec(name=rname, vertices=vertices, rho=rho, mass=mass, inertia=inertia,
                     thickness=t.number("thickness", 1.0, lo=0, lo_open=True, dim="length") if D == 2 else 1.0,
                     drivers=drivers, forces=forces)


FIXED = {k: ("velocity", 0.0) for k in ("x", "y", "rz")}


def _openings(w: Table, U: dict, what: str) -> list:
    """`openings`: a list of [x0, y0, x1, y1] rectangles (2D; [x0, z0, x1, z1] in the wall frame in 3D), in SI;
    `what` is the expected form for the error."""
    ops = w.raw("openings", [])
    if not isinstance(ops, list) or not all(isinstance(o, list) and len(o) == 4 and all(_finite(v) for v in o)
                                            for o in ops):
        raise w.error("openings", f"expected a list of {what}")
    return [[float(v) * U["length"] for v in o] for o in ops]


def _parse_wall(w: Table, U: dict, materials, warnings: list, units: str = "SI") -> WallSpec:
    """[wall]: a masonry wall (expand.py builds it with `builders`), optional rigid foundation and top beam."""
    kind = w.string("type", "running_bond", choices=("running_bond", "courses", "prism"))
    mat = _material(w, materials)
    L = w.number("brick_length", required=True, lo=0, lo_open=True, dim="length")
    H = w.number("brick_height", required=True, lo=0, lo_open=True, dim="length")
    for k, v in (("brick_length", L), ("brick_height", H)):
        _warn_implausible(warnings, w, k, v, "length", units)
    joint = w.number("joint", 0.0, lo=0, dim="length")
    expanded = w.boolean("expanded", False)
    g = WallSpec(key=w.path, kind=kind, material=mat, brick_length=L, brick_height=H, joint=joint, expanded=expanded,
                 mesh_size=w.number("mesh_size", required=True, lo=0, lo_open=True, dim="length"),
                 cell=w.string("cell", "quad", choices=("quad", "triangle")),
                 mass=w.string("mass", "lumped", choices=("lumped", "consistent")),
                 position=w.vector("position", 2, (0.0, 0.0), dim="length"),
                 group=w.string("group", "bricks"))
    x0 = g.position[0]
    if kind in ("running_bond", "courses"):
        g.openings = _openings(w, U, "[x0, y0, x1, y1] rectangles [m]")
    if kind == "running_bond":
        g.courses = w.integer("courses", required=True, lo=1, hi=2000)
        g.bricks_per_course = w.integer("bricks_per_course", required=True, lo=1, hi=2000)
        g.half_bricks = w.boolean("half_bricks", True)
    elif kind == "courses":
        rows = w.raw("rows")
        if rows is None:
            raise w.missing("rows", "a list of courses, e.g. [[0.5, 1, 1, 0.5], [1, 1, 1]]")
        if not isinstance(rows, list) or not rows:
            raise w.error("rows", "expected a list of courses, e.g. [[0.5, 1, 1, 0.5], [1, 1, 1]]")
        g.rows = [[({"gap": float(it["gap"]) * U["length"]} if isinstance(it, dict) and "gap" in it else it)
                   for it in row] if isinstance(row, list) else row for row in rows]
    else:
        g.bricks = w.integer("bricks", required=True, lo=1, hi=10000)
    g.split_bricks = w.boolean("split_bricks", False)
    if g.split_bricks and not expanded:
        raise w.error("split_bricks", "needs expanded = true (the crack between two halves has no joint "
                                      "thickness; thick joints would give the crack the joint's g0)")
    f = w.table("foundation")
    if f is not None:
        depth = f.number("depth", 0.1, lo=0, lo_open=True, dim="length")
        over = f.number("overhang", 0.0, lo=0, dim="length")
        splits = f.raw("split", [])
        if not isinstance(splits, list) or not all(isinstance(v, NUMBER) for v in splits):
            raise f.error("split", "expected a list of x positions [m] where the foundation is cut")
        cuts = sorted(float(v) * U["length"] + x0 for v in splits)  # range checked by expand (needs the wall)
        sett = f.table("settlement")
        part, hist = None, None
        if sett is not None:
            part = sett.integer("part", required=True, lo=0, hi=len(cuts))
            hist = sett.history("history", "length", required=True, protocol=True)
            sett.done()
        bodies = []
        for k in range(len(cuts) + 1):
            drv = dict(FIXED)
            if k == part:
                drv["y"] = ("displacement", hist)
            bodies.append(RigidSpec(name="foundation" if not cuts else f"foundation{k}", vertices=None, rho=None,
                                    mass=None, inertia=None, thickness=1.0, drivers=drv, forces={},
                                    group="foundation"))
        g.foundation = SlabSpec(depth, over, bodies, cuts)
        f.done()
    g.beam = _parse_beam(w, U, 2, materials[mat].thickness)
    return g


def _parse_beam(w: Table, U: dict, D: int, thickness: float | None = None) -> SlabSpec | None:
    """[wall.beam] / [wall3d.beam]: a rigid body (mass, drivers, forces) on top of the wall, `depth` high; a 2D
    beam is as thick as the wall's material unless it gives its own thickness."""
    bt = w.table("beam")
    if bt is None:
        return None
    depth = bt.number("depth", required=True, lo=0, lo_open=True, dim="length")
    over = bt.number("overhang", 0.0, lo=0, dim="length")
    r = _parse_rigid(bt, U, "beam", None, D)
    if D == 2 and "thickness" not in bt.data:  # the wall's thickness, read as if given in the file's unit
        r.thickness = float(thickness / U["length"]) * U["length"]
    r.group = "beam"
    bt.done()
    return SlabSpec(depth, over, [r])


def quick(case: Case, factor: float = 2.0) -> Case:
    """Reduced-resolution variant of a case (`--quick`): element sizes and time steps multiplied by `factor`
    (durations, loads and stop criteria unchanged). For smoke tests and a first look. The generated block types
    (case.generators, before expand) take the same change."""
    for bt in list(case.block_types.values()) + list(case.generators):
        if bt.mesh_size is not None and getattr(bt, "geometry", None) != "file":
            bt.mesh_size *= factor
        if bt.divisions is not None:  # 3D: fewer elements along each edge, n / factor rounded up
            bt.divisions = tuple(max(1, math.ceil(n / factor)) for n in bt.divisions)
    for st in case.stages:
        st.h = min(st.h * factor, st.duration)
        st.output_every = max(1, int(round(st.output_every / factor)))
        if st.stop_after_peak is not None:
            body, dof, drop, n = st.stop_after_peak
            st.stop_after_peak = (body, dof, drop, max(1, int(round(n / factor))))
        st.min_steps = max(1, int(round(st.min_steps / factor)))
    case.warnings += [w for w in reversal_warnings(case) if w not in case.warnings]  # the steps changed
    case.name += " (quick)"
    case.variant = f"quick x{factor:g}"
    return case


def _parse_arch(a: Table, U: dict, materials, warnings: list = None, units: str = "SI") -> ArchSpec:
    """[arch]: semicircular arch of identical voussoirs (one block type, rotated instances) on two rigid piers."""
    mat = _material(a, materials)
    return ArchSpec(key=a.path, material=mat,
                    span=a.number("span", required=True, lo=0, lo_open=True, dim="length"),
                    ring_depth=a.number("ring_depth", required=True, lo=0, lo_open=True, dim="length"),
                    voussoirs=a.integer("voussoirs", required=True, lo=3, hi=10000),
                    pier_height=a.number("pier_height", required=True, lo=0, lo_open=True, dim="length"),
                    pier_width=a.number("pier_width", required=True, lo=0, lo_open=True, dim="length"),
                    joint=a.number("joint", 0.0, lo=0, dim="length"),
                    mesh_size=a.number("mesh_size", required=True, lo=0, lo_open=True, dim="length"),
                    cell=a.string("cell", "triangle", choices=("quad", "triangle")),
                    mass=a.string("mass", "lumped", choices=("lumped", "consistent")),
                    group=a.string("group", "voussoirs"),
                    piers=[RigidSpec(name=f"pier{k}", vertices=None, rho=None, mass=None, inertia=None, thickness=1.0,
                                     drivers=dict(FIXED), forces={}, group="piers") for k in range(2)])


# ----------------------------------------------------------------------------- dimension 3
GEOMETRIES = {2: ("rectangle", "polygon", "file"), 3: ("box", "hexahedron", "file")}
FIXED_3D = {k: ("velocity", 0.0) for k in DOFS_3D}


def _check_geometry_dimension(t: Table, D: int):
    g = t.data.get("geometry")
    if isinstance(g, str) and g in GEOMETRIES[5 - D] and g not in GEOMETRIES[D]:
        raise t.error("geometry", f"= {g!r}: a geometry of dimension {5 - D}; expected one of "
                                  f"{list(GEOMETRIES[D])} in dimension {D}")


def _mesh_file(t: Table, base: str) -> str:
    f = t.string("file", required=True)
    full = f if os.path.isabs(f) else os.path.join(base, f)
    if not os.path.isfile(full):
        raise t.error("file", f"= {f!r}: mesh file not found (expected a .geo or .msh file, "
                              f"relative to the case file)")
    if not full.endswith((".geo", ".msh")):
        raise t.error("file", f"= {f!r}: expected a .geo or .msh file")
    return full


def _divisions(t: Table, key: str = "divisions"):
    """[n0, n1, n2]: hexahedra along the edges 0-1, 0-3, 0-4 of a block (x, y, z of a box), integers 1..200."""
    v = t.raw(key)
    if v is None:
        return None
    if not (isinstance(v, list) and len(v) == 3 and all(isinstance(n, int) and not isinstance(n, bool)
                                                          and 1 <= n <= 200 for n in v)):
        raise t.error(key, f"= {v!r}: expected [n0, n1, n2], 3 integers from 1 to 200 (elements along x, y, z)")
    return tuple(v)


def _mesh_resolution(t: Table, geom: str):
    """mesh_size [m] or divisions (exactly one for generated blocks; a .geo file takes an optional size cap)."""
    size = t.number("mesh_size", None, lo=0, lo_open=True, dim="length")
    div = _divisions(t)
    if geom == "file":
        if div is not None:
            raise t.error("divisions", "not used with geometry = 'file' (the file sets its mesh); expected "
                                       "mesh_size (an element size cap for .geo files) or nothing")
    elif (size is None) == (div is None):
        raise t.error("mesh_size", "give exactly one of mesh_size [m] (element size) or divisions = [n0, n1, n2]")
    return size, div


def _check_corners(t: Table, C):
    """`corners` (or a box's) of table t: a proper hexahedron in the gmsh order (geometry.check_hex_corners)."""
    try:
        check_hex_corners(np.asarray(C, dtype=float), t.path)
    except InputError as e:
        raise InputError(f"{t.source}: {e}") from None


def _parse_block_type_3d(t: Table, tname: str, materials: dict, base: str) -> BlockTypeSpec:
    """[block_types.NAME] in dimension 3: box (size), hexahedron (8 corners) or a 3D .msh/.geo file."""
    _check_geometry_dimension(t, 3)
    t.dimension_keys(3, dict(lx=2, ly=2, vertices=2))
    geom = t.string("geometry", required=True, choices=GEOMETRIES[3])
    mat = t.string("material", required=True)
    if mat not in materials:
        raise t.error("material", f"= {mat!r}: expected one of the [materials] {sorted(materials)}")
    size, div = _mesh_resolution(t, geom)
    bt = BlockTypeSpec(name=tname, geometry=geom, material=mat, mesh_size=size, divisions=div,
                       cell=t.string("cell", None if geom == "file" else "hexahedron",
                                     choices=("hexahedron", "tetrahedron")),
                       mass=t.string("mass", "lumped", choices=("lumped", "consistent")))
    if geom == "box":
        lx, ly, lz = t.vector("size", 3, dim="length", required=True)
        if min(lx, ly, lz) <= 0:
            raise t.error("size", f"= {t.data['size']!r}: expected [lx, ly, lz] > 0 [m]")
        bt.lx, bt.ly, bt.lz = lx, ly, lz
    elif geom == "hexahedron":
        bt.corners = t.points("corners", n=3, min_count=8, exact=True)
        _check_corners(t, bt.corners)
    else:
        bt.file = _mesh_file(t, base)
    return bt


def _rotation(t: Table) -> np.ndarray:
    """3D block placement x = R X + position, R the rotation by rotation_angle [deg] about rotation_axis
    (right-hand rule, through the block type's origin; default axis z)."""
    axis = t.vector("rotation_axis", 3, (0.0, 0.0, 1.0))
    angle = t.number("rotation_angle", 0.0)
    if math.hypot(*axis) == 0.0:
        raise t.error("rotation_axis", "= [0, 0, 0]: expected a non-zero vector")
    return rotation_matrix(axis, math.radians(angle))


def _solid_corners(t: Table) -> list:
    """A 3D rigid body's 8 corners: a box (size [lx, ly, lz] from origin [x, y, z]) or corners (gmsh order)."""
    size = t.vector("size", 3, dim="length")
    corners = t.points("corners", n=3, min_count=8, exact=True, required=False)
    if (size is None) == (corners is None):
        raise t.error("size", "give exactly one of size = [lx, ly, lz] (a box from origin) or corners = 8 [x, y, z] "
                              "points")
    if size is not None:
        if min(size) <= 0:
            raise t.error("size", f"= {t.data['size']!r}: expected [lx, ly, lz] > 0 [m]")
        corners = box_corners(*size, t.vector("origin", 3, (0.0, 0.0, 0.0), dim="length"))
    elif "origin" in t.data:
        raise t.error("origin", "only with size (a box); corners are absolute positions")
    _check_corners(t, corners)
    return [tuple(float(x) for x in c) for c in corners]


def type_corners(bt: BlockTypeSpec):
    """(8, 3) corners of a 3D box/hexahedron block type in its own frame (None for a mesh file)."""
    if bt.geometry == "box":
        return box_corners(bt.lx, bt.ly, bt.lz)
    if bt.geometry == "hexahedron":
        return np.asarray(bt.corners, dtype=float)
    return None


def _resolution_3d(t: Table):
    """mesh_size or divisions, cell, mass of the block types a 3D builder table makes."""
    size, div = _mesh_resolution(t, "box")
    return dict(mesh_size=size, divisions=div, cell=t.string("cell", "hexahedron", choices=("hexahedron",
                                                                                           "tetrahedron")),
                mass=t.string("mass", "lumped", choices=("lumped", "consistent")))


def _material(t: Table, materials: dict) -> str:
    mat = t.string("material", required=True)
    if mat not in materials:
        raise t.error("material", f"= {mat!r}: expected one of the [materials] {sorted(materials)}")
    return mat


def _parse_wall3d(w: Table, U: dict, materials, warnings: list, units: str = "SI") -> Wall3DSpec:
    """[wall3d]: running-bond wall of bricks (expand.py: builders3d.running_bond_wall), optional rigid foundation
    (fixed) and top beam (rigid body with drivers/forces) in the wall's frame."""
    mat = _material(w, materials)
    L = w.number("brick_length", required=True, lo=0, lo_open=True, dim="length")
    H = w.number("brick_height", required=True, lo=0, lo_open=True, dim="length")
    W = w.number("brick_width", required=True, lo=0, lo_open=True, dim="length")
    for k, v in (("brick_length", L), ("brick_height", H), ("brick_width", W)):
        _warn_implausible(warnings, w, k, v, "length", units)
    joint = w.number("joint", 0.0, lo=0, dim="length")
    origin = w.vector("position", 3, (0.0, 0.0, 0.0), dim="length")
    angle = math.radians(w.number("angle", 0.0))
    leaves = w.integer("leaves", 1, lo=1, hi=2)
    ops = _openings(w, U, "[x0, z0, x1, z1] rectangles [m] (wall frame)")
    g = Wall3DSpec(key=w.path, material=mat, brick_length=L, brick_height=H, brick_width=W, joint=joint,
                   position=origin, angle=angle, leaves=leaves, openings=ops, **_resolution_3d(w),
                   group=w.string("group", "bricks"),
                   courses=w.integer("courses", required=True, lo=1, hi=2000),
                   bricks_per_course=w.integer("bricks_per_course", required=True, lo=1, hi=2000),
                   half_bricks=w.boolean("half_bricks", True), stagger_leaves=w.boolean("stagger_leaves", False))
    f = w.table("foundation")
    if f is not None:
        depth = f.number("depth", 0.1, lo=0, lo_open=True, dim="length")
        over = f.number("overhang", 0.0, lo=0, dim="length")
        g.foundation = SlabSpec(depth, over, [RigidSpec(name="foundation", vertices=None, rho=None, mass=None,
                                                        inertia=None, thickness=1.0, drivers=dict(FIXED_3D),
                                                        forces={}, group="foundation")])
        f.done()
    g.beam = _parse_beam(w, U, 3)
    return g


def _parse_dome(a: Table, U: dict, materials, warnings: list = None, units: str = "SI") -> DomeSpec:
    """[dome]: spherical dome of hexahedral voussoirs (expand.py: builders3d.dome, thesis §7.2.1.c), one block
    type per course (instances rotated about z), optional fixed rigid piers under the bed course (§7.2.2.a)."""
    mat = _material(a, materials)
    top = a.number("top_elevation", None, lo=0, hi=90, lo_open=True, hi_open=True)
    res = _resolution_3d(a)
    group = a.string("group", "dome")
    pier_group = a.string("pier_group", "piers")
    g = DomeSpec(key=a.path, material=mat, **res, group=group,
                 span=a.number("span", 4.0, lo=0, lo_open=True, dim="length"),
                 thickness=a.number("thickness", 0.48, lo=0, lo_open=True, dim="length"),
                 courses=a.integer("courses", 12, lo=1, hi=1000),
                 blocks_per_course=a.integer("blocks_per_course", 22, lo=3, hi=10000),
                 joint=a.number("joint", 0.03, lo=0, dim="length"),
                 top_elevation=None if top is None else math.radians(top),
                 running_bond=a.boolean("running_bond", True),
                 piers=a.integer("piers", 0, lo=0), pier_blocks=a.integer("pier_blocks", 3, lo=1),
                 pier_height=a.number("pier_height", 0.5, lo=0, lo_open=True, dim="length"))
    g.pier_bodies = [RigidSpec(name=f"pier{p}", vertices=None, rho=None, mass=None, inertia=None, thickness=1.0,
                               drivers=dict(FIXED_3D), forces={}, group=pier_group) for p in range(g.piers)]
    return g
