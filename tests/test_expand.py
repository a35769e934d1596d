"""Parse → expand: `load_case`/`parse_case` keep [wall]/[arch]/[wall3d]/[dome] as specs (no geometry), and
`expand(case)` adds their block types, blocks and rigid bodies (docs/architecture.md "Parse → expand → build").

Expectations by hand from the keys of the small cases below (counts, names, halved resolutions), never from the
code under test. Fast: no meshing, no run."""
import copy
import json
import subprocess
import sys

import pytest

from fem_blocks.case import parse_case, quick, rigid_specs
from fem_blocks.errors import InputError
from fem_blocks.expand import expand

STAGES = [{"h": 0.001, "duration": 0.002}]
MAT = {"m": {"E": 5e9, "nu": 0.2, "rho": 1800.0, "thickness": 0.1}}
WALL = {"materials": MAT, "stages": STAGES,
        "wall": {"material": "m", "type": "prism", "bricks": 3, "brick_length": 0.2, "brick_height": 0.1,
                 "joint": 0.01, "mesh_size": 0.05,
                 "foundation": {"depth": 0.1, "split": [0.1],
                                "settlement": {"part": 1, "history": {"times": [0, 1], "values": [0, -0.001]}}},
                 "beam": {"depth": 0.1, "rho": 2000.0}},
        "interfaces": [{"between": ["bricks", "bricks"], "mu": 0.6}, {"between": ["bricks", "foundation"], "mu": 0.6},
                       {"between": ["bricks", "beam"], "mu": 0.6}]}
DOME = {"dimension": 3, "materials": {"m": {"E": 5e9, "nu": 0.2, "rho": 1800.0}}, "stages": STAGES,
        "dome": {"material": "m", "courses": 2, "blocks_per_course": 8, "divisions": [3, 2, 2], "piers": 2,
                 "pier_blocks": 1, "running_bond": False}}


def test_parse_keeps_the_generators_as_given():
    # one-line bug caught: a parse that still generates (case.blocks filled) or forgets the foundation's parts
    case = parse_case(copy.deepcopy(WALL), "case.toml")
    assert case.blocks == [] and case.block_types == {} and case.rigid_bodies == [] and not case.expanded
    (g,) = case.generators
    assert (g.key, g.kind, g.bricks, g.mesh_size) == ("wall", "prism", 3, 0.05)
    # the rigid bodies it will make are known (names, drivers) before their geometry
    rigid = rigid_specs(case)
    assert [r.name for r in rigid] == ["foundation0", "foundation1", "beam"]
    assert all(r.vertices is None for r in rigid)
    assert rigid[0].drivers["y"] == ("velocity", 0.0) and rigid[1].drivers["y"][0] == "displacement"
    assert rigid[2].thickness == 0.1 and rigid[2].rho == 2000.0  # the beam is as thick as the wall


def test_expand_adds_the_bodies_and_leaves_the_parsed_case():
    # bugs caught: expand writing into the parsed case, or expanding twice (duplicate bricks)
    case = parse_case(copy.deepcopy(WALL), "case.toml")
    ex = expand(case)
    assert case.blocks == [] and case.rigid_bodies == [] and len(case.generators) == 1
    assert [b.name for b in ex.blocks] == ["brick0", "brick1", "brick2"]  # a prism of 3 bricks
    assert [r.name for r in ex.rigid_bodies] == ["foundation0", "foundation1", "beam"]
    assert all(r.vertices is not None for r in ex.rigid_bodies)
    assert ex.expanded and ex.generators == [] and expand(ex) is ex
    assert [r.name for r in rigid_specs(ex)] == ["foundation0", "foundation1", "beam"]


def test_geometry_errors_come_from_expand_naming_file_and_key():
    # the foundation cut is checked against the wall's extent, which only expand knows
    d = copy.deepcopy(WALL)
    d["wall"]["foundation"]["split"] = [5.0]
    case = parse_case(d, "case.toml")  # valid as given
    with pytest.raises(InputError, match=r"^case\.toml: wall\.foundation\.split: cut at x = 5 m outside"):
        expand(case)
    d = copy.deepcopy(WALL)
    d["blocks"] = [{"type": "t", "name": "brick1", "position": [5.0, 5.0]}]
    d["block_types"] = {"t": {"geometry": "rectangle", "lx": 0.2, "ly": 0.1, "mesh_size": 0.1, "material": "m"}}
    with pytest.raises(InputError, match=r"^case\.toml: wall\.group: body name 'brick1' already used"):
        expand(parse_case(d, "case.toml"))


def test_quick_before_or_after_expand_halves_the_same_resolutions():
    # 2D: mesh_size x 2; 3D: divisions ceil(n / 2) -> [3, 2, 2] becomes (2, 1, 1)
    a = expand(quick(parse_case(copy.deepcopy(WALL), "case.toml")))
    b = quick(expand(parse_case(copy.deepcopy(WALL), "case.toml")))
    assert {bt.mesh_size for bt in a.block_types.values()} == {0.1} == {bt.mesh_size for bt in b.block_types.values()}
    a = expand(quick(parse_case(copy.deepcopy(DOME), "case.toml")))
    b = quick(expand(parse_case(copy.deepcopy(DOME), "case.toml")))
    assert len(a.block_types) == 2 and len(a.blocks) == 16  # one block type per course, 2 x 8 voussoirs
    assert {bt.divisions for bt in a.block_types.values()} == {(2, 1, 1)} == \
        {bt.divisions for bt in b.block_types.values()}
    assert [r.name for r in a.rigid_bodies] == ["pier0", "pier1"] and a.rigid_bodies[0].group == "piers"


def test_the_input_layer_imports_no_geometry_or_model_module():
    # bug caught: case.py importing a builder (or bodies, meshing, ...) again, even inside a function run at load
    code = ("import json, sys\nfrom fem_blocks.case import parse_case\n"
            f"parse_case(json.loads({json.dumps(WALL)!r}), 'a.toml')\n"
            f"parse_case(json.loads({json.dumps(DOME)!r}), 'b.toml')\n"
            "print(json.dumps(sorted(m for m in sys.modules if m.startswith('fem_blocks.'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    loaded = {m.split(".")[1] for m in json.loads(out.stdout)}
    assert "case" in loaded and not loaded & {"builders", "builders3d", "bodies", "meshing", "fem_backend", "model",
                                              "expand", "dynamics", "contact", "solver", "runner"}, loaded
