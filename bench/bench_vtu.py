"""VTU writer: file size and write time of every ParaView frame of a demo run, and a bitwise check that two
writers store the same numbers (docs/benchmarks.md "VTU writer").

  record CASE.toml FRAMES.pkl [--quick]   run the case once; keep the arguments of every write_vtu call
  time FRAMES.pkl [--repeat R] [--zlib] [--no-fsync] [--keep DIR]
                                          write every recorded frame with the `write_vtu` of the fem_blocks on
                                          PYTHONPATH (R times, the fastest kept); total bytes, seconds, files
                                          read back by meshio and by VTK; --zlib: with vtu.COMPRESSION = "zlib"
                                          (meshio writer only); --no-fsync: os.fsync made a no-op, i.e. the
                                          writer's own cost without the disk flushes of the atomic write (the
                                          same two fsyncs per file before and after); --keep DIR keeps the files;
                                          --dir D writes there (e.g. /dev/shm: no disk)
  same DIR_A DIR_B                        every .vtu of DIR_A and DIR_B read by meshio: points, cells, point
                                          and cell data equal bit for bit (same dtype, same values)

Before/after: `record` once, then `time` with PYTHONPATH set to each tree (the frames are the same input).
"""
import argparse
import glob
import os
import pickle
import shutil
import sys
import tempfile
import time

import numpy as np


def record(case_path, frames_path, quick):
    import fem_blocks.output.pvd as pvd
    from fem_blocks.case import load_case, quick as make_quick
    from fem_blocks.runner import run_case
    frames, real = [], pvd.write_vtu

    def keep(path, points, cells, point_data=None, cell_data=None, field_data=None):
        frames.append((os.path.basename(path), np.array(points),
                       [(n, [np.array(p) for p in c] if n == "polygon" else np.array(c)) for n, c in cells],
                       {k: np.array(v) for k, v in (point_data or {}).items()},
                       {k: np.array(v) for k, v in (cell_data or {}).items()}))
        return real(path, points, cells, point_data, cell_data, field_data)
    pvd.write_vtu = keep
    case = load_case(case_path)
    with tempfile.TemporaryDirectory(prefix="bench_vtu_") as out:
        run_case(make_quick(case) if quick else case, out, progress=False)
    with open(frames_path, "wb") as f:
        pickle.dump(frames, f)
    print(f"{len(frames)} frames of {case_path} -> {frames_path}")


def _vtk_ok(path):
    import vtk
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(path)
    r.Update()
    return r.GetErrorCode() == 0


def timing(frames_path, repeat, zlib, keep, no_fsync=False, where=None):
    import meshio
    import fem_blocks
    from fem_blocks.output import vtu
    if zlib:
        vtu.COMPRESSION = "zlib"
    if no_fsync:
        os.fsync = lambda fd: None
    with open(frames_path, "rb") as f:
        frames = pickle.load(f)
    best = float("inf")
    d = tempfile.mkdtemp(prefix="bench_vtu_", dir=where)
    for _ in range(repeat):
        t0 = time.perf_counter()
        for name, P, cells, pd, cd in frames:
            vtu.write_vtu(os.path.join(d, name), P, cells, point_data=pd, cell_data=cd)
        best = min(best, time.perf_counter() - t0)
    files = sorted(glob.glob(os.path.join(d, "*.vtu")))
    size = sum(os.path.getsize(f) for f in files)
    bad = [os.path.basename(f) for f in files if not _vtk_ok(f)]
    unread = []
    for f in files:
        try:
            meshio.read(f)
        except Exception as e:  # noqa: BLE001 - reported, e.g. meshio 5.0 on a zlib-compressed empty array
            unread.append(f"{os.path.basename(f)} ({type(e).__name__})")
    print(f"{os.path.dirname(fem_blocks.__file__)}{' zlib' if zlib else ''}{' no-fsync' if no_fsync else ''}: "
          f"{len(files)} files, {size / 1e6:.3f} MB, write {best:.3f} s (best of {repeat}), "
          f"{1e3 * best / len(files):.2f} ms/file; meshio cannot read: {unread or 'none'}; "
          f"VTK reader errors: {bad or 'none'}")
    if keep:
        shutil.rmtree(keep, ignore_errors=True)
        shutil.copytree(d, keep)
    shutil.rmtree(d)


def same(a, b):
    import meshio
    names = sorted(os.path.basename(f) for f in glob.glob(os.path.join(a, "*.vtu")))
    assert names == sorted(os.path.basename(f) for f in glob.glob(os.path.join(b, "*.vtu"))), "file lists differ"

    def eq(x, y):
        return x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y)
    for n in names:
        ma, mb = meshio.read(os.path.join(a, n)), meshio.read(os.path.join(b, n))
        assert eq(ma.points, mb.points), n
        assert [c.type for c in ma.cells] == [c.type for c in mb.cells], n
        assert all(eq(np.asarray(x.data), np.asarray(y.data)) for x, y in zip(ma.cells, mb.cells)), n
        assert ma.point_data.keys() == mb.point_data.keys() and ma.cell_data.keys() == mb.cell_data.keys(), n
        assert all(eq(ma.point_data[k], mb.point_data[k]) for k in ma.point_data), n
        assert all(eq(x, y) for k in ma.cell_data for x, y in zip(ma.cell_data[k], mb.cell_data[k])), n
    print(f"{len(names)} files: points, cells, point and cell data identical (dtype and bits)")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("case")
    r.add_argument("frames")
    r.add_argument("--quick", action="store_true")
    t = sub.add_parser("time")
    t.add_argument("frames")
    t.add_argument("--repeat", type=int, default=3)
    t.add_argument("--zlib", action="store_true")
    t.add_argument("--no-fsync", action="store_true")
    t.add_argument("--keep")
    t.add_argument("--dir", help="where to write (default: the temporary directory; /dev/shm takes the disk out)")
    s = sub.add_parser("same")
    s.add_argument("a")
    s.add_argument("b")
    a = p.parse_args(argv)
    if a.cmd == "record":
        record(a.case, a.frames, a.quick)
    elif a.cmd == "time":
        timing(a.frames, a.repeat, a.zlib, a.keep, a.no_fsync, a.dir)
    else:
        same(a.a, a.b)


if __name__ == "__main__":
    sys.exit(main())
