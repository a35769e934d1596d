"""3D contact detection (node-to-face) and 3D G blocks on plain arrays (no dolfinx)."""
import numpy as np
import pytest
from scipy.optimize import minimize

from fem_blocks import delassus
from fem_blocks.contact import detection_3d as d3
from fem_blocks.contact import kinematics_3d as k3
from fem_blocks.contact.matching import match
from fem_blocks.errors import InputError

from _split_detection import check_parts

HEX_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
UNIT = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)


def box(origin=(0, 0, 0), size=(1, 1, 1), R=None, center=None):
    """8 corners and 6 outward quads of a box [origin, origin+size], optionally rotated by R about `center`."""
    V = UNIT * np.asarray(size, float) + np.asarray(origin, float)
    if R is not None:
        c = np.asarray(center, float)
        V = (V - c) @ R.T + c
    return V, HEX_FACES.copy()


def tri(F):
    """Each quad (a, b, c, d) -> triangles (a, b, c), (a, c, d): same orientation."""
    return np.concatenate([F[:, [0, 1, 2]], F[:, [0, 2, 3]]])


def rot(axis, a):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def detect(bodies, table=None, kind=None, **kw):
    flat = d3.flatten_boundaries([b[0] for b in bodies], [b[1] for b in bodies])
    nb = len(bodies)
    kind = np.zeros(nb, int) if kind is None else np.asarray(kind)
    return d3.detect(*flat, kind, np.zeros(nb, int), table or d3.simple_table(), **kw), flat


def check_frame(cs):
    F = np.stack([cs.n, cs.t, cs.s], axis=1)  # rows n, t, s
    assert np.abs(np.einsum("kij,klj->kil", F, F) - np.eye(3)).max() < 1e-14
    assert np.allclose(np.linalg.det(F), 1.0, atol=1e-14)
    assert np.abs(np.cross(cs.t, cs.s) - cs.n).max() < 1e-14  # (t, s, n) right-handed


def check_interpolation(cs, flat):
    """point = Σ cand_w X_cand, projection point - gap n = Σ ant_w X_ant (inside points), weights sum to 1."""
    bx, nbody, nloc = flat[0], flat[1], flat[2]
    start = np.searchsorted(nbody, np.arange(nbody.max() + 1))
    for nodes, w, body, x in ((cs.cand_nodes, cs.cand_w, cs.cand_body, cs.point),
                              (cs.ant_nodes, cs.ant_w, cs.ant_body, cs.point - cs.gap[:, None] * cs.n)):
        X = bx[start[body][:, None] + np.maximum(nodes, 0)] * (nodes >= 0)[..., None]
        assert np.abs(np.einsum("ck,ckj->cj", w, X) - x).max() < 1e-13
        assert np.abs(w.sum(axis=1) - 1).max() < 1e-14


# ----------------------------------------------------------------------------- detection
@pytest.mark.parametrize("delta", [0.0, 3.7e-4])
def test_stacked_cubes_face_to_face(delta):
    cs, flat = detect([box((0, 0, 1 + delta)), box((0, 0, 0))])
    assert len(cs) == 4
    assert np.all(cs.cand_body == 0) and np.all(cs.ant_body == 1)  # lower index is candidate
    assert np.all(cs.cand_face == 0) and np.all(cs.ant_face == 7)  # bottom of the upper, top of the lower
    assert np.abs(cs.gap - delta).max() < 1e-15
    assert np.array_equal(cs.n, np.tile([0.0, 0.0, 1.0], (4, 1)))
    pts = sorted(map(tuple, np.round(cs.point[:, :2], 15)))
    assert pts == [(0.25, 0.25), (0.25, 0.75), (0.75, 0.25), (0.75, 0.75)]
    assert np.allclose(cs.point[:, 2], 1 + delta, rtol=0, atol=1e-15)
    assert np.abs(cs.area - 0.25).max() < 1e-15 and abs(cs.area.sum() - 1.0) < 1e-14
    check_frame(cs)
    check_interpolation(cs, flat)
    assert np.all(cs.g0 == 0) and np.all(cs.interface == 0)
    assert len(np.unique(cs.key)) == 4


def test_offset_cube_and_triangle_rules():
    # the upper cube shifted by (0.5, 0.3): only its points above the lower cube's top face project inside
    cs, _ = detect([box((0.5, 0.3, 1)), box((0, 0, 0))])
    assert len(cs) == 1 and np.allclose(cs.point[0], [0.75, 0.55, 1])
    # triangulated faces: 3 points per triangle (area A/3) or the centroid (area A)
    V0, F0 = box((0, 0, 1))
    V1, F1 = box((0, 0, 0), size=(1.5, 1.2, 1))
    for rule, npt in ((3, 6), (1, 2)):
        cs, flat = detect([(V0, tri(F0)), (V1, tri(F1))], d3.simple_table(tri_rule=rule))
        assert len(cs) == npt and abs(cs.area.sum() - 1.0) < 1e-14
        assert np.abs(cs.area - 1.0 / npt).max() < 1e-15
        assert np.abs(cs.gap).max() < 1e-15 and np.allclose(cs.n, [0, 0, 1], atol=0)
        check_frame(cs)
        check_interpolation(cs, flat)
    cs, _ = detect([(V0, tri(F0)), (V1, tri(F1))])
    lam = np.array([[1 / 6, 1 / 6], [2 / 3, 1 / 6], [1 / 6, 2 / 3]])
    # triangles (0,3,2) and (0,2,1) of the bottom face of the upper cube, in the plane z = 1
    X = V0[[[0, 3, 2], [0, 2, 1]]]
    ref = np.concatenate([X[j, 0] + lam[:, :1] * (X[j, 1] - X[j, 0]) + lam[:, 1:] * (X[j, 2] - X[j, 0])
                          for j in range(2)])
    assert np.allclose(np.sort(cs.point, axis=0), np.sort(ref, axis=0), atol=1e-15)


def test_node_placement_areas_summed_over_faces():
    # upper body: a unit cube whose bottom face is split in 2 x 2 quads (9 nodes); node contacts on the
    # lower cube's top face; tributary areas: corners 1/16, edge mid-points 1/8, centre 1/4
    V = np.vstack([UNIT + [0, 0, 1], [[0.5, 0, 1], [1, 0.5, 1], [0.5, 1, 1], [0, 0.5, 1], [0.5, 0.5, 1]]])
    # 8: (0.5,0), 9: (1,0.5), 10: (0.5,1), 11: (0,0.5), 12: centre ; bottom quads ordered clockwise seen from
    # above (outward normal -z)
    F = np.array([[0, 11, 12, 8], [8, 12, 9, 1], [12, 10, 2, 9], [11, 3, 10, 12],
                  [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
    V1, F1 = box((0, 0, 0))
    cs, flat = detect([(V, F), (V1, F1)], d3.simple_table(placement="nodes"))
    assert len(cs) == 9 and len(np.unique(cs.key)) == 9
    byxy = {tuple(np.round(p[:2], 12)): a for p, a in zip(cs.point, cs.area)}
    assert byxy[(0.0, 0.0)] == pytest.approx(1 / 16, abs=1e-15)
    assert byxy[(0.5, 0.0)] == pytest.approx(1 / 8, abs=1e-15)
    assert byxy[(0.5, 0.5)] == pytest.approx(1 / 4, abs=1e-15)
    assert abs(cs.area.sum() - 1.0) < 1e-14
    assert np.all(cs.cand_nodes[:, 1:] == -1) and np.all(cs.cand_w[:, 0] == 1)
    check_interpolation(cs, flat)
    # re-detection after a small motion: every contact matched by (key, antagonist body)
    V2 = V + [1e-5, -2e-5, 1e-5]
    cs2, _ = detect([(V2, F), (V1, F1)], d3.simple_table(placement="nodes"))
    m = match(cs, cs2)
    assert np.all(m >= 0) and np.array_equal(cs.key[m], cs2.key)


def test_block_on_inclined_face_vs_analytic():
    alpha, beta, delta = 0.35, 0.02, 2e-4
    R = rot([0.3, 1.0, 0.0], alpha) @ rot([0, 0, 1], 0.4)
    # ramp: box [-2, 2]^2 x [-1, 0] rotated about the origin; its top face is the plane n·x = 0
    ramp = box((-2, -2, -1), (4, 4, 1), R, (0, 0, 0))
    n = R @ [0, 0, 1.0]
    # block: unit cube tilted by beta about its own x axis, lifted by delta along n
    Rb = R @ rot([1, 0, 0], beta)
    V = (UNIT - [0.5, 0.5, 0.0]) @ Rb.T + delta * n
    table = d3.simple_table(alert=0.05)
    cs, flat = detect([ramp, (V, HEX_FACES)], table, kind=[1, 0])  # rigid ramp is the antagonist
    assert len(cs) == 4 and np.all(cs.cand_body == 1) and np.all(cs.ant_body == 0)
    assert np.abs(cs.n - n).max() < 1e-14
    Xc = V[[0, 3, 2, 1]]  # bottom face corners
    sh = np.array([[(1 - x) * (1 - y) / 4, (1 + x) * (1 - y) / 4, (1 + x) * (1 + y) / 4, (1 - x) * (1 + y) / 4]
                   for x in (-0.5, 0.5) for y in (-0.5, 0.5)])
    pts = sh @ Xc
    gaps = pts @ n
    o = np.lexsort(np.round(cs.point, 9).T)
    oref = np.lexsort(np.round(pts, 9).T)
    assert np.abs(cs.point[o] - pts[oref]).max() < 1e-14
    assert np.abs(cs.gap[o] - gaps[oref]).max() < 1e-14
    assert gaps.max() - gaps.min() == pytest.approx(0.5 * np.sin(beta), rel=1e-12)  # tilt between the rows
    check_frame(cs)
    check_interpolation(cs, flat)


def test_thick_joint_and_alert():
    g0, alert = 0.01, 1e-3
    table = d3.simple_table(g0=g0, alert=alert)
    cs, _ = detect([box((0, 0, 1 + g0)), box((0, 0, 0))], table)
    assert len(cs) == 4 and np.allclose(cs.gap, g0, rtol=0, atol=1e-15) and np.all(cs.g0 == g0)
    assert len(detect([box((0, 0, 1 + g0 + 0.9 * alert)), box()], table)[0]) == 4
    assert len(detect([box((0, 0, 1 + g0 + 1.1 * alert)), box()], table)[0]) == 0
    # without a joint: nothing beyond the alert distance, and nothing between side faces that do not face
    assert len(detect([box((0, 0, 1 + 1.1 * alert)), box()])[0]) == 0
    assert len(detect([box((0, 0, 1 + 0.9 * alert)), box()])[0]) == 4
    # side contact with a partial overlap in z: of the candidate's points at z = 0.55 and 1.05, only those
    # at z = 0.55 project inside the antagonist's side face x = 1
    cs, _ = detect([box((1.0005, 0, 0.3)), box()])
    assert len(cs) == 2 and np.allclose(cs.point[:, 2], 0.55, rtol=0, atol=1e-15)
    assert np.array_equal(cs.n, [[1.0, 0, 0]] * 2) and np.allclose(cs.gap, 5e-4, rtol=0, atol=1e-15)


def test_warped_and_skewed_quad_projection_vs_brute_force():
    rng = np.random.default_rng(3)
    quads = [np.array([[0, 0, 0], [1.2, 0.1, 0.0], [1.4, 1.1, 0.0], [0.1, 0.9, 0.0]]),        # skewed, planar
             np.array([[0, 0, 0.0], [1.0, 0.0, 0.15], [1.1, 1.0, -0.1], [0.0, 0.8, 0.2]])]     # warped
    for X in quads:
        c0 = X.mean(axis=0)
        a = (-X[0] + X[1] + X[2] - X[3]) / 4
        b = (-X[0] - X[1] + X[2] + X[3]) / 4
        d = (X[0] - X[1] + X[2] - X[3]) / 4

        def x_of(u):
            return c0 + u[0] * a + u[1] * b + u[0] * u[1] * d

        g = np.linspace(-1.5, 1.5, 601)
        GU, GV = np.meshgrid(g, g, indexing="ij")
        grid = c0 + GU[..., None] * a + GV[..., None] * b + (GU * GV)[..., None] * d
        for _ in range(8):
            p = c0 + rng.uniform(-0.5, 0.5, 3) + [0, 0, rng.choice([-1, 1]) * rng.uniform(0.01, 0.2)]
            res = d3.project_point(X, np.array([[0, 1, 2, 3]]), 0, p)
            assert res["ok"]
            # brute force: grid search, then a tight local minimisation of |x(u) - p|^2
            k = np.unravel_index(np.argmin(((grid - p) ** 2).sum(-1)), GU.shape)
            bf = minimize(lambda u: ((x_of(u) - p) ** 2).sum(), [GU[k], GV[k]], method="Nelder-Mead",
                          options=dict(xatol=1e-13, fatol=1e-30, maxiter=20000))
            dist_bf = np.sqrt(bf.fun)
            assert abs(abs(res["gap"]) - dist_bf) < 1e-10
            assert np.abs(res["ref"] - bf.x).max() < 1e-7
            assert np.abs(x_of(res["ref"]) - res["x"]).max() < 1e-15
            # orthogonality: p - x_a is along n (exact stationarity)
            assert np.abs(p - res["x"] - res["gap"] * res["n"]).max() < 1e-12
            F = np.stack([res["n"], res["t"], res["s"]])
            assert np.abs(F @ F.T - np.eye(3)).max() < 1e-14 and np.linalg.det(F) == pytest.approx(1, abs=1e-14)
            xu = a + res["ref"][1] * d
            xv = b + res["ref"][0] * d
            nn = np.cross(xu, xv)
            assert np.abs(res["n"] - nn / np.linalg.norm(nn)).max() < 1e-14
            assert np.abs(res["t"] - xu / np.linalg.norm(xu)).max() < 1e-14


def test_areas_of_skewed_and_warped_candidate_faces():
    # a candidate body whose bottom face is a skewed planar quad, then a warped one, over a large slab
    slab = box((-2, -2, -1), (5, 5, 1))
    Xs = np.array([[0, 0, 0], [0.1, 0.9, 0.0], [1.4, 1.1, 0.0], [1.2, 0.1, 0.0]])  # clockwise from above
    top = Xs + [0, 0, 1]
    V = np.vstack([Xs, top])
    F = np.array([[0, 1, 2, 3], [4, 7, 6, 5], [0, 3, 7, 4], [3, 2, 6, 7], [2, 1, 5, 6], [1, 0, 4, 5]])
    cs, _ = detect([(V, F), slab])
    exact = 0.5 * np.linalg.norm(np.cross(Xs[2] - Xs[0], Xs[1] - Xs[3]))
    assert len(cs) == 4 and abs(cs.area.sum() - exact) < 1e-14
    # planar bilinear quad: |x_ξ × x_η| is affine in (ξ, η), so the area of the unit cell around the point
    # (ξ, η) = (±1/2, ±1/2) is |x_ξ × x_η| at that point (the four are different on this skewed quad)
    X = Xs[[0, 1, 2, 3]]
    a, b, d = (-X[0] + X[1] + X[2] - X[3]) / 4, (-X[0] - X[1] + X[2] + X[3]) / 4, (X[0] - X[1] + X[2] - X[3]) / 4
    xi = cs.cand_w @ [-1.0, 1, 1, -1]  # bilinear weights reproduce the corner coordinates
    eta = cs.cand_w @ [-1.0, -1, 1, 1]
    assert np.abs(np.abs(xi) - 0.5).max() < 1e-15 and np.abs(np.abs(eta) - 0.5).max() < 1e-15
    J = np.linalg.norm(np.cross(a + eta[:, None] * d, b + xi[:, None] * d), axis=1)
    assert np.abs(cs.area - J).max() < 1e-15
    assert np.ptp(cs.area) > 0.02  # not a uniform split
    # 0.25/0.75 cells of a skewed quad are not equal: compare each with its own exact bilinear integral
    Vw = V.copy()
    Vw[1, 2] = 0.05
    Vw[3, 2] = 0.03
    cs, _ = detect([(Vw, F), slab], d3.simple_table(alert=0.1))
    X = Vw[[0, 1, 2, 3]]
    c0, a, b, d = X.mean(0), (-X[0] + X[1] + X[2] - X[3]) / 4, (-X[0] - X[1] + X[2] + X[3]) / 4, \
        (X[0] - X[1] + X[2] - X[3]) / 4
    gx, gw = np.polynomial.legendre.leggauss(64)
    U, W = np.meshgrid(gx, gx, indexing="ij")
    J = np.linalg.norm(np.cross(a + W[..., None] * d, b + U[..., None] * d), axis=-1)
    A_fine = (np.outer(gw, gw) * J).sum()
    assert len(cs) == 4 and abs(cs.area.sum() - A_fine) < 1e-12 * A_fine
    # the same warped face as antagonist (body 1, under a cube): projections interpolate on the bilinear patch
    up = box((0.3, 0.3, 0.06), (0.5, 0.5, 0.5))
    Vf = Vw.copy()
    Vf[:, 2] = -Vf[:, 2]
    Vf[4:, 2] = -1.0
    Ff = F[:, ::-1]  # mirrored in z: reverse the orientation; the warped face is now the top (face 0)
    cs, flat = detect([up, (Vf, Ff)], d3.simple_table(alert=0.1))
    assert len(cs) == 4 and np.all(cs.ant_face == 6)
    check_frame(cs)
    check_interpolation(cs, flat)
    for k in range(4):
        r = d3.project_point(Vf, Ff, 0, cs.point[k])
        assert r["inside"] and abs(r["gap"] - cs.gap[k]) < 1e-15 and np.abs(r["n"] - cs.n[k]).max() < 1e-15
        assert r["gap"] > 0.06 - 0.05 and np.abs(cs.point[k] - r["x"] - r["gap"] * r["n"]).max() < 1e-13


def test_many_blocks_contact_count():
    n, m, h = 20, 3, 6   # a 20 x 3 x 6 stack of unit cubes
    bodies = [box((i, j, k)) for i in range(n) for j in range(m) for k in range(h)]
    cs, _ = detect(bodies)
    faces = (n - 1) * m * h + n * (m - 1) * h + n * m * (h - 1)
    assert len(cs) == 4 * faces
    assert np.all(np.abs(cs.gap) < 1e-15) and np.allclose(cs.area, 0.25, rtol=0, atol=1e-15)
    assert np.all(cs.cand_body < cs.ant_body)
    pairs = np.unique(np.column_stack([cs.cand_body, cs.ant_body]), axis=0)
    assert len(pairs) == faces


def split_box(origin, size, nx):
    """A box [origin, origin + size] in nx elements along x (conforming quads, outward): its top and bottom faces
    have nodes at x0 + k size_x / nx."""
    o, (L, T, H) = np.asarray(origin, float), size
    V = np.array([o + [i * L / nx, j * T, k * H] for i in range(nx + 1) for j in (0, 1) for k in (0, 1)])

    def n(i, j, k):
        return 4 * i + 2 * j + k
    F = []
    for i in range(nx):
        F += [[n(i, 0, 0), n(i, 1, 0), n(i + 1, 1, 0), n(i + 1, 0, 0)], [n(i, 0, 1), n(i + 1, 0, 1), n(i + 1, 1, 1),
              n(i, 1, 1)], [n(i, 0, 0), n(i + 1, 0, 0), n(i + 1, 0, 1), n(i, 0, 1)],
              [n(i + 1, 1, 0), n(i, 1, 0), n(i, 1, 1), n(i + 1, 1, 1)]]
    F += [[n(0, 1, 0), n(0, 0, 0), n(0, 0, 1), n(0, 1, 1)], [n(nx, 0, 0), n(nx, 1, 0), n(nx, 1, 1), n(nx, 0, 1)]]
    return V, np.array(F)


@pytest.mark.parametrize("placement", ["nodes", "positions"])
def test_detection_of_some_candidate_bodies_is_the_whole_detections_rows(placement):
    """detect(..., bodies=mask) (a rank's own bodies on N > 1 ranks) gives the whole detection's contacts whose
    candidate body is in the mask, every field bit for bit and in the same order, and the parts of a partition merged
    by (key, antagonist body) give the whole set. A running-bond wall of 3 courses on a rigid foundation (body 0,
    numbered below the bricks that are its candidates), each brick in 1 to 3 elements along its length drawn at
    random (nodes at the head joints of the course above: a node point facing two bricks, its area summed over its
    candidate faces), courses lifted by up to half the alert distance. Expectation: the whole detection (tested
    above). Catches: a body pair of the mask dropped (a contact lost, e.g. with the foundation), the matches not
    filtered by their candidate (another rank's contacts kept)."""
    rng = np.random.default_rng(5)
    L, T, H = 0.5, 0.3, 0.25
    bodies = [box((-0.5, -0.1, -0.2), (3.0, 0.5, 0.2))]
    for row in range(3):
        for k in range(4 + row % 2):
            x0 = k * L - (0.5 * L if row % 2 else 0.0) + rng.uniform(-1e-4, 1e-4)
            bodies.append(split_box((x0, 0.0, row * H + rng.uniform(0.0, 5e-4)), (L, T, H), int(rng.integers(1, 4))))
    nb = len(bodies)
    flat = d3.flatten_boundaries([b[0] for b in bodies], [b[1] for b in bodies])
    kind = (np.arange(nb) == 0).astype(int)
    args = (*flat, kind, np.zeros(nb, int), d3.simple_table(placement=placement))
    whole = d3.detect(*args)
    assert len(whole) > 60 and np.any(whole.ant_body == 0) and np.all(whole.cand_body != 0)
    if placement == "nodes":  # nodes facing two bodies: one contact per (key, antagonist body)
        assert len(np.unique(whole.key)) < len(whole)
    check_parts(d3.detect, args, whole, nb, rng, placement)
    with pytest.raises(InputError, match=rf"bodies: expected {nb} booleans \(one per body\), got bool \({nb - 1},\)"):
        d3.detect(*args, bodies=np.ones(nb - 1, dtype=bool))


# ----------------------------------------------------------------------------- broad phase
def test_box_pairs_vs_brute_force():
    rng = np.random.default_rng(0)
    n = 400
    lo = rng.integers(0, 20, (n, 3)).astype(float)
    hi = lo + rng.integers(0, 5, (n, 3))
    lo[:3] = [[0, 0, 0], [10, 0, 5], [-3, 2, 2]]
    hi[:3] = [[30, 2, 3], [11, 25, 6], [5, 5, 25]]  # a few long boxes; integer corners -> many touching
    pairs = d3.box_pairs(lo, hi)
    ov = np.all((lo[:, None] <= hi[None]) & (lo[None] <= hi[:, None]), axis=2)
    i, j = np.nonzero(np.triu(ov, 1))
    ref = np.column_stack([i, j])
    assert len(ref) > 500
    assert np.array_equal(pairs, ref[np.lexsort((ref[:, 1], ref[:, 0]))])
    for cell in (0.5, 7.0, 100.0):
        assert np.array_equal(d3.box_pairs(lo, hi, cell=cell), pairs)


# ----------------------------------------------------------------------------- kinematics
def _two_body_setup(kind):
    """Unit cube (body 0) tilted by 0.01 rad on a rotated 1.6 x 1.6 slab (body 1), gaps 1e-3 to 1.1e-2;
    flat W numbering: 24 nodal dofs (deformable) or 6 (rigid) per body."""
    Rb = rot([1, 2, 3], 0.3)
    c_low = np.array([0.2, -0.1, 0.3])
    low = box(c_low - [0.8, 0.8, 0.5], (1.6, 1.6, 0.5), Rb, c_low)
    up = box(c_low - [0.5, 0.5, 0], (1, 1, 1), Rb @ rot([1, 0, 0], 0.01), c_low)
    up = (up[0] + 0.006 * (Rb @ [0, 0, 1.0]), up[1])
    cs, flat = detect([up, low], d3.simple_table(alert=0.02), kind=kind)
    assert len(cs) == 4 and len(np.unique(cs.cand_body)) == 1 and np.all(cs.ant_body != cs.cand_body)
    assert cs.gap.min() > 5e-4 and cs.gap.max() < 0.012
    centers = np.array([up[0].mean(0), low[0].mean(0)]) + [[0.1, -0.2, 0.05], [0.0, 0.3, -0.1]]
    size = np.where(np.asarray(kind) == 0, 3 * 8, 6)
    off = np.concatenate([[0], np.cumsum(size)])
    return cs, flat, centers, off, [up, low]


@pytest.mark.parametrize("kind", [(0, 0), (1, 0), (0, 1), (1, 1)])
def test_G_rigid_translation_and_rotation(kind):
    cs, flat, centers, off, bodies = _two_body_setup(list(kind))
    rng = np.random.default_rng(1)
    Rtype = np.stack([rot(rng.normal(size=3), rng.uniform(0, 3)) for _ in range(2)])  # type frame -> global
    G = k3.build_G(cs, np.array(kind), Rtype, centers)
    frame = np.stack([cs.n, cs.t, cs.s], axis=1)
    V, omega = np.array([0.3, -1.2, 0.7]), np.array([0.4, 0.1, -0.9])
    for side, sign in ((0, 1.0), (1, -1.0)):
        b = int((cs.cand_body if side == 0 else cs.ant_body)[0])
        x = cs.point if side == 0 else cs.point - cs.gap[:, None] * cs.n
        for rigid_motion in ("translation", "rotation"):
            U = np.zeros(off[-1])
            if kind[b] == 1:
                U[off[b]:off[b] + 6] = np.concatenate([V, 0 * V] if rigid_motion == "translation" else [0 * V, omega])
            else:  # nodal velocities of the motion, in the type frame: R^T v(X)
                X = bodies[b][0]
                vX = np.tile(V, (8, 1)) if rigid_motion == "translation" else np.cross(omega, X - centers[b])
                U[off[b]:off[b + 1]] = (vX @ Rtype[b]).ravel()
            v = k3.local_velocity(G, U, off)
            vg = np.tile(V, (len(cs), 1)) if rigid_motion == "translation" else np.cross(omega, x - centers[b])
            assert np.abs(v - sign * np.einsum("kij,kj->ki", frame, vg)).max() < 1e-14


def test_G_H_adjoint():
    cs, flat, centers, off, _ = _two_body_setup([0, 1])
    rng = np.random.default_rng(2)
    G = k3.build_G(cs, np.array([0, 1]), None, centers)
    for _ in range(5):
        u = rng.normal(size=off[-1])
        P = rng.normal(size=(len(cs), 3))
        lhs = np.sum(k3.local_velocity(G, u, off) * P)
        rhs = u @ k3.accumulate_impulse(G, P, off[-1], off)
        assert abs(lhs - rhs) < 1e-12 * (abs(lhs) + 1)


def test_G_uses_boundary_numbering():
    cs, _, centers, _, _ = _two_body_setup([0, 0])
    assert np.all(cs.cand_body == 0)
    # body 0's 8 nodes numbered in reverse in its W numbering; body 1 identity
    bidx = np.concatenate([np.arange(8)[::-1], np.arange(8)])
    G = k3.build_G(cs, np.array([0, 0]), None, None, bidx, np.array([0, 8]))
    G0 = k3.build_G(cs, np.array([0, 0]))
    assert np.array_equal(G.side_dofs[:, 0, 0::3], 3 * (7 - G0.side_dofs[:, 0, 0::3] // 3))
    assert np.array_equal(G.side_G, G0.side_G)
    with pytest.raises(InputError, match="not a boundary node"):
        k3.build_G(cs, np.array([0, 0]), None, None, np.concatenate([-np.ones(8, int), np.arange(8)]),
                   np.array([0, 8]))


# ----------------------------------------------------------------------------- bad input
def test_bad_input():
    V, F = box()
    with pytest.raises(InputError, match="non-finite"):
        Vb = V.copy()
        Vb[2, 1] = np.nan
        detect([(Vb, F), box((0, 0, 1))])
    with pytest.raises(InputError, match="zero area"):
        Vb = V.copy()
        Vb[[1, 2, 3]] = Vb[0]
        detect([(Vb, F), box((0, 0, 1))])
    with pytest.raises(InputError, match=r"\(n, 3\)"):
        detect([(V[:, :2], F), box((0, 0, 1))])
    with pytest.raises(InputError, match=r"node ids expected in \[0, 8\)"):
        detect([(V, F + 1), box((0, 0, 1))])
    with pytest.raises(InputError, match="tri_rule"):
        detect([box(), box((0, 0, 1))], d3.simple_table(tri_rule=2))


def test_running_bond_wall_count_and_area():
    # rows of n bricks 0.5 x 0.3 x 0.25, odd rows shifted by a quarter brick: 4 points per head joint;
    # on each bed joint every lower brick keeps its 4 points except the 2 beyond the upper row's end
    n, rows, L, T, H = 20, 10, 0.5, 0.3, 0.25
    bodies = [box((i * L + (L / 2 if k % 2 else 0), 0, k * H), (L, T, H)) for k in range(rows) for i in range(n)]
    cs, flat = detect(bodies)
    n_head, n_bed = rows * (n - 1) * 4, (rows - 1) * (4 * n - 2)
    assert len(cs) == n_head + n_bed
    bed = np.abs(cs.n[:, 2]) > 0.5
    assert bed.sum() == n_bed and np.array_equal(cs.n[bed], np.tile([0, 0, -1.0], (n_bed, 1)))  # upper = antagonist
    assert abs(cs.area.sum() - (rows * (n - 1) * H * T + (rows - 1) * (n * L - L / 2) * T)) < 1e-12
    assert np.all(cs.cand_body < cs.ant_body) and np.all(np.abs(cs.gap) < 1e-15)
    check_interpolation(cs, flat)


def test_delassus3d_vs_dense():
    # 3 bodies (deformable, rigid, deformable) in a column: W_del = G W Gᵀ with G assembled densely
    bodies = [box((0, 0, 2)), box((0, 0, 1)), box((0.1, 0.2, 0))]
    kind = np.array([0, 1, 0])
    cs, _ = detect(bodies, kind=kind)
    assert len(cs) == 8
    centers = np.array([b[0].mean(0) for b in bodies])
    G = k3.build_G(cs, kind, None, centers)
    size = np.where(kind == 0, 24, 6)
    off = np.concatenate([[0], np.cumsum(size)])
    rng = np.random.default_rng(4)
    Ws = [(lambda A: A @ A.T)(rng.normal(size=(m, m))) for m in size]
    W_offset = np.concatenate([[0], np.cumsum(size ** 2)[:-1]])
    D = delassus.assemble(G, np.concatenate([w.ravel() for w in Ws]), W_offset, size, 3)
    Gd = np.zeros((3 * len(cs), off[-1]))
    for j in range(off[-1]):
        e = np.zeros(off[-1])
        e[j] = 1.0
        Gd[:, j] = k3.local_velocity(G, e, off).ravel()
    from scipy.linalg import block_diag
    ref = Gd @ block_diag(*Ws) @ Gd.T
    dense = D.to_scipy().toarray()
    assert np.abs(dense - ref).max() < 1e-12 * np.abs(ref).max()
    assert np.all(D.indices[D.diag_pos] == np.arange(len(cs)))


@pytest.mark.parametrize("placement", ["positions", "nodes"])
def test_update_geometry_rigid_motion_and_redetect(placement):
    bodies = [box((0.1, 0.2, 1 + 2e-4)), box((0, 0, 0), (1.5, 1.3, 1))]
    table = d3.simple_table(placement=placement)
    cs, flat = detect(bodies, table)
    assert len(cs) == 4
    # a rigid motion of the whole scene: same gaps, rotated frames, moved points
    R = rot([1, -2, 0.5], 0.7)
    c = np.array([0.3, -1.0, 2.0])
    bx2 = flat[0] @ R.T + c
    up = d3.update_geometry(cs, bx2, flat[3])
    assert np.abs(up.gap - cs.gap).max() < 1e-14
    for f in ("n", "t", "s"):
        assert np.abs(getattr(up, f) - getattr(cs, f) @ R.T).max() < 1e-14
    assert np.abs(up.point - (cs.point @ R.T + c)).max() < 1e-14 and np.abs(up.ant_w - cs.ant_w).max() < 1e-14
    # a small motion of the upper body: the same result as a fresh detection
    bx3 = flat[0].copy()
    bx3[:8] += [0.01, -0.02, 3e-4]
    up = d3.update_geometry(cs, bx3, flat[3])
    fresh = d3.detect(bx3, *flat[1:], np.zeros(2, int), np.zeros(2, int), table)
    m = match(cs, fresh)
    assert np.all(m >= 0)
    for f in ("point", "n", "t", "s", "gap", "ant_w", "ant_ref", "area"):
        assert np.abs(getattr(up, f)[m] - getattr(fresh, f)).max() < 1e-14, f
