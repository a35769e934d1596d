"""The contact step returns its result (contact/result.py) and writes nothing into the simulation's objects; the
simulation applies the corrections and keeps the record; the record owns its arrays; the in-memory history of the
HistoryWriter equals what read_history reads back from the file."""
import numpy as np
import pytest

from fem_blocks.bodies import (BlockType, BlockType3D, DeformableBody, DeformableBody3D, Driver, Material,
                               RigidBody, RigidBody3D)
from fem_blocks.contact.result import ContactResult
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.meshing import box_corners, mesh_box, mesh_rectangle
from fem_blocks.output.history import HistoryWriter, read_history

pytestmark = pytest.mark.dolfinx


def scene_2d():
    """A deformable block (a group) and a rigid block resting on a fixed rigid floor: contacts with both kinds."""
    bt = BlockType(mesh_rectangle(0.4, 0.2, 0.1), Material(E=1e9, nu=0.2, rho=1000.0, thickness=1.0))
    blk = DeformableBody(bt, position=(0.0, 0.0))
    rig = RigidBody(np.array([[0.6, 0.0], [1.0, 0.0], [1.0, 0.2], [0.6, 0.2]]), rho=1000.0)
    floor = RigidBody(np.array([[-1.0, -0.5], [2.0, -0.5], [2.0, 0.0], [-1.0, 0.0]]),
                      drivers={k: Driver("velocity", 0.0) for k in ("x", "y", "rz")})
    cst = ContactStep([InterfaceSpec("i", ("block", "ground"), mu=0.5)], ["block", "block", "ground"],
                      ContactOptions(tol=1e-10, max_sweeps=2000))
    return Simulation([blk, rig, floor], h=1e-3, theta=0.5, contact=cst), cst


def scene_3d():
    bt = BlockType3D(mesh_box(0.5, 0.5, 0.25, divisions=(1, 1, 1)), Material(1e8, 0.2, 2000.0))
    blk = DeformableBody3D(bt, position=(-0.25, -0.25, 0.0))
    rig = RigidBody3D.box(0.4, 0.4, 0.2, origin=(0.6, -0.2, 0.0), rho=2000.0)
    floor = RigidBody3D(box_corners(4.0, 4.0, 1.0, (-2.0, -2.0, -1.0)),
                        drivers={k: Driver("velocity", 0.0) for k in ("x", "y", "z", "rx", "ry", "rz")})
    cst = ContactStep([InterfaceSpec("j", ("block", "floor"), mu=0.5, candidate="block")],
                      ["block", "block", "floor"], ContactOptions(tol=1e-10, criterion="residual", max_sweeps=5000))
    return Simulation([blk, rig, floor], 1e-3, 0.5, contact=cst), cst


def _snapshot(objs):
    """Per object: its attribute names -> (identity, copy of an array's values)."""
    out = []
    for o in objs:
        out.append({k: (id(v), np.array(v, copy=True) if isinstance(v, np.ndarray) else None)
                    for k, v in vars(o).items()})
    return out


@pytest.mark.parametrize("make", [scene_2d, scene_3d], ids=["2d", "3d"])
def test_contact_solve_writes_nothing_into_the_simulation(make):
    """ContactStep.solve reads the simulation and returns a record: no attribute of a body, a group or the
    simulation is added, rebound or changed in place during the solve (the old scene wrote gr.Ucorr, b.ucorr,
    b.contact_impulse); then Simulation.step applies the corrections and keeps the record."""
    sim, cst = make()
    sim.step()  # contact set detected, state allocated
    seen = []
    solve = cst.solve

    def watched(s, t0, t1):
        objs = [s] + list(s.bodies) + list(s.groups)
        before = _snapshot(objs)
        res = solve(s, t0, t1)
        after = _snapshot(objs)
        for o, b, a in zip(objs, before, after):
            assert set(a) == set(b), f"{type(o).__name__}: attributes added {sorted(set(a) - set(b))}"
            for k in b:
                assert a[k][0] == b[k][0], f"{type(o).__name__}.{k} rebound by the contact step"
                if b[k][1] is not None:
                    assert np.array_equal(a[k][1], b[k][1], equal_nan=True), \
                        f"{type(o).__name__}.{k} changed in place by the contact step"
        seen.append(res)
        return res
    cst.solve = watched
    info = sim.step()
    assert len(seen) == 1 and sim.last_contact is seen[0] and isinstance(seen[0], ContactResult)
    res = seen[0]
    assert info.contact is res.stats and res.stats["contacts"] == len(res.cs.gap) > 0
    assert res.stats["active"] > 0  # both blocks rest on the floor
    assert len(res.group_corr) == len(sim.groups) and res.rigid_corr.shape == (len(sim.rigid), sim.rigid_ndof)
    # the simulation applied the record's correction: a rigid body's impulse reaches its reaction (the floor)
    k = sim.rigid.index(2)
    assert np.any(res.rigid_impulse[k] != 0.0)


@pytest.mark.parametrize("make", [scene_2d, scene_3d], ids=["2d", "3d"])
def test_record_arrays_are_not_aliased_to_the_next_step(make):
    """The record of step k keeps its values through step k+1 (the contact step updates its warm start and law
    state in place) and shares no memory with the step's buffers."""
    sim, cst = make()
    for _ in range(3):
        sim.step()
    res = sim.last_contact
    names = ("P", "r", "v", "gt_end", "status", "law", "state")
    kept = {k: np.array(getattr(res, k), copy=True) for k in names}
    sim.step()
    new = sim.last_contact
    assert new is not res
    for k in names:
        assert np.array_equal(getattr(res, k), kept[k]), k
        assert not np.shares_memory(getattr(res, k), getattr(new, k)), k
    assert not np.shares_memory(new.P, cst.P) and not np.shares_memory(new.state, cst.state)
    assert not np.array_equal(new.P, res.P)  # the step did change the impulses (a test that sees a change)


def test_history_in_memory_equals_the_file(tmp_path):
    """HistoryWriter(keep=True).columns_dict() gives exactly what read_history reads back from the file (None ->
    NaN, bool -> 0/1, ints, floats at full precision), also after a resume that cuts the file back."""
    cols = ["step", "time", "h", "converged", "x"]
    rows = [dict(step=0, time=0.0, h=None, converged=True, x=-0.0),
            dict(step=1, time=0.1, h=0.1, converged=False, x=1 / 3),
            dict(step=2, time=0.30000000000000004, h=0.2, converged=1, x=np.float64(2.0) ** -1074),
            dict(step=3, time=0.4, h=0.1, converged=1, x=np.nan)]
    p = tmp_path / "history.csv"
    with HistoryWriter(p, cols, keep=True) as w:
        for r in rows:
            w.write(r)

    def same(a, b):
        assert set(a) == set(b)
        for c in a:
            assert a[c].dtype == b[c].dtype and np.array_equal(a[c], b[c], equal_nan=True), c
            assert np.array_equal(np.signbit(a[c]), np.signbit(b[c])), c
    same(w.columns_dict(), read_history(p))
    w2 = HistoryWriter.resume(p, 1, columns=cols, keep=True)
    w2.write(dict(step=2, time=0.25, h=0.15, converged=1, x=7.0))
    w2.close()
    mem = w2.columns_dict()
    assert list(mem["step"]) == [0, 1, 2] and mem["x"][2] == 7.0
    same(mem, read_history(p))


def test_record_of_a_step_without_contacts():
    """No contact detected (a block 1 m above the floor): the record still carries the (empty) law state, so the
    summary's dissipated energy is 0 rather than missing, no correction for the group, and zero rigid impulses."""
    bt = BlockType(mesh_rectangle(0.4, 0.2, 0.1), Material(E=1e9, nu=0.2, rho=1000.0, thickness=1.0))
    blk = DeformableBody(bt, position=(0.0, 1.0))
    floor = RigidBody(np.array([[-1.0, -0.5], [2.0, -0.5], [2.0, 0.0], [-1.0, 0.0]]),
                      drivers={k: Driver("velocity", 0.0) for k in ("x", "y", "rz")})
    cst = ContactStep([InterfaceSpec("i", ("block", "ground"), mu=0.5)], ["block", "ground"])
    sim = Simulation([blk, floor], h=1e-3, theta=0.5, contact=cst)
    info = sim.step()
    res = sim.last_contact
    assert info.contact["contacts"] == 0 and info.contact["solver"] == "none"
    assert res.state is not None and res.state.shape[0] == 0 and float(res.state.sum()) == 0.0
    assert res.group_corr == [None] and not res.has_contacts()
    assert res.rigid_impulse.shape == (1, 3) and not np.any(res.rigid_impulse)
