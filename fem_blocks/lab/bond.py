"""What the two bond tests of a couplet share (lab/bond_tension.py, lab/bond_wrench.py; docs/lab-tests.md).

A couplet: two bricks `lower` [0, L] x [0, H] and `upper` [0, L] x [H, 2H] (H = brick_height + joint_thickness,
expanded bricks: the joint is the interface between them, law `[lab] joint`), 2D, thickness t (the material's):
the joint's area A = L t.

Glue. Contact is unilateral, so a plate can only pull a brick through an interface that carries tension: the
plates are glued to the bricks by the `elastic` law (docs/laws.md: adhesive part (c_N <u_N>+, c_T u_T), compliant
compression c_N; it has no strength, so it never opens or slides for good, whatever the load), with
c_N = c_T = GLUE_STIFFNESS E / H (E the bricks' modulus): the glue layer is GLUE_STIFFNESS times stiffer than a brick
over its height (an assumed value; an epoxied steel plate). It is in series with the joint, so it changes the
plates' displacements, not the force through the joint: the read-outs take the force from the plate's reaction and
the joint's opening or rotation from the bricks themselves (rigid bricks: their own displacements; deformable bricks:
displacement gauges at the joint's faces), never from the plates.

Rigid bricks (`bricks = "rigid"`) are polygons whose bed faces are cut into `divisions` equal edges (collinear
vertices: specimen.Emitter.brick), so the joint between them has divisions + 1 contact points (placement
"overlap": the trapezoidal rule, docs/case-files.md `placement`); deformable bricks have their mesh nodes.
"""
from __future__ import annotations

import numpy as np

from .specimen import BRICKS, PLATES

GLUE_STIFFNESS = 100.0   # glue stiffness c_N = c_T = GLUE_STIFFNESS E / H (assumed: far stiffer than a brick)

#: the tensile strength of the joint law, by law kind (the input a bond test measures): docs/laws.md
STRENGTH_KEY = {"mixed": "f_t", "brittle": "r_c"}


def height(s) -> float:
    """H: the expanded brick's height [m] (brick + one joint thickness)."""
    return s.brick_height + s.joint_thickness


def glue(e, s, groups=(PLATES,)):
    """The joint interface (bricks-bricks, the `[lab] joint` law) and the glue (bricks-GROUP, elastic law; module
    docstring) for each group of `groups`."""
    mat = e.data["materials"][s.material]
    k = GLUE_STIFFNESS * float(mat["E"]) / e.L(height(s))   # file units (stress / length)
    e.data["interfaces"].append(dict(name="joint", between=[BRICKS, BRICKS], law=s.joint))
    for g in groups:
        e.data["interfaces"].append(dict(name=f"glue_{g}", between=[BRICKS, g], law="elastic", c_N=k, c_T=k,
                                         mu=0.0))


def strength_input(s, case) -> tuple:
    """(key, value [Pa]) of the joint law's tensile strength (STRENGTH_KEY), or (None, None) for a law without one."""
    itf = next(i for i in case.interfaces if i.name == "joint")
    key = STRENGTH_KEY.get(getattr(itf, "law", None))
    if key is None:
        return None, None
    return f"laws.{s.joint}.{key}", float(itf.params[key])


def joint_gauges(s, xs) -> list:
    """Gauge pairs across the joint at abscissae xs [m] (SI; written by the caller in file units): one gauge on each
    brick at (x, H), the joint's face (the same material point of the reference configuration on both sides)."""
    H = height(s)
    return [(f"lo{i}", "lower", x, H) for i, x in enumerate(xs)] + [(f"up{i}", "upper", x, H)
                                                                      for i, x in enumerate(xs)]


def add_gauges(e, s, xs):
    if s.bricks == "rigid":
        return
    e.defaults("output", gauges=[dict(name=g, block=b, point=[e.L(x), e.L(y)]) for g, b, x, y in joint_gauges(s, xs)])


def opening_at(s, h, xs) -> np.ndarray:
    """(rows, len(xs)) joint opening [m] at the abscissae xs (> 0 opening): rigid bricks from their displacements
    u_y(p) = u_y + θ (p_x − c_x) at p = (x, H) (small rotation, centroids at x = L/2); deformable bricks from the
    gauges (up_i.uy − lo_i.uy)."""
    xs = np.asarray(xs, dtype=float)
    if s.bricks == "rigid":
        cx = 0.5 * s.brick_length

        def uy(b):
            return h[f"{b}.uy"][:, None] + h[f"{b}.urz"][:, None] * (xs[None, :] - cx)
        return uy("upper") - uy("lower")
    return np.stack([h[f"up{i}.uy"] - h[f"lo{i}.uy"] for i in range(len(xs))], axis=1)
