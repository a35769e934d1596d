"""Case-file validation: every bad input gives an InputError naming the file, the key and the expectation."""
import copy
import os
import subprocess
import sys

import pytest

from fem_blocks.case import load_case, parse_case
from fem_blocks.errors import InputError

from _paths import ROOT  # noqa: E402

BASE = {
    "gravity": [0.0, -9.81],
    "materials": {"stone": {"E": 5e9, "nu": 0.2, "rho": 1800.0, "thickness": 0.1}},
    "block_types": {"beam": {"geometry": "rectangle", "lx": 1.0, "ly": 0.2, "mesh_size": 0.05,
                             "material": "stone"}},
    "blocks": [{"type": "beam", "clamps": [{"tag": "left"}]}],
    "rigid_bodies": [{"name": "base", "vertices": [[0, -1], [1, -1], [1, 0], [0, 0]],
                      "drivers": {"x": {"kind": "velocity", "history": 0.0},
                                  "y": {"kind": "displacement", "history": {"times": [0, 1], "values": [0, -0.01]}},
                                  "rz": {"kind": "velocity", "history": 0.0}}}],
    "stages": [{"name": "s1", "duration": 0.01, "h": 1e-3, "theta": 0.5}],
}


def mutate(path, value):
    d = copy.deepcopy(BASE)
    node = d
    for k in path[:-1]:
        node = node[k]
    if value is DELETE:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return d


DELETE = object()


def test_valid_case_parses_with_units():
    c = parse_case(copy.deepcopy(BASE), "case.toml")
    assert c.materials["stone"].E == 5e9
    assert c.rigid_bodies[0].mass is None and len(c.rigid_bodies[0].drivers) == 3
    assert c.stages[0].h == 1e-3 and c.stages[0].output_every == 1
    mm = copy.deepcopy(BASE)
    mm["units"] = "mm-N-MPa"
    mm["materials"]["stone"].update(E=5000.0, rho=1.8e-9, thickness=100.0)
    mm["block_types"]["beam"].update(lx=1000.0, ly=200.0, mesh_size=50.0)
    mm["gravity"] = [0.0, -9810.0]
    c2 = parse_case(mm, "case.toml")
    assert c2.materials["stone"].E == pytest.approx(5e9, rel=1e-15)
    assert c2.materials["stone"].rho == pytest.approx(1800.0, rel=1e-12)
    assert c2.materials["stone"].thickness == pytest.approx(0.1, rel=1e-15)
    assert c2.block_types["beam"].lx == pytest.approx(1.0, rel=1e-15)
    assert c2.gravity[1] == pytest.approx(-9.81, rel=1e-15)


BAD = [
    (("materials", "stone", "E"), -1.0, r"materials\.stone\.E: = -1\.0: expected a number > 0"),
    (("materials", "stone", "E"), "hard", r"materials\.stone\.E: expected a finite number"),
    (("materials", "stone", "nu"), 0.5, r"materials\.stone\.nu: = 0\.5: expected a number > -1 and < 0\.5"),
    (("materials", "stone", "nu"), -1.0, r"materials\.stone\.nu: = -1\.0: expected"),
    (("materials", "stone", "rho"), 0.0, r"materials\.stone\.rho: = 0\.0: expected a number > 0"),
    (("materials", "stone", "rho"), DELETE, r"materials\.stone\.rho: missing"),
    (("materials", "stone", "plane"), "3d", r"materials\.stone\.plane: = '3d': expected one of"),
    (("materials", "stone", "colour"), "red", r"materials\.stone\.colour: unknown key"),
    (("stages", 0, "h"), 0.0, r"stages\[0\]\.h: = 0\.0: expected a number > 0"),
    (("stages", 0, "h"), -1e-3, r"stages\[0\]\.h: = -0\.001: expected a number > 0"),
    (("stages", 0, "theta"), 0.3, r"stages\[0\]\.theta: = 0\.3: expected a number >= 0\.5 and <= 1"),
    (("stages", 0, "theta"), 1.5, r"stages\[0\]\.theta: = 1\.5: expected"),
    (("stages", 0, "duration"), 1e-5, r"stages\[0\]\.duration: .*expected at least one time step"),
    (("stages", 0, "output_every"), 0, r"stages\[0\]\.output_every: = 0: expected an integer >= 1"),
    (("stages", 0, "output_every"), 2.5, r"stages\[0\]\.output_every: expected an integer"),
    (("stages",), [], r"stages: expected at least 1 entries"),
    (("stages",), DELETE, r"stages: missing"),
    (("blocks", 0, "type"), "brick", r"blocks\[0\]\.type: = 'brick': expected one of"),
    (("blocks", 0, "position"), [1.0], r"blocks\[0\]\.position: expected a list of 2 finite numbers"),
    (("blocks", 0, "clamps"), [{"tag": "left", "box": [0, 1, 0, 1]}], r"blocks\[0\]\.clamps\[0\]\.box: give exactly one"),
    (("blocks", 0, "clamps"), [{"box": [1, 0, 0, 1]}], r"blocks\[0\]\.clamps\[0\]\.box: .*xmin <= xmax"),
    (("block_types", "beam", "geometry"), "circle", r"block_types\.beam\.geometry: = 'circle': expected one of"),
    (("block_types", "beam", "lx"), -1.0, r"block_types\.beam\.lx: = -1\.0: expected a number > 0"),
    (("block_types", "beam", "material"), "steel", r"block_types\.beam\.material: = 'steel': expected one of"),
    (("block_types", "beam", "mesh_size"), DELETE, r"block_types\.beam\.mesh_size: missing"),
    (("block_types", "beam", "geometry"), "file", r"block_types\.beam\.file: missing"),
    (("block_types", "beam", "cell"), "hex", r"block_types\.beam\.cell: = 'hex': expected one of"),
    (("rigid_bodies", 0, "vertices"), [[0, 0], [1, 0]], r"rigid_bodies\[0\]\.vertices: expected a list of at least 3"),
    (("rigid_bodies", 0, "drivers"), {"z": {"kind": "velocity", "history": 0.0}}, r"rigid_bodies\[0\]\.drivers\.z: unknown dof"),
    (("rigid_bodies", 0, "drivers"), {"x": {"kind": "jerk", "history": 0.0}},
     r"rigid_bodies\[0\]\.drivers\.x\.kind: = 'jerk': expected one of"),
    (("rigid_bodies", 0, "drivers"), {"x": {"kind": "velocity", "history": {"times": [1, 0], "values": [0, 1]}}},
     r"rigid_bodies\[0\]\.drivers\.x\.history\.times: expected strictly increasing"),
    (("rigid_bodies", 0, "drivers"), {"x": {"kind": "velocity", "history": 0.0}},
     r"rigid_bodies\[0\]\.rho: missing; give rho"),
    (("rigid_bodies", 0, "forces"), {"y": 1.0}, r"rigid_bodies\[0\]\.forces\.y: this dof is driven"),
    (("gravity",), [0, "down"], r"gravity: expected a list of 2 finite numbers"),
    (("units",), "inch", r"units: = 'inch': expected one of"),
    (("unknown_section",), {}, r"unknown_section: unknown key"),
]


@pytest.mark.parametrize("path, value, message", BAD, ids=[".".join(map(str, b[0])) + f"={b[1]!r}"[:20] for b in BAD])
def test_bad_case_names_key(path, value, message):
    with pytest.raises(InputError, match=r"^case\.toml: " + message):
        parse_case(mutate(path, value), "case.toml")


def test_duplicate_names_rejected():
    d = copy.deepcopy(BASE)
    d["blocks"].append({"type": "beam", "name": "base"})
    with pytest.raises(InputError, match=r"rigid_bodies\[0\]\.name: = 'base': duplicate"):
        parse_case(d, "case.toml")


def test_missing_and_invalid_files(tmp_path):
    with pytest.raises(InputError, match="case file not found"):
        load_case(str(tmp_path / "nope.toml"))
    bad = tmp_path / "bad.toml"
    bad.write_text("[materials\nE = 1")
    with pytest.raises(InputError, match=r"bad\.toml: invalid TOML"):
        load_case(str(bad))
    mesh_missing = tmp_path / "m.toml"
    mesh_missing.write_text("""
[materials.m]
E = 1e9
nu = 0.2
rho = 1000.0
[block_types.t]
geometry = "file"
file = "missing.msh"
material = "m"
[[blocks]]
type = "t"
[[stages]]
duration = 1.0
h = 0.1
""")
    with pytest.raises(InputError, match=r"m\.toml: block_types\.t\.file: = 'missing\.msh': mesh file not found"):
        load_case(str(mesh_missing))


def run_cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "fem_blocks.cli", *args], capture_output=True, text=True,
                          cwd=cwd or ROOT, timeout=300)


def test_cli_exit_2_one_line(tmp_path):
    case = tmp_path / "c.toml"
    case.write_text("[materials.m]\nE = -5.0\nnu = 0.2\nrho = 1.0\n")
    p = run_cli("run", str(case), "--out", str(tmp_path / "out"))
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in p.stderr
    assert "c.toml: materials.m.E: = -5.0: expected a number > 0" in lines[0]
    p = run_cli("run", str(tmp_path / "absent.toml"), "--out", str(tmp_path / "out"))
    assert p.returncode == 2 and "case file not found" in p.stderr


def test_cli_version_and_demo_list():
    p = run_cli("--version")
    assert p.returncode == 0 and p.stdout.startswith("fem-blocks 0.")
    p = run_cli("demo", "--list")
    assert p.returncode == 0 and "vibrating_block" in p.stdout
    p = run_cli("demo", "no_such_demo")
    assert p.returncode == 2 and "demo 'no_such_demo' not found" in p.stderr


def test_demo_cases_parse():
    from fem_blocks.lab import load_lab
    for f in sorted(os.listdir(os.path.join(ROOT, "demos"))):
        if f.endswith(".toml"):
            path = os.path.join(ROOT, "demos", f)
            if load_lab(path) is None:   # a [lab] file: every specimen parsed by load_lab
                load_case(path)


CLI_BAD = [
    ("materials.m.E", "E = 0.0", "materials.m.E: = 0.0: expected a number > 0"),
    ("materials.m.nu", "nu = 0.7", "materials.m.nu: = 0.7: expected a number > -1 and < 0.5"),
    ("materials.m.rho", "rho = -3.0", "materials.m.rho: = -3.0: expected a number > 0"),
    ("stages[0].h", "h = 0.0", "stages[0].h: = 0.0: expected a number > 0"),
    ("stages[0].theta", "theta = 0.2", "stages[0].theta: = 0.2: expected a number >= 0.5 and <= 1"),
    ("unknown key", "colour = 'red'", "stages[0].colour: unknown key"),
]


@pytest.mark.parametrize("field, line, message", CLI_BAD, ids=[c[0] for c in CLI_BAD])
def test_cli_bad_parameters_exit_2(tmp_path, field, line, message):
    key = line.split("=")[0].strip()
    base = {"E": "E = 1e9", "nu": "nu = 0.2", "rho": "rho = 1000.0", "h": "h = 0.01", "theta": "theta = 0.5"}
    if key in base:
        base[key] = line
        extra = ""
    else:
        extra = line
    case = tmp_path / "c.toml"
    case.write_text(f"""[materials.m]
{base['E']}
{base['nu']}
{base['rho']}
[block_types.t]
geometry = "rectangle"
lx = 1.0
ly = 0.2
mesh_size = 0.1
material = "m"
[[blocks]]
type = "t"
[[stages]]
duration = 0.1
{base['h']}
{base['theta']}
{extra}
""")
    p = run_cli("run", str(case), "--out", str(tmp_path / "o"))
    assert p.returncode == 2
    assert len(p.stderr.strip().splitlines()) == 1
    assert p.stderr.strip().startswith(f"fem-blocks: error: {case}: {message}")
