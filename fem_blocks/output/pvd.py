"""ParaView collection (.pvd) of time frames, rewritten atomically after every frame.

A crash leaves a valid series listing every frame added so far. `PvdSeries.open_existing(path,
keep_until_time)` reloads a series to continue it after a restart: entries with time > keep_until_time
are dropped (and their .vtu files deleted; a dropped .pvtu frame with the pieces it lists), so the resumed run
appends without duplicate times.

Parallel series (SeriesWriter with comm, N ranks): frame f is `BASENAME_<f>.pvtu` (written by rank 0, listing the
pieces in rank order) over the pieces `BASENAME_<f>_p<rank>.vtu`, each written by its rank (a rank with nothing
to write writes no piece and is not listed); the .pvd lists the .pvtu files. Rank 0 adds a frame to the .pvd only
after every rank has written its piece (the gather of the pieces' array layouts), so the series never names an
incomplete frame."""
from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from xml.sax.saxutils import quoteattr

from ..distributed.root import on_root
from ..errors import InputError
from .atomic import atomic_write_text
from .vtu import array_info, write_pvtu, write_vtu


def _read_entries(path: str) -> list:
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as e:
        raise InputError(f"{path}: cannot read the ParaView series ({e})") from None
    if root.tag != "VTKFile" or root.get("type") != "Collection":
        raise InputError(f"{path}: expected a ParaView collection (<VTKFile type=\"Collection\">)")
    entries = []
    for ds in root.iter("DataSet"):
        f = ds.get("file")
        try:
            t, part = float(ds.get("timestep", "0")), int(ds.get("part", "0"))
        except ValueError:
            t = part = None
        if f is None or t is None:
            raise InputError(f"{path}: DataSet {ET.tostring(ds, encoding='unicode').strip()} "
                             "has no file or a non-numeric timestep/part")
        entries.append((t, part, f))
    return entries


class PvdSeries:
    """Time series `<DataSet timestep=t part=p file=relative.vtu/>`; `.entries` = [(time, part, file)].

    append=False starts a new (empty, valid) series at `path`; append=True continues an existing one."""

    def __init__(self, path, append: bool = False):
        self.path = os.fspath(path)
        self.entries: list[tuple[float, int, str]] = []
        if append and os.path.exists(self.path):
            self.entries = _read_entries(self.path)
        self._write()

    @classmethod
    def open_existing(cls, path, keep_until_time: float | None = None) -> "PvdSeries":
        """Reload `path`; drop entries with time > keep_until_time * (1 + 1e-12) and delete their files (inside the
        series' directory that no kept entry refers to). The rewritten series is saved at once."""
        path = os.fspath(path)
        if not os.path.exists(path):
            raise InputError(f"{path}: ParaView series not found; cannot resume it")
        entries = _read_entries(path)
        if keep_until_time is not None:
            tk = float(keep_until_time)
            if not math.isfinite(tk):
                raise InputError(f"keep_until_time = {keep_until_time!r}: expected a finite time")
            tk += 1e-12 * abs(tk)  # the checkpoint time recomputed in another order may differ by ulps
            kept = [e for e in entries if e[0] <= tk]
            dropped = [e for e in entries if e[0] > tk]
        else:
            kept, dropped = entries, []
        s = cls.__new__(cls)
        s.path, s.entries = path, kept
        s._write()  # first the series without the dropped frames, then delete their files
        d = os.path.dirname(os.path.abspath(path))
        kept_files = {os.path.normpath(os.path.join(d, e[2])) for e in kept}
        for _, _, f in dropped:
            full = os.path.normpath(os.path.join(d, f))
            if full in kept_files or os.path.commonpath([d, full]) != d:
                continue  # still referenced, or outside the output directory: never delete
            files = [full]
            if full.endswith(".pvtu"):  # a parallel frame: its pieces too
                try:
                    src = [p.get("Source") for p in ET.parse(full).getroot().iter("Piece")]
                except (OSError, ET.ParseError):
                    src = []
                base = os.path.dirname(full)
                files = [os.path.normpath(os.path.join(base, p)) for p in src if p] + files
            for g in files:
                if os.path.commonpath([d, g]) != d:
                    continue
                try:
                    os.unlink(g)
                except FileNotFoundError:
                    pass
        return s

    @property
    def times(self) -> list:
        return [e[0] for e in self.entries]

    @property
    def files(self) -> list:
        return [e[2] for e in self.entries]

    def add(self, time: float, vtu_relative_path, part: int = 0) -> None:
        """Append a frame and rewrite the .pvd atomically."""
        t = float(time)
        if not math.isfinite(t):
            raise InputError(f"time = {time!r}: expected a finite number")
        f = os.fspath(vtu_relative_path)
        if not f:
            raise InputError("vtu_relative_path: expected a non-empty file name")
        self.entries.append((t, int(part), f.replace(os.sep, "/")))
        self._write()

    def _write(self) -> None:
        lines = ['<?xml version="1.0"?>', '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
                 "<Collection>"]
        for t, part, f in self.entries:
            lines.append(f'<DataSet timestep="{t!r}" group="" part="{part}" file={quoteattr(f)}/>')
        lines += ["</Collection>", "</VTKFile>", ""]
        atomic_write_text(self.path, "\n".join(lines))


class SeriesWriter:
    """Base of the writers of one `.vtu` per frame listed in `DIR/BASENAME.pvd` (bodies, contact points; 2D
    and 3D). append=True continues an existing series, dropping the frames after keep_until_time
    (`PvdSeries.open_existing`); `.frame` is the number of the next frame.

    comm (an mpi4py communicator of N > 1 ranks, every rank constructing the writer and calling write_frame at
    the same frames): each rank writes its piece of every frame and rank 0 the .pvtu and the .pvd (module
    docstring); rank 0 opens (or cuts back) the series and sends the frame number to the others. `.series` is
    None on the other ranks."""

    def __init__(self, directory: str, basename: str, append: bool = False,
                 keep_until_time: float | None = None, comm=None):
        self.dir, self.base = directory, basename
        self.comm = comm if comm is not None and comm.Get_size() > 1 else None
        os.makedirs(directory, exist_ok=True)
        pvd = os.path.join(directory, f"{basename}.pvd")
        self.series = None

        def open_series():
            self.series = PvdSeries.open_existing(pvd, keep_until_time) if append and os.path.exists(pvd) \
                else PvdSeries(pvd)
            return len(self.series.entries)

        # (N ranks: the others wait here until rank 0 has cut the series back and deleted the dropped pieces; its
        # failure, e.g. a malformed series on resume, is raised on every rank)
        self.frame = on_root(self.comm, open_series)

    def write_frame(self, time: float, points, cells, point_data=None, cell_data=None) -> str:
        """Write `BASENAME_<frame>.vtu` (write_vtu arguments) and add it to the series at `time`. With comm:
        (points, cells, data) are this rank's piece, None for no piece; returns the .pvtu's name."""
        if self.comm is not None:
            return self._write_parallel(time, points, cells, point_data, cell_data)
        name = f"{self.base}_{self.frame:06d}.vtu"
        write_vtu(os.path.join(self.dir, name), points, cells, point_data=point_data or None,
                  cell_data=cell_data or None)
        self.series.add(time, name)
        self.frame += 1
        return name

    def _write_parallel(self, time, points, cells, point_data, cell_data) -> str:
        rank = self.comm.Get_rank()
        name = f"{self.base}_{self.frame:06d}.pvtu"
        info = None
        if points is not None:
            piece = f"{self.base}_{self.frame:06d}_p{rank}.vtu"
            write_vtu(os.path.join(self.dir, piece), points, cells, point_data=point_data or None,
                      cell_data=cell_data or None)
            info = (piece, array_info(point_data, cell_data))
        infos = self.comm.gather(info, root=0)  # (also: every piece is on disk before the .pvd names the frame)
        if rank == 0:
            pieces = [i for i in infos if i is not None]
            write_pvtu(os.path.join(self.dir, name), [p for p, _ in pieces], pieces[0][1] if pieces else array_info())
            self.series.add(time, name)
        self.frame += 1
        return name
