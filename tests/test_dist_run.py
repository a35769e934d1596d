"""Runs on several MPI ranks: `mpirun -n N fem-blocks run CASE` (issue #24; runner.run_case(comm=),
distributed/colour.py).

Expectation (from outside the distributed code): the run of the same case file on ONE process, `fem-blocks run`
without mpirun, with `[contact] order = "colours"`. Every rank builds the model and steps it; the Gauss–Seidel sweeps
are split by contact owner (the rank of the candidate body, PT-Scotch partition) and only interface impulses cross
ranks, in colour order, with exact sums in the stopping tests. So history.csv of N = 2 and 3 ranks must be the
serial file, byte for byte: a dry wall, a wall with mixed-mode cohesive joints, a 3D wall, and a brick on its
foundation on 3 ranks (one rank owns no body). The exit status is the serial one on every rank (a solver policy
stop: 1; invalid input: 2), and a run check that stops the run names the serial contact on 3 ranks. A run killed
by SIGKILL on one rank and resumed (--resume) on 2 ranks gives the uninterrupted serial history, byte for byte, and so
does its checkpoint (one piece per rank) resumed on one process. The ParaView pieces of the bodies and of the
contacts are the serial frames'.

One-line bugs these catch (checked): scattering the impulses after the sweep instead of after each colour (the
ranks read stale interface impulses: histories differ on 2 ranks); summing the change per rank without the exact
reduction (the sweep counts differ on the cohesive wall); ranks other than 0 writing history.csv (duplicated rows).
"""
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from _mpi import ENV
from _paths import ROOT

sys.path.insert(0, os.path.dirname(__file__))
import dist_cases  # noqa: E402

pytestmark = pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")

DRIVER = os.path.join(os.path.dirname(__file__), "dist_cases.py")
SERIAL = ("dry", "mixed", "wall3d", "one_brick", "fail", "bad", "long", "newton", "guard", "joints")


def _mpirun(n, d, *names, wait=True):
    cmd = ["mpirun", "-n", str(n), sys.executable, DRIVER, str(d), *names]
    if not wait:
        return subprocess.Popen(cmd, cwd=ROOT, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    p = subprocess.run(cmd, cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=600)
    return p


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The serial runs (this process) and the runs on 2 and 3 ranks (one mpirun launch each)."""
    from fem_blocks import cli
    d = tmp_path_factory.mktemp("dist")
    dist_cases.write_cases(d, dist_cases.CASES)
    serial = {n: cli.main(["run", str(d / f"{n}.toml"), "--out", str(d / f"{n}.1"), "--quiet"]) for n in SERIAL}
    p2 = _mpirun(2, d, "dry", "mixed", "wall3d", "fail", "bad", "newton", "joints")
    p3 = _mpirun(3, d, "dry", "one_brick", "guard")
    logs = {2: p2.stdout + p2.stderr, 3: p3.stdout + p3.stderr}
    codes = {}
    for n in (2, 3):
        path = d / f"codes.{n}.json"
        assert path.exists(), logs[n][-3000:]
        codes[n] = json.loads(path.read_text())
    return d, serial, codes, logs


def _history(d, name, n):
    return (d / f"{name}.{n}" / "history.csv").read_bytes()


@pytest.mark.parametrize("n,name", [(2, "dry"), (2, "mixed"), (2, "wall3d"), (3, "dry"), (3, "one_brick"),
                                    (2, "joints")])
def test_history_on_n_ranks_is_the_serial_colour_order_history_bitwise(runs, n, name):
    d, serial, codes, logs = runs
    assert codes[n][name] == [serial[name]] * n, logs[n][-3000:]
    assert _history(d, name, n) == _history(d, name, 1)
    s = json.loads((d / f"{name}.{n}" / "summary.json").read_text())
    assert s["mpi_ranks"] == n
    assert s["contact"]["sweeps"] > 0


def test_the_runs_do_not_converge_trivially_and_ranks_share_contacts(runs):
    """The runs are worth comparing: the dry wall takes several sweeps per step, and on 3 ranks the PT-Scotch
    partition (in the checkpoint) gives every rank bodies and cuts some contacts (their two bodies on two ranks);
    the brick on its foundation leaves one of 3 ranks without a body."""
    d, serial, codes, logs = runs
    import csv
    rows = list(csv.DictReader(open(d / "dry.3" / "history.csv")))
    assert min(int(r["sweeps"]) for r in rows[1:]) >= 5
    pieces = [np.load(d / "dry.3" / f"checkpoint.rank{p}.npz") for p in range(3)]
    owner = pieces[0]["contact.body_owner"]
    assert set(owner.tolist()) == {0, 1, 2}
    cand, ant, key, ids = (np.concatenate([ck[k] for ck in pieces])
                           for k in ("contact.cs.cand_body", "contact.cs.ant_body", "contact.cs.key",
                                     "part.contact_ids"))
    assert np.count_nonzero(owner[cand] != owner[ant]) > 0
    assert np.unique(ids).size == ids.size == int(pieces[0]["part.n_contacts"])  # each contact in one piece
    assert np.array_equal(ids, key * owner.size + ant)  # (its id: key · nb + antagonist body)
    for p, ck in enumerate(pieces):  # the piece of rank p: its contacts and bodies, with the partition
        assert np.array_equal(ck["part.body_owner"], owner)
        assert np.all(owner[ck["contact.cs.cand_body"]] == p) and len(ck["contact.P"]) == len(ck["part.contact_ids"])
        assert {int(k.split(".")[1][4:]) for k in ck.files if k.startswith("sim.body")} == \
            set(np.flatnonzero(owner == p).tolist())
    ck1 = np.load(d / "one_brick.3" / "checkpoint.rank0.npz")
    assert len(set(ck1["contact.body_owner"].tolist())) <= 2  # two bodies on three ranks


def test_newton_on_2_ranks_matches_the_serial_newton(runs):
    """solver = "newton": every rank runs the Newton iteration, its linear solves J Δr = -F shared (a PETSc block
    matrix with the rows of each rank's contacts, MUMPS) instead of the serial block LU: the same solution within
    the solver's tolerance (1e-8 on the residual): the history's displacements, energies and reactions within 1e-6
    of their column's scale, the same exit status on both ranks."""
    import csv
    d, serial, codes, logs = runs
    assert codes[2]["newton"] == [serial["newton"]] * 2, logs[2][-3000:]
    a = list(csv.DictReader(open(d / "newton.1" / "history.csv")))
    b = list(csv.DictReader(open(d / "newton.2" / "history.csv")))
    assert len(a) == len(b) > 3
    skip = {"sweeps", "change", "residual", "closed", "slip"}  # counts of P_N > 0: a contact at 0 may flip
    for k in a[0]:
        if k in skip or not a[0][k]:
            continue
        x = np.array([float(r[k]) for r in a])
        y = np.array([float(r[k]) for r in b])
        scale = max(np.max(np.abs(x)), 1e-30)
        assert np.max(np.abs(x - y)) <= 1e-6 * scale, k
    assert [r["contacts"] for r in a] == [r["contacts"] for r in b]


def test_exit_status_is_the_same_on_every_rank(runs):
    """A solver-policy stop exits 1 and invalid input 2, on every rank, as on one process; rank 0 alone writes."""
    d, serial, codes, logs = runs
    assert serial["fail"] == 1 and serial["bad"] == 2
    assert codes[2]["fail"] == [1, 1] and codes[2]["bad"] == [2, 2]
    assert json.loads((d / "fail.2" / "summary.json").read_text())["exit_status"] == 1
    assert (d / "dry.2" / "paraview" / "blocks.pvd").exists()


def test_a_run_check_stops_every_rank_naming_the_serial_contact(runs):
    """The penetration check on 3 ranks ([checks] max_penetration below the first step's penetrations): each rank
    checks the rows of its own contacts and the ranks agree on the contact to name (runner._Guards._agree), the one
    one process names (the worst ratio of penetration to bound, the first among equals). Expectation: the serial
    run's stop message (contact number, bodies, depth, bound) and exit status 1 on every rank."""
    d, serial, codes, logs = runs
    assert serial["guard"] == 1 and codes[3]["guard"] == [1, 1, 1]
    one, three = (json.loads((d / f"guard.{n}" / "summary.json").read_text())["status"] for n in (1, 3))
    assert "penetration" in one and "at contact" in one
    assert three.replace(str(d / "guard.3"), "OUT") == one.replace(str(d / "guard.1"), "OUT")


def _wait_for_pieces(p, out, n):
    """Wait until every rank of the launch `p` has written a checkpoint piece in `out`."""
    t0 = time.time()
    while not all((out / f"checkpoint.rank{r}.npz").exists() for r in range(n)) and p.poll() is None \
            and time.time() - t0 < 300:
        time.sleep(0.02)


def test_resume_after_sigkill_of_one_rank_is_bitwise_the_uninterrupted_run(runs):
    """Killed on 2 ranks, resumed on 2 ranks from the pieces (checkpoint.rank<p>.npz) and, from a copy, on one
    process (the pieces merged): both give the serial history byte for byte."""
    from fem_blocks import cli
    d, serial, codes, logs = runs
    out = d / "long.2"
    p = _mpirun(2, d, "long", wait=False)
    _wait_for_pieces(p, out, 2)
    assert p.poll() is None, "the run ended before its first checkpoint"
    ranks = subprocess.run(["pgrep", "-P", str(p.pid)], capture_output=True, text=True).stdout.split()
    assert ranks, "no rank process found"
    os.kill(int(ranks[-1]), signal.SIGKILL)
    p.communicate(timeout=120)
    assert p.returncode != 0
    rows = (out / "history.csv").read_bytes().count(b"\n") if (out / "history.csv").exists() else 0
    full = _history(d, "long", 1).count(b"\n")
    assert rows < full  # killed before the end
    assert not (out / "checkpoint.npz").exists()
    one = d / "long.2to1"
    shutil.copytree(out, one)
    assert cli.main(["run", str(d / "long.toml"), "--out", str(one), "--quiet", "--resume"]) == serial["long"]
    assert (one / "history.csv").read_bytes() == _history(d, "long", 1)
    r = _mpirun(2, d, "long", "--resume")
    assert json.loads((d / "codes.2.resume.json").read_text())["long"] == [serial["long"]] * 2, \
        (r.stdout + r.stderr)[-3000:]
    assert _history(d, "long", 2) == _history(d, "long", 1)
    # the ParaView series cut back to the checkpoint and continued: the serial frames, bitwise, and no piece left
    # over that no .pvtu lists
    assert _check_pieces(d, "long", 2) == len(_frames(d / "long.1" / "paraview" / "blocks.pvd"))
    pv = d / "long.2" / "paraview"
    import xml.etree.ElementTree as ET
    listed = {p.get("Source") for _, f in _frames(pv / "blocks.pvd") for p in ET.parse(pv / f).getroot().iter("Piece")}
    assert {f.name for f in pv.glob("blocks_*_p*.vtu")} == listed


# ---------------------------------------------------------------- ParaView pieces (one .pvtu per frame)

def _read_vtu(path):
    """(points, [(vtk cell type, connectivity)] per cell, point data, cell data) of a .vtu, by VTK's own reader."""
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(str(path))
    r.Update()
    assert r.GetErrorCode() == 0, f"VTK could not read {path}"
    g = r.GetOutput()
    pts = vtk_to_numpy(g.GetPoints().GetData())
    cells = []
    for i in range(g.GetNumberOfCells()):
        c = g.GetCell(i)
        cells.append((g.GetCellType(i), tuple(c.GetPointId(j) for j in range(c.GetNumberOfPoints()))))
    pd, cd = g.GetPointData(), g.GetCellData()
    pdat = {pd.GetArrayName(i): vtk_to_numpy(pd.GetArray(i)) for i in range(pd.GetNumberOfArrays())}
    cdat = {cd.GetArrayName(i): vtk_to_numpy(cd.GetArray(i)) for i in range(cd.GetNumberOfArrays())}
    return pts, cells, pdat, cdat


def _by_body(path):
    """Body id -> its part of the grid, independent of where the body sits in the file: its cells (type and
    connectivity renumbered over its own points, in file order), its points' coordinates and point data, its
    cells' data (rows in file order)."""
    pts, cells, pdat, cdat = _read_vtu(path)
    out = {}
    for b in np.unique(cdat["body_id"]):
        rows = np.flatnonzero(cdat["body_id"] == b)
        used = np.unique(np.concatenate([np.array(cells[i][1], dtype=np.int64) for i in rows]))
        new = {int(p): k for k, p in enumerate(used)}
        out[int(b)] = dict(cells=[(cells[i][0], tuple(new[p] for p in cells[i][1])) for i in rows],
                           points=pts[used], **{f"p.{k}": v[used] for k, v in pdat.items()},
                           **{f"c.{k}": v[rows] for k, v in cdat.items()})
    return out, len(pts), len(cells)


def _frames(pvd):
    import xml.etree.ElementTree as ET
    return [(float(e.get("timestep")), e.get("file")) for e in ET.parse(pvd).getroot().iter("DataSet")]


def _partition(out, n):
    """The rank of each body in the checkpoint pieces of the run in `out` (None without a checkpoint)."""
    path = out / "checkpoint.rank0.npz"
    if not path.exists():
        return None
    with np.load(path) as z:
        return np.array(z["contact.body_owner"]) if "contact.body_owner" in z else None


def _check_pieces(d, name, n):
    """The ParaView series of the run on n ranks against the serial run's; returns the number of frames."""
    import xml.etree.ElementTree as ET
    import vtk
    ser = d / f"{name}.1" / "paraview"
    par = d / f"{name}.{n}" / "paraview"
    fs, fp = _frames(ser / "blocks.pvd"), _frames(par / "blocks.pvd")
    assert [t for t, _ in fp] == [t for t, _ in fs] and len(fs) >= 2
    nb = len(_by_body(ser / fs[0][1])[0])
    blocks = [list(range(p * nb // n, (p + 1) * nb // n)) for p in range(n)]  # the first frame's pieces
    owner = _partition(d / f"{name}.{n}", n)  # the pieces after it: the partition's, when a checkpoint holds it
    split = [list(np.flatnonzero(owner == p)) for p in range(n)] if owner is not None else None
    later = None
    for f, ((_, vtu), (_, pvtu)) in enumerate(zip(fs, fp)):
        assert pvtu.endswith(".pvtu") and (par / pvtu).exists()
        root = ET.parse(par / pvtu).getroot()  # the PUnstructuredGrid structure and the serial file's arrays
        assert root.tag == "VTKFile" and root.get("type") == "PUnstructuredGrid"
        g = root.find("PUnstructuredGrid")
        sroot = ET.parse(ser / vtu).getroot().find("UnstructuredGrid/Piece")
        for ptag, tag in (("PPointData", "PointData"), ("PCellData", "CellData"), ("PPoints", "Points")):
            decl = [(a.get("Name"), a.get("type"), a.get("NumberOfComponents", "1")) for a in g.find(ptag)]
            have = [(a.get("Name"), a.get("type"), a.get("NumberOfComponents", "1")) for a in sroot.find(tag)]
            if ptag == "PPoints":
                decl, have = [x[1:] for x in decl], [x[1:] for x in have]
            assert decl == have, (ptag, decl, have)
        sources = [p.get("Source") for p in g.findall("Piece")]
        ranks = [int(s.rsplit("_p", 1)[1][:-4]) for s in sources]
        assert sources == [pvtu[:-5] + f"_p{p}.vtu" for p in ranks] and ranks == sorted(set(ranks))  # rank order
        whole, n_pts, n_cells = _by_body(ser / vtu)
        got, n_pts2, n_cells2, pieces = {}, 0, 0, {}
        for s, p in zip(sources, ranks):
            assert (par / s).exists()
            part, a, b = _by_body(par / s)
            assert part and not set(part) & set(got)  # a listed piece holds bodies, each body in one piece
            pieces[p] = sorted(part)
            got.update(part)
            n_pts2, n_cells2 = n_pts2 + a, n_cells2 + b
        assert (n_pts2, n_cells2) == (n_pts, n_cells) and sorted(got) == sorted(whole)
        if f == 0 or split is not None:
            assert pieces == {p: b for p, b in enumerate(blocks if f == 0 else split) if b}, (pvtu, pieces)
        else:  # (no checkpoint: one partition, so the same pieces in every frame after the first)
            later = later or pieces
            assert pieces == later, (pvtu, pieces, later)
        for b in whole:
            assert whole[b].keys() == got[b].keys()
            for k in whole[b]:
                if k == "cells":
                    assert got[b][k] == whole[b][k], (pvtu, b)
                else:  # bitwise
                    assert whole[b][k].dtype == got[b][k].dtype and np.array_equal(whole[b][k], got[b][k]), \
                        (pvtu, b, k)
        r = vtk.vtkXMLPUnstructuredGridReader()  # ParaView's reader of .pvtu files
        r.SetFileName(str(par / pvtu))
        r.Update()
        assert r.GetErrorCode() == 0 and r.GetOutput().GetNumberOfCells() == n_cells
    return len(fp)


@pytest.mark.parametrize("n,name", [(2, "dry"), (3, "dry"), (2, "wall3d"), (3, "one_brick"), (2, "joints")])
def test_paraview_pieces_per_rank_are_the_serial_grid(runs, n, name):
    """On N ranks blocks.pvd lists one .pvtu per frame (the serial run's times); each .pvtu declares the serial
    .vtu's arrays (names, VTK types, components), lists in rank order the pieces blocks_<frame>_p<rank>.vtu of the
    ranks with bodies (one_brick on 3 ranks: a rank has none), which exist; piece p holds, in the first frame, the
    bodies [p nb / N, (p + 1) nb / N), and in the later frames rank p's bodies of the partition (the checkpoint's
    contact.body_owner in the resume test; else the same pieces in each frame), each body in one piece, and, body by
    body, the serial file's cells, points, point and cell data BITWISE;
    VTK's parallel reader (ParaView's) reads the .pvtu with the serial number of cells.
    One-line bugs this catches (checked): every rank writing the piece of all bodies (piece_bodies returning
    range(nb): the pieces' bodies overlap); array_info without write_vtu's padding of 2-vectors (the .pvtu declares
    2 components, the pieces hold 3); rank 0 listing a piece for every rank (one_brick: rank 0 has none).
    In the resume test: the ranks other than 0 counting frames from 0 after --resume (their pieces overwrite the
    first frames: frame 0 differs from the serial one)."""
    d, serial, codes, logs = runs
    assert codes[n][name] == [serial[name]] * n, logs[n][-3000:]
    assert not list((d / f"{name}.1" / "paraview").glob("*.pvtu"))  # one process: the serial files
    _check_pieces(d, name, n)

def _contact_rows(path):
    """The contacts of a contacts .vtu as rows of floats, each a contact's point then its point arrays (by name),
    sorted (a piece holds a rank's own contacts; the order of the rows is not compared), and the arrays' names."""
    import xml.etree.ElementTree as ET
    if ET.parse(path).getroot().find("UnstructuredGrid/Piece").get("NumberOfPoints") == "0":
        return np.zeros((0, 0)), []
    pts, _, pdat, _ = _read_vtu(path)
    n = len(pts)
    rows = np.hstack([pts.reshape(n, -1)] + [np.asarray(pdat[k], dtype=float).reshape(n, -1) for k in sorted(pdat)])
    return rows[np.lexsort(rows.T[::-1])], sorted(pdat)


@pytest.mark.parametrize("n,name", [(2, "dry"), (3, "dry"), (2, "wall3d")])
def test_contact_pieces_per_rank_are_the_serial_contacts(runs, n, name):
    """On N ranks contacts.pvd lists one .pvtu per frame at the serial run's times; each rank writes the piece of its
    own contacts (its record's rows), the ranks with no contact none (a frame without contacts: rank 0's empty piece);
    the pieces of a frame hold, contact by contact, the serial frame's points and point arrays bitwise, each contact
    once; VTK's parallel reader reads every contact. One-line bugs this catches (checked): every rank writing the
    rows of every contact (each contact N times)."""
    import xml.etree.ElementTree as ET
    import vtk
    d, serial, codes, logs = runs
    ser, par = d / f"{name}.1" / "paraview", d / f"{name}.{n}" / "paraview"
    fs, fp = _frames(ser / "contacts.pvd"), _frames(par / "contacts.pvd")
    assert [t for t, _ in fp] == [t for t, _ in fs] and len(fs) >= 2
    shared = 0
    for (_, vtu), (_, pvtu) in zip(fs, fp):
        assert pvtu.endswith(".pvtu")
        sources = [p.get("Source") for p in ET.parse(par / pvtu).getroot().find("PUnstructuredGrid").findall("Piece")]
        whole, names = _contact_rows(ser / vtu)
        parts = [_contact_rows(par / s) for s in sources]
        if len(whole) == 0:
            assert sources == [pvtu[:-5] + "_p0.vtu"] and len(parts[0][0]) == 0
            continue
        assert all(nm == names for _, nm in parts) and len(parts) >= 2  # the contacts are shared among ranks
        shared += 1
        got = np.vstack([a for a, _ in parts])
        assert np.array_equal(got[np.lexsort(got.T[::-1])], whole), pvtu
        reader = vtk.vtkXMLPUnstructuredGridReader()  # ParaView's reader of .pvtu files
        reader.SetFileName(str(par / pvtu))
        reader.Update()
        assert reader.GetErrorCode() == 0 and reader.GetOutput().GetNumberOfPoints() == len(whole)
    assert shared >= 1


def test_joint_outputs_on_2_ranks_are_the_serial_files(runs):
    """`[output] joints` and `joints_paraview` on 2 ranks: the joints' resultants come from the record of every
    contact, gathered by every rank (ContactResult.whole()), at the contacts' current points computed by their owners
    (runner.joints_record), and rank 0 writes joints.pvd. Expectation: the serial run's joints.pvd and every frame's
    .vtu, byte for byte (the history's joint columns: the bitwise history test)."""
    d, serial, codes, logs = runs
    assert codes[2]["joints"] == [serial["joints"]] * 2, logs[2][-3000:]
    ser, par = d / "joints.1" / "paraview", d / "joints.2" / "paraview"
    frames = _frames(ser / "joints.pvd")
    assert len(frames) >= 2 and _frames(par / "joints.pvd") == frames
    for _, f in frames:
        assert (par / f).read_bytes() == (ser / f).read_bytes(), f
    assert "brick0|brick4.N" in (d / "joints.2" / "history.csv").read_text().splitlines()[0]


def test_bodies_stepped_per_rank_give_the_serial_outputs(runs):
    """The "joints" wall on 2 ranks (frozen geometry): each rank steps only its bodies, those of its own contacts and
    the bodies the outputs read at every step (dynamics.py "Bodies stepped per rank"). Found here from the partition
    and the contact set of the last checkpoint: each rank leaves bodies unstepped, among them bodies of a gauge, of a
    rotation column and of a listed joint. Expectation: the serial run's history (gauges, rotations, joints: the
    bitwise history test), joints.pvd (test above), blocks.pvd pieces (test above) and figures at the end (rank 0
    receives every body's state: Simulation.collect_bodies), byte for byte. One-line bugs this catches (checked): the
    gauges' and rotations' bodies not shared (their columns NaN on rank 0); the joints' points computed by rank 0 for
    every contact (NaN); rank 0 not collecting the bodies before the figures."""
    d, serial, codes, logs = runs
    assert codes[2]["joints"] == [serial["joints"]] * 2, logs[2][-3000:]
    with np.load(d / "joints.2" / "checkpoint.rank0.npz") as z:
        owner, cand, ant = (np.array(z[k]) for k in ("contact.body_owner", "contact.cs.cand_body",
                                                      "contact.cs.ant_body"))
    summary = json.loads((d / "joints.2" / "summary.json").read_text())
    read = {0, 21, 3, 18, 4}  # brick0 and brick21 (gauges), brick3 and brick18 (rotations); brick0, brick4 (a joint)
    unstepped = set()
    for p in range(2):
        B = owner == p
        mine = owner[cand] == p
        B[cand[mine]] = B[ant[mine]] = True
        assert not B.all()
        unstepped |= set(np.flatnonzero(~B))
    assert unstepped & read and summary["n_bodies"] == len(owner)
    for f in ("crack_pattern.png", "rotations.png"):
        assert (d / "joints.2" / f).read_bytes() == (d / "joints.1" / f).read_bytes(), f


def test_sigterm_to_one_rank_stops_every_rank_at_the_same_step(runs):
    """SIGTERM reaches one rank only: the ranks decide together, once per step, so every rank finishes the same
    step, every rank writes its checkpoint piece and every rank exits with 143. Catches each rank acting on its own
    signal (checked: rank 1 stops, rank 0 waits for it in the next sweep's exchange: the launch hangs and times
    out)."""
    d, serial, codes, logs = runs
    out = d / "long.2"
    shutil.rmtree(out, ignore_errors=True)
    p = _mpirun(2, d, "long", wait=False)
    _wait_for_pieces(p, out, 2)
    assert p.poll() is None, "the run ended before its first checkpoint"
    ranks = subprocess.run(["pgrep", "-P", str(p.pid)], capture_output=True, text=True).stdout.split()
    os.kill(int(ranks[-1]), signal.SIGTERM)
    try:
        p.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        p.kill()
        p.communicate()
        pytest.fail("the ranks did not stop together after SIGTERM to one of them")
    assert json.loads((d / "codes.2.json").read_text())["long"] == [143, 143]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] == 143 and "signal 15" in summary["status"]
    rows = (out / "history.csv").read_bytes()
    assert rows == _history(d, "long", 1)[:len(rows)]  # the steps done are the serial steps

