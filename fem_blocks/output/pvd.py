"""ParaView collection (.pvd) of time frames, rewritten atomically after every frame.

A crash leaves a valid series of all frames written so far; `open_existing` reloads a series to
append to it after a restart, dropping frames later than the restart time."""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET

from ..errors import InputError
from .atomic import atomic_write_text


class PvdSeries:
    def __init__(self, path: str, entries=None):
        self.path = os.fspath(path)
        self.entries: list[tuple[float, int, str]] = list(entries or [])  # (time, part, relative file)
        self._write()

    @classmethod
    def open_existing(cls, path: str, keep_until_time: float | None = None) -> "PvdSeries":
        try:
            root = ET.parse(path).getroot()
        except (OSError, ET.ParseError) as e:
            raise InputError(f"{path}: cannot read the ParaView series ({e})") from None
        entries = []
        d = os.path.dirname(os.path.abspath(path))
        for ds in root.iter("DataSet"):
            t = float(ds.get("timestep", "0"))
            f = ds.get("file")
            part = int(ds.get("part", "0"))
            if keep_until_time is not None and t > keep_until_time * (1 + 1e-12) + 1e-300:
                try:
                    os.unlink(os.path.join(d, f))
                except FileNotFoundError:
                    pass
                continue
            entries.append((t, part, f))
        return cls(path, entries)

    def add(self, time: float, relative_file: str, part: int = 0) -> None:
        self.entries.append((float(time), int(part), relative_file))
        self._write()

    def _write(self):
        lines = ['<?xml version="1.0"?>', '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
                 "<Collection>"]
        for t, part, f in self.entries:
            lines.append(f'<DataSet timestep="{t:.17g}" group="" part="{part}" file="{f}"/>')
        lines += ["</Collection>", "</VTKFile>", ""]
        atomic_write_text(self.path, "\n".join(lines))
