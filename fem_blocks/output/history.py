"""history.csv: header line, then one row per step; floats written with `%.17g` (exact float64 round trip),
integers as integers; flushed and fsynced every `flush_every` rows and at close, so a crash loses at most
`flush_every - 1` rows. `HistoryWriter.resume` truncates the rows written after a checkpoint's step.

With keep=True the writer also keeps the rows it writes (and, on resume, the rows of the file it keeps) in memory:
`columns_dict()` gives them as read_history would read the file back (name -> float64 array, empty -> NaN), so that
figures and reports are drawn from the run itself; the file is the users' copy, not an input of the run."""
from __future__ import annotations

import csv
import io
import math
import os

import numpy as np

from ..errors import InputError
from .atomic import atomic_write_text


def _fmt(v) -> str:
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return str(int(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (str, np.str_)):
        return str(v)
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InputError(f"history value {v!r}: expected a number, a string or None") from None
    if math.isnan(f):
        return "nan"
    return "%.17g" % f


def _value(v):
    """A history value as read_history reads it back: None -> NaN, bool/int/float -> float; str kept."""
    if v is None:
        return np.nan
    if isinstance(v, (str, np.str_)):
        return _parse(str(v))
    return float(v)


def _parse(x: str):
    """A history.csv cell as read_history reads it: "" -> NaN, a number -> float, else the string."""
    if x == "":
        return np.nan
    try:
        return float(x)
    except ValueError:
        return x


def _line(values) -> str:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(values)
    return buf.getvalue()


def _read_rows(path: str):
    """Header and complete rows; a last line without its newline (cut by a crash) is dropped."""
    try:
        with open(path, newline="") as f:
            text = f.read()
    except OSError as e:
        raise InputError(f"{path}: cannot read the history ({e})") from None
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise InputError(f"{path}: empty history file (expected a header line)")
    return rows[0], [r for r in rows[1:] if len(r) == len(rows[0])]


def _drop_torn_line(path: str) -> None:
    """Truncate a last line without its newline (a row cut by a crash) so appended rows start clean."""
    with open(path, "rb+") as f:
        f.seek(0, os.SEEK_END)
        size = f.tell()
        if size == 0:
            return
        f.seek(size - 1)
        if f.read(1) == b"\n":
            return
        f.seek(0)
        data = f.read()
        f.truncate(data.rfind(b"\n") + 1)
        f.flush()
        os.fsync(f.fileno())


class HistoryWriter:
    """CSV writer with a fixed list of columns; `.write(dict)` (missing keys -> empty) or `.write(sequence)`."""

    def __init__(self, path, columns, append: bool = False, flush_every: int = 1, keep: bool = False):
        self.path = os.fspath(path)
        self.kept = [] if keep else None  # rows written (values), when keep
        self.columns = [str(c) for c in columns]
        if not self.columns:
            raise InputError(f"{self.path}: columns: expected at least one column name")
        if len(set(self.columns)) != len(self.columns):
            dup = sorted({c for c in self.columns if self.columns.count(c) > 1})
            raise InputError(f"{self.path}: columns: duplicate column name(s) {dup}")
        bad = [c for c in self.columns if not c or any(ch in c for ch in ',"\n\r')]
        if bad:
            raise InputError(f"{self.path}: columns: names must be non-empty without comma, quote or newline, "
                             f"got {bad}")
        try:
            self.flush_every = int(flush_every)
        except (TypeError, ValueError):
            self.flush_every = 0
        if self.flush_every < 1:
            raise InputError(f"flush_every = {flush_every!r}: expected an integer >= 1")
        self._index = {c: i for i, c in enumerate(self.columns)}
        self._pending = 0
        if append and os.path.exists(self.path) and os.path.getsize(self.path) > 0:
            with open(self.path, newline="") as f:
                header = next(csv.reader(f), [])
            if header != self.columns:
                raise InputError(f"{self.path}: columns differ from this run's (file {header}, run {self.columns});"
                                 " cannot append")
            _drop_torn_line(self.path)
            self.f = open(self.path, "a", newline="")
        else:
            self.f = open(self.path, "w", newline="")
            self.f.write(_line(self.columns))
            self.flush()

    @classmethod
    def resume(cls, path, last_step: int, step_column: str = "step", columns=None,
               flush_every: int = 1, keep: bool = False) -> "HistoryWriter":
        """Keep the header and the rows with step <= last_step (dropping a torn last line), rewrite the file
        atomically and reopen it for appending. `columns`, if given, must equal the file's header. keep=True: the
        kept rows are also the first rows of `columns_dict()` (the file is read once, here)."""
        path = os.fspath(path)
        header, rows = _read_rows(path)
        if columns is not None and header != [str(c) for c in columns]:
            raise InputError(f"{path}: columns differ from this run's (file {header}, run {list(columns)}); "
                             "cannot resume")
        if step_column not in header:
            raise InputError(f"{path}: step_column {step_column!r} not in the header {header}")
        k = header.index(step_column)
        kept = []
        for r in rows:
            try:
                s = float(r[k])
            except ValueError:
                raise InputError(f"{path}: non-numeric {step_column} {r[k]!r}") from None
            if s <= last_step:
                kept.append(r)
        atomic_write_text(path, "".join(_line(r) for r in [header] + kept))
        w = cls(path, header, append=True, flush_every=flush_every, keep=keep)
        if keep:
            w.kept = [[_parse(x) for x in r] for r in kept]
        return w

    def write(self, row) -> None:
        if isinstance(row, dict):
            unknown = [c for c in row if c not in self._index]
            if unknown:
                raise InputError(f"{self.path}: unknown history column(s) {sorted(map(str, unknown))}; "
                                 f"expected a subset of {self.columns}")
            vals = [row.get(c) for c in self.columns]
        else:
            vals = list(row)
            if len(vals) != len(self.columns):
                raise InputError(f"{self.path}: expected {len(self.columns)} values ({self.columns}), "
                                 f"got {len(vals)}")
        self.f.write(_line([_fmt(v) for v in vals]))
        if self.kept is not None:
            self.kept.append([_value(v) for v in vals])
        self._pending += 1
        if self._pending >= self.flush_every:
            self.flush()

    def columns_dict(self) -> dict:
        """The kept rows as columns: name -> float64 array (None/empty -> NaN), or a str array for a column with
        non-numeric entries; the values read_history gives for the file (floats are written exactly)."""
        if self.kept is None:
            raise InputError(f"{self.path}: this HistoryWriter keeps no rows (keep=False)")
        out = {}
        for j, name in enumerate(self.columns):
            col = [r[j] for r in self.kept]
            try:
                out[name] = np.array(col, dtype=np.float64)
            except (TypeError, ValueError):
                out[name] = np.array([str(x) for x in col])
        return out

    def flush(self) -> None:
        self.f.flush()
        os.fsync(self.f.fileno())
        self._pending = 0

    def close(self) -> None:
        if not self.f.closed:
            try:
                self.flush()
            finally:
                self.f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def read_history(path) -> dict:
    """Columns of a history.csv: name -> float64 array (empty cells -> NaN), or a str array for a column
    with non-numeric entries. A torn last line is ignored."""
    header, rows = _read_rows(os.fspath(path))
    out = {}
    for j, name in enumerate(header):
        col = [r[j] for r in rows]
        try:
            out[name] = np.array(col, dtype=np.float64)  # C-level parse; exact for the %.17g text
        except ValueError:
            try:
                out[name] = np.array([float(x) if x != "" else np.nan for x in col], dtype=np.float64)
            except ValueError:
                out[name] = np.array(col)
    return out
