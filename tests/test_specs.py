"""fem_blocks/specs.py: the one schema (stage accumulation, per-stage options, law-parameter table, TOML mapping)."""
import pytest

from fem_blocks.case import parse_case
from fem_blocks.errors import InputError
from fem_blocks.specs import LAW_KEYS, LAW_PARAMS, REQUIRED, ContactOptions, InterfaceSpec, StageSpec, controls_at


class RigidSpec_like:  # what controls_at reads of case.RigidSpec
    def __init__(self, name, drivers, forces):
        self.name, self.drivers, self.forces = name, drivers, forces


def _stage(drivers=None, forces=None, **kw):
    return StageSpec(name="s", duration=1.0, h=0.1, theta=0.5, drivers=drivers or {}, forces=forces or {}, **kw)


def test_controls_at_accumulates_stages_in_order():
    """Catches: a stage's driver not replacing the body's force, "free" keeping the old driver, a force not freeing
    a driven dof, or stage k reading stages after k."""
    beam = RigidSpec_like("beam", drivers={"x": ("velocity", 0.0)}, forces={"y": -1e3})
    s0 = _stage(drivers={"beam": {"y": ("displacement", 0.0)}})
    s1 = _stage(drivers={"beam": {"x": None}}, forces={"beam": {"y": -2e3}})
    s2 = _stage(drivers={"beam": {"x": ("velocity", 1e-3)}})
    stages = [s0, s1, s2]
    c0 = controls_at([beam], stages, 0)
    assert (c0[("beam", "x")].kind, c0[("beam", "x")].stage) == ("velocity", -1)
    assert (c0[("beam", "y")].kind, c0[("beam", "y")].label) == ("displacement", "stages[0].drivers.beam.y")
    c1 = controls_at([beam], stages, 1)
    assert ("beam", "x") not in c1  # freed, no force
    assert (c1[("beam", "y")].kind, c1[("beam", "y")].history, c1[("beam", "y")].driven) == ("force", -2e3, False)
    c2 = controls_at([beam], stages, 2)
    assert c2[("beam", "x")].driven and c2[("beam", "x")].history == 1e-3 and c2[("beam", "y")].kind == "force"


def test_stage_options_override_and_leave_the_case_options_alone():
    """Catches: a stage's tol not reaching the solver, the [contact] value lost when the stage gives none, the
    policy 'fail' left in the step (the runner applies it), or the case's options mutated."""
    base = ContactOptions(tol=1e-8, max_sweeps=500, on_nonconvergence="fail", solver="newton")
    o = base.for_stage(_stage(tol=1e-5))
    assert (o.tol, o.max_sweeps, o.on_nonconvergence, o.solver) == (1e-5, 500, "warn", "newton")
    assert (base.tol, base.on_nonconvergence) == (1e-8, "fail")
    assert base.for_stage(_stage(max_sweeps=7)).max_sweeps == 7


def test_law_table_keys_per_law():
    """Catches a parameter accepted by a law it does not belong to (e.g. mu for mixed, l_c for elastic)."""
    assert LAW_KEYS["coulomb"] == {"mu", "f_c", "G_fc", "kappa_p", "f_ci"}
    assert LAW_KEYS["mixed"] == {"k_n", "k_s", "f_t", "c", "G_I", "G_II", "tan_phi", "softening", "f_c", "G_fc",
                                 "kappa_p", "f_ci", "damage_viscosity", "damage_integration", "C_ss"}
    assert LAW_PARAMS["c_N"].laws["elastic"] is REQUIRED and LAW_PARAMS["c_T"].laws["brittle"] == 0.0


def test_interface_spec_checks_fields_and_law_once():
    """Catches: a field range not checked in the Python API, or mixed not taking its friction from tan_phi."""
    with pytest.raises(InputError, match=r"interfaces\.j\.orientation = 'diagonal': expected 'any', 'bed', 'head' "
                                         r"or 'crack'"):
        InterfaceSpec("j", ("a", "a"), orientation="diagonal")
    with pytest.raises(InputError, match=r"bed\[0\]\.c_N: missing; law 'elastic' needs c_N > 0"):
        InterfaceSpec("j", ("a", "a"), law="elastic", params=dict(c_T=1e9), where="bed[0]")
    m = InterfaceSpec("j", ("a", "a"), law="mixed", params=dict(k_n=1e11, k_s=5e10, f_t=2e5, c=3e5, G_I=10.0,
                                                                  G_II=50.0, tan_phi=0.6))
    assert m.mu == 0.6


CASE = """
units = "mm-N-MPa"
[materials.m]
E = 10000.0
nu = 0.2
rho = 2.5e-9
[block_types.b]
geometry = "rectangle"
material = "m"
lx = 100.0
ly = 50.0
mesh_size = 50.0
[[blocks]]
type = "b"
group = "g"
[[rigid_bodies]]
name = "base"
vertices = [[0.0, -10.0], [100.0, -10.0], [100.0, 0.0], [0.0, 0.0]]
group = "f"
[rigid_bodies.drivers]
x = {kind = "velocity", history = 0.0}
y = {kind = "velocity", history = 0.0}
rz = {kind = "velocity", history = 0.0}
[[interfaces]]
between = ["g", "f"]
law = "mixed"
k_n = 2.0
k_s = 1.0
f_t = 0.2
c = 0.3
G_I = 0.05
G_II = 0.2
tan_phi = 0.7
damage_viscosity = 0.5
g0 = 2.0
[contact]
tol = 1e-7
[[stages]]
h = 0.01
duration = 0.02
"""


def test_toml_maps_through_the_schema_with_units():
    """mm-N-MPa through the field table: stiffness MPa/mm -> 1e9 N/m^3, energy N/mm -> 1e3 J/m^2, stress MPa ->
    1e6 Pa, length mm -> 1e-3 m, time s; [contact] keeps the schema's defaults for keys not given."""
    case = parse_case(dict(__import__("tomllib").loads(CASE)), "<t>")
    itf = case.interfaces[0]
    assert isinstance(itf, InterfaceSpec) and isinstance(case.contact, ContactOptions)
    assert itf.params["k_n"] == pytest.approx(2e9) and itf.params["G_I"] == pytest.approx(50.0)
    assert itf.params["f_t"] == pytest.approx(2e5) and itf.params["damage_viscosity"] == 0.5
    assert itf.g0 == pytest.approx(2e-3) and itf.mu == 0.7
    assert (case.contact.tol, case.contact.max_sweeps, case.contact.geometry) == (1e-7, 2000, "frozen")
    assert (case.stages[0].theta, case.stages[0].output_every, case.stages[0].velocity_reset) == (0.5, 1, False)
