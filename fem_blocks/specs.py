"""The schema: the one definition of every engine-facing field of a case file.

Each field below is defined once, with its default, unit kind, valid range or choices and a one-line doc, as
`dataclasses.field(metadata=...)` (built by `spec(...)`):

* `InterfaceSpec`  — one `[[interfaces]]` entry: groups, law, friction, joint geometry, law parameters;
* `SolverOptions`  — the solver's options (`solver.solve(problem, options)`), the `[contact]` table's solver keys;
* `ContactOptions` — the `[contact]` table: SolverOptions plus contact geometry and non-convergence policy;
* `CyclicProtocol` — a displacement history given as a cyclic protocol (expanded by `case.cyclic_history`);
* `StageSpec`      — one `[[stages]]` entry; `StageSpec.changes()` lists what a stage sets, and
  `controls_at(rigid_bodies, stages, k)` folds them (stages accumulate in order) into the control of every
  rigid dof during stage k — the one implementation used by the case checks and by the runner;
* `LAW_PARAMS`     — the interface-law parameter table (unit kind, range, default per law, which laws use it);
  `validate_law_params` is the one validation against it (with the laws' cross rules); `laws.pack` puts the
  values in the kernels' parameter vector (`laws.law_parameters` = both);
* `MaterialSpec`, `ChecksSpec`, `OutputSpec` — `[materials.NAME]`, `[checks]`, `[output]`;
* `ReferenceSpec`  — one `[[reference]]` entry (a measured curve, band or peak on force_displacement.png).

Metadata keys (`spec`): `doc`, `unit` (unit kind of the mm-N-MPa conversion: "length", "stress", "stiffness",
"energy", "time", ... — see case.UNIT_SYSTEMS/DERIVED; None: dimensionless), `choices`, `lo`/`hi` (with `lo_open`/
`hi_open`), `key` (TOML key, default the field name), `toml` (False: not a case-file key), `required` (required in a
case file), `expected` (the text of the range error, when the generic one would say less).

`check_fields(obj, prefix)` is the one generic validator of the Python API (messages
``PREFIX.NAME = VALUE: expected ...``); case.py maps TOML tables onto these classes with one generic mapper
(`case.read_fields`) that reads the same metadata. Imports: stdlib and fem_blocks.errors only.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from .errors import InputError, check_range

def spec(default=dataclasses.MISSING, *, doc: str, unit: str | None = None, choices=None, lo=None, hi=None,
         lo_open: bool = False, hi_open: bool = False, key: str | None = None, toml: bool = True,
         required: bool = False, expected: str | None = None, default_factory=dataclasses.MISSING):
    """A dataclass field with its schema metadata (see the module docstring)."""
    md = dict(doc=doc, unit=unit, choices=None if choices is None else tuple(choices), lo=lo, hi=hi,
              lo_open=lo_open, hi_open=hi_open, key=key, toml=toml, required=required, expected=expected)
    if default_factory is not dataclasses.MISSING:
        return field(default_factory=default_factory, metadata=md)
    return field(default=default, metadata=md)


def choices_text(choices) -> str:
    """'a', 'b' or 'c'."""
    q = [repr(c) for c in choices if c is not None]
    return q[0] if len(q) == 1 else ", ".join(q[:-1]) + " or " + q[-1]


def range_text(name: str, md: dict) -> str:
    """`name > 0`, `0 < name < 2`, `1 <= name <= 12`: the generic text of a range."""
    lo, hi = md["lo"], md["hi"]
    if lo is not None and hi is not None:
        return f"{lo:g} {'<' if md['lo_open'] else '<='} {name} {'<' if md['hi_open'] else '<='} {hi:g}"
    if lo is not None:
        return f"{name} {'>' if md['lo_open'] else '>='} {lo:g}"
    return f"{name} {'<' if md['hi_open'] else '<='} {hi:g}"


def schema_fields(cls) -> list:
    """The fields of a schema class that carry metadata, in declaration order."""
    return [f for f in dataclasses.fields(cls) if "doc" in f.metadata]


def default_of(cls, name: str):
    """The default of field `name` of schema class `cls` (where a reader needs it outside the dataclass)."""
    f = {f.name: f for f in dataclasses.fields(cls)}[name]
    return f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default


def toml_key(f) -> str:
    return f.metadata["key"] or f.name


def check_fields(obj, prefix: str, names=None):
    """Validate the fields of `obj` against their metadata (choices, range); InputError
    ``PREFIX.NAME = VALUE: expected ...``. `names`: only these fields, in that order."""
    fields = {f.name: f for f in schema_fields(type(obj))}
    for f in (fields.values() if names is None else [fields[n] for n in names]):
        md, v = f.metadata, getattr(obj, f.name)
        if md["choices"] is not None:
            if v not in md["choices"] and not (v is None and f.default is None):
                raise InputError(f"{prefix}.{f.name} = {v!r}: expected {md['expected'] or choices_text(md['choices'])}")
        elif md["lo"] is not None or md["hi"] is not None:
            if v is None and f.default is None:
                continue
            check_range(f"{prefix}.{f.name}", v, md["lo"], md["hi"], md["lo_open"], md["hi_open"],
                        expected=md["expected"] or range_text(f.name, md))


# ----------------------------------------------------------------------------- interface-law parameters
REQUIRED = object()  # a law parameter without default for that law


@dataclass(frozen=True)
class LawParam:
    """One interface-law parameter: its unit kind (mm-N-MPa conversion), the laws that take it with their default
    (REQUIRED: the law needs it), the range (lo, lo_open) or choices, and the text of the range error."""
    unit: str | None
    laws: dict          # law name -> default value or REQUIRED
    doc: str
    lo: float | None = 0.0
    lo_open: bool = False
    expected: str = ""
    choices: tuple | None = None
    finite: bool = False  # +inf is rejected too (a range check alone lets it through)
    per_law: dict = field(default_factory=dict)  # law -> {lo_open, expected} where that law's range differs


_R = REQUIRED
# The one table of the interface-law parameters (laws.py keeps the kernels and packs these into the parameter
# vector). Keys are the [[interfaces]] keys; values per unit area, SI after conversion.
LAW_PARAMS: dict[str, LawParam] = {
    "mu": LawParam(None, dict(coulomb=_R, elastic=0.0, brittle=0.0, fremond=0.0), "friction coefficient",
                   expected="mu >= 0"),
    "c_N": LawParam("stiffness", dict(elastic=_R, brittle=_R, fremond=_R), "normal joint stiffness", lo_open=True,
                    expected="c_N > 0 [N/m^3]"),
    "c_T": LawParam("stiffness", dict(elastic=_R, brittle=0.0, fremond=_R), "tangential joint stiffness",
                    lo_open=True, expected="c_T > 0 [N/m^3]",
                    per_law=dict(brittle=dict(lo_open=False, expected="c_T >= 0 [N/m^3]"))),
    "r_c": LawParam("stress", dict(brittle=_R), "tensile strength", lo_open=True,
                    expected="tensile strength r_c > 0 [Pa]"),
    "s_c": LawParam("stress", dict(brittle=0.0), "shear strength (elastic-brittle; 0: none)",
                    expected="shear strength s_c >= 0 [Pa] (0: none)"),
    "l_c": LawParam("length", dict(brittle=_R), "critical opening (Dugdale)", lo_open=True,
                    expected="critical opening l_c > 0 [m]"),
    "variant": LawParam(None, dict(brittle="elastic"), "brittle variant", lo=None,
                        choices=("elastic", "dugdale")),
    "w": LawParam("energy", dict(fremond=_R), "adhesion energy", lo_open=True,
                  expected="adhesion energy w > 0 [J/m^2]"),
    "b": LawParam("viscosity", dict(fremond=0.0), "adhesion viscosity (0: rate-independent)",
                  expected="viscosity b >= 0 [J s/m^2]"),
    "p": LawParam(None, dict(fremond=1.0), "viscosity exponent", lo_open=True, expected="exponent p > 0"),
    "friction": LawParam(None, dict(fremond="constant"), "friction: constant mu or mu(beta) = (1 - beta) mu_r",
                         lo=None, choices=("constant", "damage")),
    "mu_r": LawParam(None, dict(fremond=_R), "residual friction (friction = 'damage')",
                     expected="residual friction mu_r >= 0"),
    "k_n": LawParam("stiffness", dict(mixed=_R), "normal stiffness", lo_open=True,
                    expected="normal stiffness k_n > 0 [N/m^3]"),
    "k_s": LawParam("stiffness", dict(mixed=_R), "shear stiffness", lo_open=True,
                    expected="shear stiffness k_s > 0 [N/m^3]"),
    "f_t": LawParam("stress", dict(mixed=_R), "tensile strength", lo_open=True,
                    expected="tensile strength f_t > 0 [Pa]"),
    "c": LawParam("stress", dict(mixed=_R), "cohesion", lo_open=True, expected="cohesion c > 0 [Pa]"),
    "G_I": LawParam("energy", dict(mixed=_R), "mode I fracture energy", lo_open=True,
                    expected="mode I fracture energy G_I > 0 [J/m^2]"),
    "G_II": LawParam("energy", dict(mixed=_R), "mode II fracture energy", lo_open=True,
                     expected="mode II fracture energy G_II > 0 [J/m^2]"),
    "tan_phi": LawParam(None, dict(mixed=_R), "friction on the compressive part", expected="friction tan_phi >= 0"),
    "softening": LawParam(None, dict(mixed="linear"), "softening curve", lo=None,
                          choices=("linear", "exponential")),
    "damage_viscosity": LawParam("time", dict(mixed=0.0), "viscous regularisation of the damage (0: none)",
                                 expected="finite damage viscosity eta >= 0 [s] (0: rate-independent)",
                                 finite=True),
    "damage_integration": LawParam(None, dict(mixed="implicit", fremond="implicit"),
                                   "damage (D, β) of the step: implicit (solved with the step) or IMPL-EX "
                                   "(extrapolated from the two last steps)", lo=None, choices=("implicit", "implex")),
    "f_c": LawParam("stress", dict(coulomb=0.0, elastic=0.0, brittle=0.0, fremond=0.0, mixed=0.0),
                    "compressive strength of the cap (omit: no cap)", lo_open=True,
                    expected="compressive strength f_c > 0 [Pa] (omit: no cap)"),
    "G_fc": LawParam("energy", dict(coulomb=0.0, elastic=0.0, brittle=0.0, fremond=0.0, mixed=0.0),
                     "compressive fracture energy (softening cap; needs f_c)", lo_open=True,
                     expected="compressive fracture energy G_fc > 0 [J/m^2] (omit: perfectly plastic cap)",
                     finite=True),
    "kappa_p": LawParam("length", dict(coulomb=0.0, elastic=0.0, brittle=0.0, fremond=0.0, mixed=0.0),
                        "plastic closure at the cap's peak: the cap hardens from f_ci to f_c over it (needs f_c; "
                        "omit: no hardening)", lo_open=True,
                        expected="plastic closure at the peak of the cap kappa_p > 0 [m] (omit: no hardening)",
                        finite=True),
    "f_ci": LawParam("stress", dict(coulomb=0.0, elastic=0.0, brittle=0.0, fremond=0.0, mixed=0.0),
                     "initial cap of the hardening branch, f_ci <= f_c (needs kappa_p; omit: f_c/3)", lo_open=True,
                     expected="initial cap f_ci > 0 [Pa] (omit: f_c/3)", finite=True),
    "C_ss": LawParam(None, dict(mixed=0.0),
                     "shear term of the elliptic cap (r̃_N/A)^2 + C_ss (r̃_T/A)^2 <= f_c(κ)^2 (needs f_c; 0: the cap "
                     "bounds the normal stress only)",
                     expected="cap shear coefficient C_ss >= 0 (dimensionless; 0: no shear term)", finite=True),
}
LAWS = ("coulomb", "elastic", "brittle", "fremond", "mixed")
# the parameters each law accepts, from the table
LAW_KEYS = {law: {k for k, p in LAW_PARAMS.items() if law in p.laws} for law in LAWS}
# the keys that exclude each other within a law
_DUGDALE_ONLY, _ELASTIC_BRITTLE_ONLY = ("l_c",), ("c_N", "c_T", "s_c")
_CHOICE_TEXT = dict(variant="'elastic' or 'dugdale'",
                    friction="'constant' (mu) or 'damage' (mu(beta) = (1 - beta) mu_r)",
                    softening="'linear' or 'exponential'",
                    damage_integration="'implicit' or 'implex'")


def validate_law_params(law: str, params: dict, name: str) -> dict:
    """The one validation of an interface law's parameters (SI, per unit area) against LAW_PARAMS and the laws'
    cross rules -> the values the law uses, defaults filled in (laws.pack puts them in the parameter vector).
    InputError ``NAME.KEY ...`` naming the parameter."""
    if law not in LAW_KEYS:
        raise InputError(f"{name}.law = {law!r}: expected one of {sorted(LAW_KEYS)}")
    unknown = set(params) - LAW_KEYS[law]
    if unknown:
        raise InputError(f"{name}.{sorted(unknown)[0]}: unknown parameter for law {law!r}; expected "
                         f"{sorted(LAW_KEYS[law])}")
    out = {}

    def get(k):
        p = LAW_PARAMS[k]
        rule = dict(dict(lo_open=p.lo_open, expected=p.expected), **p.per_law.get(law, {}))
        if p.choices is not None:
            v = params.get(k, p.laws[law])
            if v not in p.choices:
                raise InputError(f"{name}.{k} = {v!r}: expected {_CHOICE_TEXT[k]}")
        elif k not in params:
            if p.laws[law] is REQUIRED:
                raise InputError(f"{name}.{k}: missing; law {law!r} needs {rule['expected'] or k}")
            v = p.laws[law]
        else:
            v = check_range(f"{name}.{k}", params[k], p.lo, lo_open=rule["lo_open"], expected=rule["expected"])
            if p.finite and v == float("inf"):
                e = rule["expected"]
                raise InputError(f"{name}.{k} = {params[k]!r}: expected {e if e.startswith('finite') else 'finite ' + e}")
        out[k] = v
        return v

    get("f_c")
    if "G_fc" in params:
        if "f_c" not in params:
            raise InputError(f"{name}.G_fc: needs the compressive strength f_c [Pa] (G_fc softens the cap f_c)")
        get("G_fc")
    else:
        out["G_fc"] = 0.0
    if "kappa_p" in params:
        if "f_c" not in params:
            raise InputError(f"{name}.kappa_p: needs the compressive strength f_c [Pa] (kappa_p is the plastic "
                             "closure at the cap's peak f_c)")
        get("kappa_p")
        if "f_ci" in params:
            if get("f_ci") > out["f_c"]:
                raise InputError(f"{name}.f_ci = {out['f_ci']:g}: expected f_ci <= f_c = {out['f_c']:g} Pa (the cap "
                                 "hardens from f_ci to f_c)")
        else:
            out["f_ci"] = out["f_c"] / 3.0
    elif "f_ci" in params:
        raise InputError(f"{name}.f_ci: needs kappa_p [m] (f_ci is the start of the cap's hardening branch)")
    else:
        out["kappa_p"] = out["f_ci"] = 0.0
    if "C_ss" in params:  # only the mixed law takes it (an unknown key for the others, above)
        if "f_c" not in params:
            raise InputError(f"{name}.C_ss: needs the compressive strength f_c [Pa] (C_ss is the shear term of the "
                             "cap's ellipse)")
        get("C_ss")
    elif law == "mixed":
        out["C_ss"] = 0.0
    if law == "mixed":
        for k in ("k_n", "k_s", "f_t", "c", "G_I", "G_II", "tan_phi", "softening", "damage_viscosity",
                  "damage_integration"):
            get(k)
        eI = out["f_t"] ** 2 / (2 * out["k_n"])
        eII = out["c"] ** 2 / (2 * out["k_s"])
        if out["G_I"] <= eI:
            raise InputError(f"{name}.G_I = {out['G_I']:g}: the peak f_t is not reachable; expected G_I > "
                             f"f_t^2/(2 k_n) = {eI:g} J/m^2 (the elastic energy at the peak)")
        if out["G_II"] <= eII:
            raise InputError(f"{name}.G_II = {out['G_II']:g}: the peak c is not reachable; expected G_II > "
                             f"c^2/(2 k_s) = {eII:g} J/m^2")
        return out
    get("mu")
    if law == "elastic":
        get("c_N"), get("c_T")
    elif law == "brittle":
        variant = get("variant")
        get("r_c")
        if variant == "dugdale":
            get("l_c")
            for k in _ELASTIC_BRITTLE_ONLY:
                if k in params:
                    raise InputError(f"{name}.{k}: not a parameter of the Dugdale variant (r_c, l_c, mu)")
        else:
            for k in _DUGDALE_ONLY:
                if k in params:
                    raise InputError(f"{name}.{k}: not a parameter of the elastic-brittle variant "
                                     "(c_N, c_T, r_c, s_c, mu)")
            get("c_N"), get("c_T"), get("s_c")
    elif law == "fremond":
        for k in ("c_N", "c_T", "w", "b", "p", "damage_integration"):
            get(k)
        if get("friction") == "damage":
            get("mu_r")
        elif "mu_r" in params:
            raise InputError(f"{name}.mu_r: only with friction = 'damage'")
    return out


# ----------------------------------------------------------------------------- [[interfaces]]
@dataclass
class InterfaceSpec:
    """Interface between two body groups: law and joint geometry (one `[[interfaces]]` entry). Validated on
    construction (`check_fields`, then the law parameters by `validate_law_params`), which sets `law_values`
    (packed into the parameter row by laws.pack) and `mu` (tan_phi for the mixed law). `where`: the key path named by the errors (default
    ``interfaces.NAME``)."""

    name: str = spec(doc="interface name (default interfaceN)")
    groups: tuple = spec(doc="two body group names, e.g. [\"bricks\", \"bricks\"]", key="between", required=True)
    law: str = spec("coulomb", doc="interface law (docs/laws.md)", choices=LAWS)
    mu: float = spec(0.5, doc="friction coefficient (required in a case file, except for law = 'mixed')", lo=0.0)
    g0: float = spec(0.0, doc="joint thickness: impenetrability on g - g0", unit="length", lo=0.0,
                     expected="g0 >= 0 [m] (joint thickness)")
    alert: float = spec(1e-3, doc="alert distance: pairs farther than g0 + alert are not contacts", unit="length",
                        lo=0.0, lo_open=True, expected="alert > 0 [m]")
    placement: str | None = spec(None, doc="candidate points: 'overlap' (the 2D default), 'nodes' or 'positions' "
                                           "(the 3D default)", choices=("overlap", "nodes", "positions"))
    positions: tuple = spec((0.25, 0.75), doc="relative positions on the candidate edges (placement = 'positions')")
    candidate: str | None = spec(None, doc="group whose bodies are candidates")
    orientation: str = spec("any", doc="'any', or 'bed'/'head' (chosen by the normal), or 'crack' (split bricks)",
                            choices=("any", "bed", "head", "crack"))
    params: dict = spec(doc="law parameters (LAW_PARAMS), SI per unit area", toml=False, default_factory=dict)
    reference: str = spec("nominal", doc="'nominal': closed at g = g0; 'as_built': the initial contacts closed as built",
                          choices=("nominal", "as_built"))
    max_angle: float = spec(60.0, doc="facing angle [degrees]: a (candidate, antagonist) edge/face pair is examined "
                            "only if its outward normals are within max_angle of opposite (60: a corner of a "
                            "right-angled block stays in contact at any tilt, 2D and 3D; docs/case-files.md)",
                            lo=0.0, hi=90.0, lo_open=True, hi_open=True, expected="0 < max_angle < 90 [degrees]")
    where: dataclasses.InitVar[str | None] = None

    def __post_init__(self, where):
        n = f"interfaces.{self.name}"
        check_fields(self, n, ("reference", "mu", "g0", "alert", "placement", "max_angle"))
        for p in self.positions:
            check_range(f"{n}.positions", p, 0.0, 1.0, lo_open=True, hi_open=True, expected="0 < position < 1")
        check_fields(self, n, ("orientation",))
        prm = dict(self.params)
        if self.law != "mixed":
            prm.setdefault("mu", self.mu)
        self.law_values = validate_law_params(self.law, prm, where or n)  # laws.pack -> the parameter row
        self.mu = float(self.law_values["tan_phi" if self.law == "mixed" else "mu"])


# ----------------------------------------------------------------------------- [contact]
NONCONV = ("warn", "fail", "refine", "adaptive")
PREDICTORS = ("previous", "scaled", "extrapolated")


@dataclass
class SolverOptions:
    """How the contact problem u = W r + q (Signorini–Coulomb or interface laws per contact) is solved: what
    `solver.solve(problem, options)` reads (solver/driver.py). The `[contact]` table's solver keys."""
    solver: str = spec("nlgs", doc="'nlgs' (nonlinear Gauss-Seidel) or 'newton' (global semismooth Newton, NLGS "
                       "start and fallback)", choices=("nlgs", "newton"))
    tol: float = spec(1e-6, doc="solver tolerance (relative, on the measure chosen by criterion)", lo=0.0,
                      lo_open=True)
    max_sweeps: int = spec(2000, doc="NLGS: most Gauss-Seidel sweeps per step; Newton: most fallback sweeps", lo=1)
    omega: float = spec(1.0, doc="NLGS relaxation r <- omega r_local + (1 - omega) r", lo=0.0, hi=2.0, lo_open=True,
                        hi_open=True)
    order: str = spec("given", doc="contact order of the sweeps (shuffled: seeded by seed + step count; colours: "
                      "greedy colours of the contact graph in turn, the order of a run on several MPI ranks)",
                      choices=("given", "reversed", "shuffled", "colours"))
    seed: int = spec(0, doc="seed of order = 'shuffled' (the contact step adds its step count)", lo=0)
    criterion: str = spec("change", doc="'change': |dP|/|P| between sweeps; 'residual': natural-map residual |F|/|q|",
                          choices=("change", "residual"))
    check_every: int = spec(10, doc="sweeps between two residual evaluations", lo=1)
    fallback: str = spec("none", doc="'newton': NLGS hands over to the global Newton when it stagnates (Coulomb)",
                         choices=("none", "newton"))
    coarse: str = spec("none", doc="'interfaces': two-level NLGS, coarse correction per interface (solver/coarse.py)",
                       choices=("none", "interfaces"))
    coarse_every: int = spec(10, doc="sweeps between two coarse corrections", lo=1)
    max_iterations: int | None = spec(None, doc="Newton with interface laws: most Newton iterations per step over "
                                      "all passes (default 10 x 200)", lo=1)

    def __post_init__(self):
        check_fields(self, "contact")
        if self.fallback == "newton" and (self.solver != "nlgs" or self.criterion != "residual"):
            raise InputError("contact.fallback = 'newton': expected solver = 'nlgs' and criterion = 'residual' "
                             "(stagnation is measured on the residual)")
        if self.order == "colours" and (self.solver != "nlgs" or self.fallback != "none" or self.coarse != "none"):
            raise InputError("contact.order = 'colours': the colour-order sweep is a Gauss-Seidel solver of its own; "
                             "expected solver = 'nlgs', fallback = 'none' and coarse = 'none'")
        if self.coarse != "none" and (self.solver != "nlgs" or self.fallback != "none"):
            raise InputError(f"contact.coarse = {self.coarse!r}: expected solver = 'nlgs' and fallback = 'none' (the "
                             "coarse correction is a step of the Gauss-Seidel solver)")


@dataclass
class ContactOptions(SolverOptions):
    """The `[contact]` table: the solver's options (SolverOptions) and the contact step's own: contact geometry and
    what an unconverged step does."""
    geometry: str = spec("frozen", doc="'frozen' (reference configuration) or 'updated' (re-detection)",
                         choices=("frozen", "updated"))
    redetect_every: int = spec(1, doc="steps between re-detections (updated geometry)", lo=1)
    rebalance: float = spec(1.1, doc="N > 1 MPI ranks, updated geometry, Gauss-Seidel in colour order: the bodies "
                            "are partitioned again at a re-detection where a rank would own more than rebalance x "
                            "the mean number of contacts per rank", lo=1.0)
    on_nonconvergence: str = spec("warn", doc="what a step reaching max_sweeps does", choices=NONCONV,
                                  expected="'warn', 'fail', 'refine' or 'adaptive' (refine, adaptive: handled by the "
                                           "runner, warn here)")
    max_refinements: int = spec(4, doc="'refine', 'adaptive': at most 2^max_refinements sub-steps per step", lo=1,
                                hi=12)
    attempt_budget: int = spec(0, doc="'refine', 'adaptive': an attempt that can still be halved stops after this "
                               "many Newton iterations / fallback sweeps (0: the full max_sweeps)", lo=0)
    grow_after: int = spec(4, doc="'adaptive': converged sub-steps in a row before the sub-step is doubled", lo=1)
    predictor: str = spec("previous", doc="warm start of the impulses: the last step's ('previous'), rescaled to "
                          "the new h ('scaled'), or extrapolated linearly in time from the last two steps "
                          "('extrapolated')", choices=PREDICTORS)

    def for_stage(self, stage: "StageSpec") -> "ContactOptions":
        """The options of a stage: its tol/max_sweeps override these; the non-convergence policy is applied by the
        runner (which writes a checkpoint before stopping), so the step itself only warns."""
        return dataclasses.replace(self, tol=self.tol if stage.tol is None else stage.tol,
                                   max_sweeps=self.max_sweeps if stage.max_sweeps is None else stage.max_sweeps,
                                   on_nonconvergence="warn")


# ----------------------------------------------------------------------------- [[stages]]
@dataclass
class StageSpec:
    """One `[[stages]]` entry. drivers: body -> dof -> (kind, history) | None (free); forces: body -> dof ->
    history. Stages accumulate in order: `controls_at`."""
    name: str = spec(doc="stage name (default stageN)")
    duration: float = spec(doc="stage duration (at least one step h)", unit="time", lo=0.0, lo_open=True,
                           required=True)
    h: float = spec(doc="time step", unit="time", lo=0.0, lo_open=True, required=True)
    theta: float = spec(doc="theta of the theta-method (default 1 with static = true, else 0.5)", lo=0.5, hi=1.0)
    velocity_reset: bool = spec(False, doc="quasi-static strategy: velocities set to zero at the start of each step")
    output_every: int = spec(1, doc="ParaView frame every N steps", lo=1)
    static: bool = spec(False, doc="static step: no inertia, no damping (theta = 1); dynamics.py")
    stop_at_equilibrium: bool = spec(False, doc="[stages.stop_at_equilibrium] given: stop when every velocity is "
                                                "below max_velocity after min_steps")
    equilibrium_velocity: float = spec(1e-6, doc="stop_at_equilibrium: velocity threshold", unit="length", lo=0.0,
                                       lo_open=True, key="stop_at_equilibrium.max_velocity")
    min_steps: int = spec(10, doc="stop_at_equilibrium: steps before the test", lo=1,
                          key="stop_at_equilibrium.min_steps")
    tol: float | None = spec(None, doc="contact solver tolerance for this stage (default: [contact])", lo=0.0,
                             lo_open=True)
    max_sweeps: int | None = spec(None, doc="sweep limit for this stage (default: [contact])", lo=1)
    stop_displacement: tuple | None = spec(None, doc="(body, dof, |value| [m]): stop at that displacement",
                                           key="stop_at_displacement")
    drivers: dict = spec(doc="body -> dof -> (kind, history) | None (free)", default_factory=dict)
    forces: dict = spec(doc="body -> dof -> history", default_factory=dict)
    stop_after_peak: tuple | None = spec(None, doc="(body, reaction dof, relative drop, min_steps)")
    stop_rotation: tuple | None = spec(None, doc="(body, relative_to | None, angle [rad]): stop when the body's "
                                       "rotation relative to relative_to (since placement if None) reaches angle",
                                       key="stop_at_rotation")
    on_nonconvergence: str | None = spec(None, doc="'warn', 'fail', 'refine' or 'adaptive' for this stage (default: "
                                         "[contact])",
                                         choices=NONCONV)

    def changes(self):
        """What this stage sets, in the order it is applied: (body, dof, kind, history) with kind "velocity" or
        "displacement" (a driver), "free" (history None) or "force" — drivers first, then forces."""
        for body, dofs in self.drivers.items():
            for dof, s in dofs.items():
                yield (body, dof, "free", None) if s is None else (body, dof, s[0], s[1])
        for body, dofs in self.forces.items():
            for dof, hist in dofs.items():
                yield body, dof, "force", hist


@dataclass
class CyclicProtocol:
    """A displacement history written as a cyclic protocol, `{protocol = "cyclic", amplitudes = [a1, a2, ...],
    cycles = n, rate = v}`, accepted wherever a displacement driver history is (`[stages.drivers.BODY]`,
    `[rigid_bodies.drivers]`, `[wall.beam.drivers]`, `[wall.foundation.settlement]`). `case.cyclic_history` expands
    it once into the piecewise-linear {times, values} with a knot at every reversal,

        0 -> +a1 -> -a1 -> ... (n cycles of a1) -> +a2 -> -a2 -> ... -> +ak -> -ak -> 0,

    at the constant rate |du/dt| = v (knot times t_{j+1} = t_j + |u_{j+1} - u_j| / v from t_0 = start), so the
    rest of the engine sees an ordinary history. Total duration sum_i 4 n a_i / v."""
    protocol: str | None = spec(None, doc="the protocol's kind", choices=("cyclic",), required=True)
    amplitudes: tuple | None = spec(None, doc="amplitudes a_1 < a_2 < ..., each > 0, in the dof's unit (length; rad "
                                              "on a rotation dof)", unit="length", lo=0.0, lo_open=True,
                                    required=True, expected="a list of amplitudes > 0, strictly increasing")
    cycles: int = spec(1, doc="cycles per amplitude", lo=1)
    rate: float | None = spec(None, doc="constant displacement rate |du/dt| (length per s; rad/s on a rotation "
                                        "dof)", unit="length", lo=0.0, lo_open=True, required=True)
    start: float = spec(0.0, doc="time of the first knot (u = 0) [s]: run time, or from the stage's start with "
                                 "history_times = \"stage\"", unit="time", lo=0.0)


DRIVER_KINDS = ("velocity", "displacement", "acceleration")  # the `kind` of a rigid dof's driver (bodies.Driver)


class DriverSpec(tuple):
    """A rigid dof's driver as read from a case file: the pair (kind, history) — it unpacks as one — with
    `pivot`: None, or the point [m] (global, SI) a rotation driver turns the body about (its translation dofs are
    then driven too: bodies._DrivenDofs). kind is one of DRIVER_KINDS."""

    def __new__(cls, kind: str, history, pivot=None):
        obj = super().__new__(cls, (kind, history))
        obj.pivot = None if pivot is None else tuple(float(x) for x in pivot)
        return obj

    def __getnewargs__(self):
        return (self[0], self[1], self.pivot)


def _translations(dof: str, pivot) -> tuple:
    """The translation dofs a pivot of dimension len(pivot) drives."""
    return ("x", "y", "z")[:len(pivot)]


@dataclass(frozen=True)
class Control:
    """How a rigid dof is controlled: kind "velocity" | "displacement" | "acceleration" (driven), "pivot" (a
    translation dof driven by the pivot of a rotation driver; history None) or "force" (free, with a history);
    label: the key path that set it; stage: its stage index (-1: the body's own); pivot: the pivot of a rotation
    driver (None)."""
    kind: str
    history: Any
    label: str
    stage: int
    pivot: Any = None

    @property
    def driven(self) -> bool:
        return self.kind in DRIVER_KINDS + ("pivot",)


def controls_at(rigid_bodies, stages, k: int) -> dict:
    """(body, dof) -> Control during stage k: the rigid bodies' own drivers/forces, then stages 0..k applied in
    order (a driver replaces a force, "free" removes both, a force frees a driven dof). The one definition of
    "stages accumulate". Free dofs without a force are absent."""
    out = {}

    def drive(body, dof, spec, label, stage):
        kind, hist = spec
        pivot = getattr(spec, "pivot", None)
        out[(body, dof)] = Control(kind, hist, label, stage, pivot)
        if pivot is not None:  # the pivot drives the translations (replacing their drivers or forces)
            for tr in _translations(dof, pivot):
                out[(body, tr)] = Control("pivot", None, label + ".pivot", stage)

    def free(body, dof):
        c = out.pop((body, dof), None)
        if c is not None and c.pivot is not None:
            for tr in _translations(dof, c.pivot):
                if out.get((body, tr)) is not None and out[(body, tr)].kind == "pivot":
                    out.pop((body, tr))

    for r in rigid_bodies:
        for dof, spec in r.drivers.items():
            drive(r.name, dof, spec, f"rigid_bodies.{r.name}.drivers.{dof}", -1)
        for dof, hist in r.forces.items():
            out[(r.name, dof)] = Control("force", hist, f"rigid_bodies.{r.name}.forces.{dof}", -1)
    for i, st in enumerate(stages[:k + 1]):
        for body, dof, kind, hist in st.changes():
            if kind == "free":
                free(body, dof)
            else:
                if (body, dof) in out and out[(body, dof)].pivot is not None:
                    free(body, dof)  # a new driver or force on a rotation dof replaces its pivot
                what = "forces" if kind == "force" else "drivers"
                label = f"stages[{i}].{what}.{body}.{dof}"
                if kind == "force":
                    out[(body, dof)] = Control(kind, hist, label, i)
                else:
                    drive(body, dof, st.drivers[body][dof], label, i)
    return out


# ----------------------------------------------------------------------------- [materials.NAME]
@dataclass
class MaterialSpec:
    """One `[materials.NAME]` table: linear elastic material of deformable blocks (model.py -> bodies.Material).
    The unit-system plausibility checks (E, rho) are case.py's."""
    name: str = spec(doc="the table's name", toml=False)
    E: float = spec(doc="Young's modulus", unit="stress", lo=0.0, lo_open=True, required=True)
    nu: float = spec(doc="Poisson's ratio", lo=-1.0, hi=0.5, lo_open=True, hi_open=True, required=True)
    rho: float = spec(doc="density", unit="density", lo=0.0, lo_open=True, required=True)
    thickness: float = spec(1.0, doc="out-of-plane thickness (2D)", unit="length", lo=0.0, lo_open=True)
    plane: str = spec("stress", doc="plane stress or plane strain (2D)", choices=("stress", "strain"))
    alpha: float = spec(0.0, doc="Rayleigh damping [a, b]: C = a M + b K (a = alpha, b = beta)", key="rayleigh",
                        lo=0.0)
    beta: float = spec(0.0, doc="Rayleigh b (the second value of rayleigh)", toml=False, lo=0.0)


# ----------------------------------------------------------------------------- [checks], [output]
@dataclass
class ChecksSpec:
    """The `[checks]` table: numerical safety limits (runner guards) and the exit status of unconverged runs.
    (The Case holds it as a dict: `dataclasses.asdict`.)"""
    max_penetration: float | None = spec(None, doc="penetration limit (default: the alert distance)", unit="length",
                                         lo=0.0, lo_open=True)
    max_energy_growth: float = spec(10.0, doc="limit of the energy growth ratio", lo=0.0, lo_open=True)
    accept_unconverged: bool = spec(False, doc="true: a run with unconverged steps exits 0 instead of 3")


@dataclass
class OutputSpec:
    """The `[output]` table (the Case holds it as a dict; `curve` only when given or chosen in 3D)."""
    paraview: bool = spec(True, doc="write paraview/blocks.pvd (and contacts.pvd)")
    stress: bool = spec(True, doc="cell stresses and von Mises in the ParaView files")
    checkpoint_every: int = spec(0, doc="checkpoint every N steps (0: at the end of each stage only)", lo=0)
    crack_pattern: bool = spec(True, doc="write crack_pattern.png")
    curve: dict | None = spec(None, doc="[output.curve] body, force, displacement: force-displacement figure")
    rotations: tuple = spec((), doc="deformable blocks (names or group names) whose rotation is written to history.csv: "
                               "NAME.rot [rad, counter-clockwise] in 2D, NAME.rotx/roty/rotz [rad, rotation vector] "
                               "in 3D")
    joints: tuple = spec((), doc="joints whose resultants are written to history.csv, each a pair of block or rigid "
                                 "body names [\"A\", \"B\"]: columns A|B.N (normal force, > 0 compression), A|B.T "
                                 "(tangential force) [N] and A|B.e (eccentricity from the joint's middle [m]; 3D "
                                 "|(e_t, e_s)|; empty while the joint is open) (output/joints.py)")
    joints_paraview: bool = spec(False, doc="write paraview/joints.pvd with the contacts: one point per joint (all "
                                            "contact points of a pair of bodies) at its point of application, its "
                                            "resultant force, N, T, eccentricity, half-width, inside")
    line_of_thrust: bool = spec(False, doc="write line_of_thrust.png (2D): the joints, their points of application "
                                           "and lines of action at the end of the run, and summary.json "
                                           "\"line_of_thrust\" (joints whose point is outside)")
    gauges: tuple = spec((), doc="displacement gauges, each {name, block, point}: history.csv NAME.ux, NAME.uy "
                                 "(3D: NAME.uz) [m], the displacement of the material point of deformable block "
                                 "`block` at `point` (its reference position, in length units)")


# ----------------------------------------------------------------------------- [[reference]]
@dataclass
class ReferenceSpec:
    """One `[[reference]]` entry: a measured or published force–displacement curve, band or peak, drawn on
    force_displacement.png and compared with the model's peak in summary.json (output/figures.py, output/summary.py).

    Its quantities are those of `[output.curve]`: the displacement of the curve's `displacement` dof (length, or
    rotation [rad] for r*) and the reaction of its `force` dof (force, or moment for r*), in the file's `units`
    (case.py converts them to SI). Three forms: a curve (`points` inline or a CSV `file`), optionally with a band
    (`band`: relative half-width, F(1 ± band); or `lower`/`upper` curves); or a peak only (`peak` and/or
    `peak_band`, optional `band` with `peak`, optional `displacement_at_peak`). Peaks are magnitudes (|F|), as the
    model's peak in summary.json."""
    label: str = spec(doc="where the data come from and how accurate they are (legend and summary.json)",
                      required=True)
    points: list | None = spec(None, doc="inline curve [[d, F], ...] (>= 2 points, displacements strictly "
                                         "monotone); after parsing: the curve in SI, from points or file")
    file: str | None = spec(None, doc="CSV file of the curve, relative to the case file (a header line allowed)")
    columns: list | None = spec(None, doc="[displacement column, force column] names in the CSV header "
                                          "(default: the first two columns)")
    band: float | None = spec(None, doc="relative half-width of a band F(1 ± band) around the curve or the peak",
                              lo=0.0)
    lower: list | None = spec(None, doc="lower curve of a band [[d, F], ...] (with upper; with a curve)")
    upper: list | None = spec(None, doc="upper curve of a band [[d, F], ...] (with lower; with a curve)")
    peak: float | None = spec(None, doc="reference peak |F| (peak-only form)", lo=0.0, lo_open=True)
    peak_band: tuple | None = spec(None, doc="[Fmin, Fmax] of the reference peak, 0 <= Fmin < Fmax (peak-only form)")
    displacement_at_peak: float | None = spec(None, doc="|d| at the reference peak (peak-only form)", lo=0.0)
    key: str = spec("reference", doc="the key path for messages", toml=False)
