"""Potential brick cracks: [wall] split_bricks replaces every full brick by two halves joined by the pair's
interface of orientation "crack" (Lourenço's micro-model)."""

import numpy as np
import pytest

from fem_blocks import builders
from fem_blocks.case import load_case
from fem_blocks.expand import expand
from fem_blocks.errors import InputError


CASE = """
name = "split"
[materials.brick]
E = 16.7e9
nu = 0.15
rho = 2500.0
thickness = 0.1
[wall]
type = "running_bond"
material = "brick"
brick_length = 0.21
brick_height = 0.052
joint = 0.01
expanded = true
courses = 3
bricks_per_course = 2
mesh_size = 0.055
cell = "quad"
split_bricks = true
[wall.foundation]
depth = 0.1
[contact]
solver = "newton"
criterion = "residual"
tol = 1e-10
[[interfaces]]
name = "joints"
between = ["bricks", "bricks"]
placement = "nodes"
mu = 0.75
[[interfaces]]
name = "cracks"
between = ["bricks", "bricks"]
orientation = "crack"
placement = "nodes"
law = "fremond"
c_N = 1e12
c_T = 1e12
w = 4.0
mu = 1.0
[[interfaces]]
name = "base"
between = ["bricks", "foundation"]
placement = "nodes"
mu = 0.75
[[stages]]
name = "gravity"
duration = 0.2
h = 1e-3
theta = 1.0
velocity_reset = true
output_every = 100
[stages.stop_at_equilibrium]
max_velocity = 1e-9
min_steps = 5
"""


def test_split_bricks_halves_full_bricks_only():
    lay = builders.running_bond(2, 3, 0.22, 0.062, expanded=True)
    split = builders.split_bricks(lay, 0.22)
    full = [b for b in lay if b.length >= 0.75 * 0.22]
    assert len(split) == len(lay) + len(full)
    assert sum(b.length * b.height for b in split) == pytest.approx(sum(b.length * b.height for b in lay), rel=1e-14)
    parents = [b.parent for b in split if b.parent >= 0]
    assert sorted(set(parents)) == [k for k, b in enumerate(lay) if b.length >= 0.75 * 0.22]
    assert all(parents.count(p) == 2 for p in set(parents))
    builders.Layout(split).check_no_overlap()


def test_crack_contacts_take_the_crack_law_and_statics_hold(tmp_path):
    from fem_blocks.laws import FREMOND
    from fem_blocks.runner import run_case
    case_path = tmp_path / "c.toml"
    case_path.write_text(CASE)
    case = expand(load_case(str(case_path)))  # the bricks and their halves: expand
    s = run_case(case, str(tmp_path / "out"), progress=False)
    assert s["status"] == "completed"
    from fem_blocks.output.history import read_history
    h = read_history(tmp_path / "out" / "history.csv")
    weight = 2500.0 * 0.1 * 9.81 * sum(b.length for b in builders.running_bond(
        3, 2, 0.22, 0.062, expanded=True)) * 0.062
    assert h["foundation.Ry"][-1] == pytest.approx(weight, rel=1e-6)
    # the contacts of the last step: between halves of one brick <=> crack interface (Frémond law)
    from fem_blocks.model import build_model  # noqa: F401 (the run's model is not returned: rebuild the rule)
    ck = np.load(tmp_path / "out" / "checkpoint.npz")
    parent = {b.name: b.parent for b in case.blocks}
    names = [b.name for b in case.blocks] + [r.name for r in case.rigid_bodies]
    cand, ant, law = ck["contact.cs.cand_body"], ck["contact.cs.ant_body"], ck["contact.law"]
    pa = np.array([parent.get(names[i], -1) for i in cand])
    pb = np.array([parent.get(names[i], -1) for i in ant])
    same = (pa >= 0) & (pa == pb)
    assert same.sum() > 0
    assert np.all(law[same] == FREMOND) and np.all(law[~same] == 0)


@pytest.mark.parametrize("change, match", [
    (("expanded = true", "expanded = false"), "split_bricks: needs expanded = true"),
    (("split_bricks = true", "split_bricks = false"), "orientation 'crack' needs split bricks"),
    (('[[interfaces]]\nname = "joints"\nbetween = ["bricks", "bricks"]\nplacement = "nodes"\nmu = 0.75\n', ''),
     "needs the joint interface"),
])
def test_split_brick_case_errors(tmp_path, change, match):
    p = tmp_path / "c.toml"
    p.write_text(CASE.replace(*change))
    with pytest.raises(InputError, match=match):
        expand(load_case(str(p)))  # the crack interface is checked on the generated blocks
