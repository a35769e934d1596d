"""history.csv: one row per step, floats with 17 significant digits, flushed and fsynced as it goes."""
from __future__ import annotations

import csv
import math
import os

import numpy as np

from ..errors import InputError


def _fmt(v) -> str:
    if isinstance(v, (bool, np.bool_)):
        return str(int(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    try:
        f = float(v)
    except (TypeError, ValueError):
        return str(v)
    if math.isnan(f):
        return "nan"
    return f"{f:.17g}"


class HistoryWriter:
    def __init__(self, path: str, columns, append: bool = False, flush_every: int = 1):
        self.path = os.fspath(path)
        self.columns = list(columns)
        self.flush_every = max(1, int(flush_every))
        self._since_flush = 0
        if append and os.path.exists(self.path):
            with open(self.path, newline="") as f:
                header = next(csv.reader(f), None)
            if header != self.columns:
                raise InputError(f"{self.path}: columns differ from this run's; cannot append")
            self.f = open(self.path, "a", newline="")
        else:
            self.f = open(self.path, "w", newline="")
            self.f.write(",".join(self.columns) + "\n")
            self.flush()

    @classmethod
    def resume(cls, path: str, columns, last_step: int, step_column: str = "step", flush_every: int = 1):
        """Drop rows after `last_step`, then reopen for appending (rows of a run resumed from a checkpoint)."""
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
        if not rows or rows[0] != list(columns):
            raise InputError(f"{path}: columns differ from this run's; cannot resume")
        k = rows[0].index(step_column)
        keep = [rows[0]] + [r for r in rows[1:] if len(r) == len(rows[0]) and int(float(r[k])) <= last_step]
        from .atomic import atomic_write_text
        atomic_write_text(path, "".join(",".join(r) + "\n" for r in keep))
        return cls(path, columns, append=True, flush_every=flush_every)

    def write(self, row) -> None:
        if isinstance(row, dict):
            unknown = set(row) - set(self.columns)
            if unknown:
                raise InputError(f"{self.path}: unknown history column(s) {sorted(unknown)}")
            vals = [row.get(c, "") for c in self.columns]
        else:
            vals = list(row)
            if len(vals) != len(self.columns):
                raise InputError(f"{self.path}: expected {len(self.columns)} values, got {len(vals)}")
        self.f.write(",".join(_fmt(v) for v in vals) + "\n")
        self._since_flush += 1
        if self._since_flush >= self.flush_every:
            self.flush()

    def flush(self):
        self.f.flush()
        os.fsync(self.f.fileno())
        self._since_flush = 0

    def close(self):
        if not self.f.closed:
            self.flush()
            self.f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def read_history(path: str) -> dict:
    """Columns of a history.csv as float arrays (non-numeric columns kept as strings)."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, data = rows[0], rows[1:]
    out = {}
    for j, name in enumerate(header):
        col = [r[j] for r in data]
        try:
            out[name] = np.array([float(x) if x != "" else np.nan for x in col])
        except ValueError:
            out[name] = np.array(col)
    return out
