"""The keys every `[lab]` test shares and the emitter that writes a specimen as an ordinary case (TOML data).

A lab test (docs/lab-tests.md) is a generator: from its `[lab]` table it writes one ordinary case per specimen —
bricks (`[[blocks]]`, or `[[rigid_bodies]]` with `bricks = "rigid"`), rigid plates with their drivers and forces
(`[[rigid_bodies]]`), the joint and plate interfaces (`[[interfaces]]`, the joint by the name of a `[laws.NAME]`
law), one quasi-static stage and the outputs the read-out needs — and `case.parse_case` validates it as any case
file, `runner.run_case` runs it. The test's own values are computed in SI and written in the file's units
(`Emitter.L`, `.F`, ...: v_file = v_SI / U[kind], U = case.UNIT_SYSTEMS[units]), so that the file's own tables
(materials, laws, contact, output, references) pass through unchanged, in their units.

Geometry convention (2D, expanded bricks as the wall builders): a brick of the specimen is the brick plus half a
joint on each bed face, `brick_height + joint_thickness` high, so neighbouring bricks touch (no initial gap) and
the joint's compliance is the interface law's (k_n, k_s).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass

from ..specs import spec

#: the groups of the generated bodies: the interfaces of a specimen are bricks-bricks (the joint law) and
#: bricks-plates (`plate_mu`)
BRICKS, PLATES = "bricks", "plates"
#: the tests: name -> module of fem_blocks.lab (each: SPEC, STANDARD, specimens, readout, plot)
TESTS = {"triplet_shear": "triplet",
         "couplet_tension": "bond_tension",
         "bond_wrench": "bond_wrench",
         "diagonal_compression": "diagonal",
         "compression": "compression"}


@dataclass
class SpecimenSpec:
    """Keys of `[lab]` common to every test (a test's spec class extends it). SI after reading."""
    test: str = spec(doc="the standard test (docs/lab-tests.md)", choices=tuple(TESTS), required=True)
    material: str = spec("brick", doc="the bricks' material: a [materials.NAME] table of the file (E, nu, rho, "
                                      "thickness)")
    joint: str = spec("joint", doc="the joints' law: a [laws.NAME] table of the file (law = KIND and its "
                                   "parameters, docs/laws.md)")
    bricks: str = spec("deformable", doc="'deformable' (finite elements of the material) or 'rigid' (the test "
                                         "then measures the joints alone)", choices=("deformable", "rigid"))
    brick_length: float = spec(0.21, doc="brick length (the joints' length in the plane of the model)",
                               unit="length", lo=0.0, lo_open=True)
    brick_height: float = spec(0.052, doc="brick height (without joint)", unit="length", lo=0.0, lo_open=True)
    joint_thickness: float = spec(0.010, doc="mortar joint thickness (bricks are expanded by it: brick_height + "
                                             "joint_thickness high)", unit="length", lo=0.0)
    mesh_size: float | None = spec(None, doc="element size of the deformable bricks (default: half the expanded "
                                             "brick's height)", unit="length", lo=0.0, lo_open=True)
    plate_mu: float = spec(0.0, doc="friction coefficient between the specimen and the steel plates (0: "
                                    "frictionless, as greased platens)", lo=0.0)
    steps: int = spec(400, doc="time steps of the loading per specimen (quasi-static: velocities reset every "
                               "step)", lo=2)


class Emitter:
    """One specimen's case data in the file's units. `base`: the file's own top-level tables (materials, laws,
    contact, output, reference, checks, units, name...), copied; `U`: the unit table of the file's `units`."""

    def __init__(self, base: dict, U: dict, lab: SpecimenSpec, name: str):
        self.data = copy.deepcopy(base)
        self.U, self.lab = U, lab
        self.data["name"] = name
        self.data.setdefault("gravity", [0.0, 0.0])
        for k in ("block_types", "blocks", "rigid_bodies", "interfaces", "stages"):
            self.data[k] = {} if k == "block_types" else []
        mat = base.get("materials", {}).get(lab.material, {})
        self.rho, self.thickness = mat.get("rho"), mat.get("thickness")   # file units, as written

    # SI -> file units
    def L(self, v): return float(v) / self.U["length"]          # noqa: E704
    def F(self, v): return float(v) / self.U["force"]           # noqa: E704
    def S(self, v): return float(v) / self.U["stress"]          # noqa: E704
    def T(self, v): return float(v) / self.U["time"]            # noqa: E704

    def brick(self, name: str, x0: float, y0: float, lx: float, ly: float, parent: int | None = None,
              divisions: int = 1):
        """A brick [x0, x0+lx] x [y0, y0+ly] (SI) of group "bricks": a deformable block of a rectangle block type
        (one per size) or, with bricks = "rigid", a free rigid body of the material's density, a polygon whose bottom
        and top faces have `divisions` equal edges (collinear vertices: more contact points in a joint between rigid
        bricks, lab/bond.py). `parent` (deformable bricks only): the id shared by the two halves of a split brick
        (`split_brick`)."""
        if self.lab.bricks == "rigid":
            xs = [x0 + lx * i / divisions for i in range(divisions + 1)]
            v = [(x, y0) for x in xs] + [(x, y0 + ly) for x in reversed(xs)]
            rb = dict(name=name, group=BRICKS, vertices=[[self.L(a), self.L(b)] for a, b in v])
            if self.rho is not None:
                rb["rho"] = self.rho
            if self.thickness is not None:
                rb["thickness"] = self.thickness
            self.data["rigid_bodies"].append(rb)
            return
        tname = f"brick_{self.L(lx):g}x{self.L(ly):g}"
        if tname not in self.data["block_types"]:
            h = self.lab.mesh_size if self.lab.mesh_size is not None else 0.5 * (self.lab.brick_height
                                                                                 + self.lab.joint_thickness)
            self.data["block_types"][tname] = dict(geometry="rectangle", lx=self.L(lx), ly=self.L(ly),
                                                   mesh_size=self.L(h), cell="quad", material=self.lab.material)
        self.data["blocks"].append(dict(name=name, type=tname, position=[self.L(x0), self.L(y0)], group=BRICKS))
        if parent is not None:
            self.data["blocks"][-1]["parent"] = int(parent)

    def split_brick(self, name: str, x0: float, y0: float, lx: float, ly: float, parent: int):
        """A brick with a potential vertical crack in its middle (Lourenço's micro-model, builders.split_bricks):
        two deformable halves NAMEa (left) and NAMEb (right) of lx/2 sharing the id `parent` (an integer >= 0,
        unique per brick); `interfaces(crack=LAW)` joins them by the "crack" interface."""
        self.brick(f"{name}a", x0, y0, 0.5 * lx, ly, parent=parent)
        self.brick(f"{name}b", x0 + 0.5 * lx, y0, 0.5 * lx, ly, parent=parent)

    def plate(self, name: str, x0: float, y0: float, x1: float, y1: float, drivers: dict | None = None,
              forces: dict | None = None):
        """A rigid steel plate [x0, x1] x [y0, y1] (SI) of group "plates". `drivers`: dof -> ("displacement" |
        "velocity", history in SI: a number or {times, values}); dofs without driver or force are held (velocity
        0). `forces`: dof -> force history [N] (SI)."""
        drivers, forces = dict(drivers or {}), dict(forces or {})
        drv = {}
        for dof in ("x", "y", "rz"):
            if dof in forces:
                continue
            kind, hist = drivers.get(dof, ("velocity", 0.0))
            conv = self.L if dof != "rz" else float
            if kind == "velocity":
                conv = (lambda v, c=conv: c(v) * self.U["time"])
            drv[dof] = dict(kind=kind, history=self._history(hist, conv))
        rb = dict(name=name, group=PLATES, vertices=[[self.L(x0), self.L(y0)], [self.L(x1), self.L(y0)],
                                                     [self.L(x1), self.L(y1)], [self.L(x0), self.L(y1)]],
                  drivers=drv)
        if forces:
            rb["forces"] = {d: self._history(h, self.F) for d, h in forces.items()}
            rb["rho"] = self.rho if self.rho is not None else 7850.0 / self.U["density"]   # steel if unknown
        if self.thickness is not None:
            rb["thickness"] = self.thickness
        self.data["rigid_bodies"].append(rb)

    def _history(self, h, conv):
        if isinstance(h, dict):
            return dict(times=[self.T(t) for t in h["times"]], values=[conv(v) for v in h["values"]])
        return conv(h)

    def interfaces(self, crack: str | None = None, **joint_keys):
        """The joint interface (bricks-bricks, law = the [laws] name `lab.joint`) and the plates' (bricks-plates,
        Coulomb with `plate_mu`); with `crack` (the name of a [laws.NAME] law) also the "crack" interface between
        the two halves of each split brick (orientation "crack", the same `joint_keys`)."""
        self.data["interfaces"] += [dict(name="joint", between=[BRICKS, BRICKS], law=self.lab.joint, **joint_keys),
                                    dict(name="plates", between=[BRICKS, PLATES], mu=self.lab.plate_mu)]
        if crack is not None:
            self.data["interfaces"].append(dict(name="crack", between=[BRICKS, BRICKS], orientation="crack",
                                                law=crack, **joint_keys))

    def stage(self, name: str, steps: int, duration: float = 1.0, output_frames: int = 20):
        """One quasi-static stage: `steps` steps over `duration` (a pseudo-time [s]; velocities reset every step,
        θ = 1)."""
        self.data["stages"].append(dict(name=name, duration=self.T(duration), h=self.T(duration / steps),
                                        theta=1.0, velocity_reset=True,
                                        output_every=max(1, steps // output_frames)))

    def defaults(self, table: str, **values):
        """The test's defaults of an ordinary table ([contact], [output]) under the file's own keys."""
        self.data[table] = {**values, **self.data.get(table, {})}
