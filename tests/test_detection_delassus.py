"""Detection, G blocks and Delassus assembly on plain arrays (no dolfinx)."""
import numpy as np
import pytest

from fem_blocks import delassus
from fem_blocks.contact import detection_2d as det
from fem_blocks.contact import kinematics_2d as kin
from fem_blocks.contact.matching import match
from fem_blocks.contact.step import InterfaceSpec
from fem_blocks.errors import InputError


def squares(corners, size=1.0):
    """Boundary arrays of unit squares (4 CCW vertices each) at the given lower-left corners."""
    bx, body, local, edges, ebody = [], [], [], [], []
    for b, (x, y) in enumerate(corners):
        V = np.array([[x, y], [x + size, y], [x + size, y + size], [x, y + size]])
        s = 4 * b
        bx.append(V)
        body += [b] * 4
        local += [0, 1, 2, 3]
        edges += [[s + k, s + (k + 1) % 4] for k in range(4)]
        ebody += [b] * 4
    return (np.concatenate(bx), np.array(body), np.array(local), np.array(edges), np.array(ebody))


def table(g0=0.0, alert=0.01, positions=(0.25, 0.75), placement="positions", candidate=None, ng=1):
    groups = {f"g{i}": i for i in range(ng)}
    itf = InterfaceSpec("j", ("g0", "g0" if ng == 1 else "g1"), g0=g0, alert=alert, positions=positions,
                        placement=placement, candidate=candidate)
    return det.build_table([itf], groups)


def test_two_stacked_squares_thick_joint():
    bx, body, local, edges, ebody = squares([(0, 0), (0, 1.01)])
    cs = det.detect(bx, body, local, edges, ebody, np.zeros(2, int), np.zeros(2, int), table(g0=0.01))
    assert len(cs) == 2
    assert np.all(cs.cand_body == 0) and np.all(cs.ant_body == 1)  # lower index is candidate
    assert np.allclose(cs.gap, 0.01, rtol=1e-12) and np.allclose(cs.g0, 0.01)
    assert np.allclose(cs.n, [[0, -1]] * 2) and np.allclose(cs.t, [[1, 0]] * 2)
    assert sorted(cs.point[:, 0]) == pytest.approx([0.25, 0.75]) and np.allclose(cs.point[:, 1], 1.0)
    assert np.allclose(cs.area, 0.5)
    # swapping the bodies swaps the roles, never both directions
    bx2, body2, local2, edges2, ebody2 = squares([(0, 1.01), (0, 0)])
    cs2 = det.detect(bx2, body2, local2, edges2, ebody2, np.zeros(2, int), np.zeros(2, int), table(g0=0.01))
    assert len(cs2) == 2 and np.all(cs2.cand_body == 0) and np.allclose(cs2.n, [[0, 1]] * 2)


def test_rigid_is_antagonist_and_candidate_group_rule():
    bx, body, local, edges, ebody = squares([(0, 0), (0, 1.0)])
    kind = np.array([1, 0])  # body 0 rigid
    cs = det.detect(bx, body, local, edges, ebody, kind, np.zeros(2, int), table())
    assert np.all(cs.cand_body == 1) and np.allclose(cs.n, [[0, 1]] * 2)
    cs = det.detect(bx, body, local, edges, np.array([0, 0, 0, 0, 1, 1, 1, 1]), np.zeros(2, int),
                    np.array([0, 1]), table(candidate="g1", ng=2))
    assert np.all(cs.cand_body == 1)


def test_separated_and_outside_points_dropped():
    bx, body, local, edges, ebody = squares([(0, 0), (0, 1.05)])
    assert len(det.detect(bx, body, local, edges, ebody, np.zeros(2, int), np.zeros(2, int), table())) == 0
    bx, body, local, edges, ebody = squares([(0, 0), (0.6, 1.0)])  # half overlap: 0.25 point of the lower
    cs = det.detect(bx, body, local, edges, ebody, np.zeros(2, int), np.zeros(2, int), table())
    assert len(cs) == 1 and cs.point[0, 0] == pytest.approx(0.75)


def test_grid_of_blocks_contact_count_and_match():
    n = 50
    corners = [(i * 1.0, j * 1.0) for i in range(n) for j in range(n)]
    bx, body, local, edges, ebody = squares(corners)
    cs = det.detect(bx, body, local, edges, ebody, np.zeros(n * n, int), np.zeros(n * n, int), table())
    assert len(cs) == 2 * (2 * n * (n - 1))  # 2 points per internal face
    assert len(np.unique(cs.key)) == len(cs)
    cs2 = det.detect(bx + 1e-4, body, local, edges, ebody, np.zeros(n * n, int), np.zeros(n * n, int), table())
    m = match(cs, cs2)
    assert np.all(m >= 0) and np.array_equal(cs.key[m], cs2.key)


def test_nodes_placement_no_duplicates():
    # body 1 bottom edge split into two edges sharing the middle node
    bx = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 1], [0.5, 1], [1, 1], [1, 2], [0, 2.0]])
    body = np.array([0, 0, 0, 0, 1, 1, 1, 1, 1])
    local = np.array([0, 1, 2, 3, 0, 1, 2, 3, 4])
    edges = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 8], [8, 4]])
    ebody = np.array([0, 0, 0, 0, 1, 1, 1, 1, 1])
    cs = det.detect(bx, body, local, edges, ebody, np.array([1, 0]), np.zeros(2, int), table(placement="nodes"))
    assert len(cs) == 3
    assert sorted(cs.point[:, 0]) == pytest.approx([0, 0.5, 1])
    assert sorted(cs.area) == pytest.approx([0.25, 0.25, 0.5])


def test_overlap_and_degenerate_edge():
    bx, body, local, edges, ebody = squares([(0, 0), (0.2, 0.9)])
    assert det.find_overlap(bx, body, edges, ebody, 1e-3)[:2] == (0, 1)
    bx, body, local, edges, ebody = squares([(0, 0), (0, 1.0)])
    assert det.find_overlap(bx, body, edges, ebody, 1e-3) is None  # touching is not overlapping
    bx[5] = bx[4]
    with pytest.raises(InputError, match="body 1: boundary edge 4 has zero length"):
        det.detect(bx, body, local, edges, ebody, np.zeros(2, int), np.zeros(2, int), table())


def scene_G(seed=0):
    """Two deformable bodies of one type (one rotated) and a rigid body with a driven dof, random contacts."""
    rng = np.random.default_rng(seed)
    nbn = 6  # boundary nodes per deformable body
    A = rng.standard_normal((2 * nbn, 2 * nbn))
    Wd = A @ A.T + np.eye(2 * nbn)
    Wr = np.diag([1 / 3.0, 1 / 3.0, 0.0])  # rigid: rz driven
    kind = np.array([0, 0, 1])
    ang = np.deg2rad(30)
    rot = np.array([np.eye(2), [[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]], np.eye(2)])
    center = np.array([[0, 0], [0, 0], [0.3, -0.2]])
    bnode_index_flat = np.concatenate([np.arange(nbn), np.arange(4)])
    bnode_offset = np.array([0, 0, nbn])
    nc = 7
    pairs = np.array([[0, 1], [0, 2], [1, 2], [1, 0], [0, 1], [2, 0], [1, 2]])
    cs = det.ContactSet(
        cand_body=pairs[:, 0], ant_body=pairs[:, 1],
        cand_nodes=np.array([rng.choice(nbn if k == 0 else 4, 2, replace=False) for k in kind[pairs[:, 0]]]),
        ant_nodes=np.array([rng.choice(nbn if k == 0 else 4, 2, replace=False) for k in kind[pairs[:, 1]]]),
        cand_w=np.column_stack([w := rng.random(nc), 1 - w]), ant_w=np.column_stack([v := rng.random(nc), 1 - v]),
        point=rng.random((nc, 2)), n=None, t=None, gap=rng.random(nc) * 0.01, g0=np.zeros(nc), area=np.ones(nc),
        interface=np.zeros(nc, int), cand_edge=np.zeros(nc, int), ant_edge=np.zeros(nc, int), key=np.arange(nc))
    th = rng.random(nc) * 2 * np.pi
    cs.n = np.column_stack([np.cos(th), np.sin(th)])
    cs.t = np.column_stack([-cs.n[:, 1], cs.n[:, 0]])
    G = kin.build_G(cs, kind, rot, center, bnode_index_flat, bnode_offset)
    W_flat = np.concatenate([Wd.ravel(), Wr.ravel()])
    W_offset = np.array([0, 0, Wd.size])
    W_size = np.array([2 * nbn, 2 * nbn, 3])
    U_offset = np.array([0, 2 * nbn, 4 * nbn, 4 * nbn + 3])
    return cs, G, kind, rot, center, (W_flat, W_offset, W_size), U_offset, Wd, Wr, nbn


def test_G_matches_independent_relative_velocity_and_transpose():
    cs, G, kind, rot, center, Wb, U_offset, Wd, Wr, nbn = scene_G()
    rng = np.random.default_rng(1)
    U = rng.standard_normal(U_offset[-1])
    v = kin.local_velocity(G, U, U_offset)

    def vel(b, nodes, w, x):
        if kind[b] == 0:
            u = U[U_offset[b]:U_offset[b + 1]].reshape(-1, 2)
            return rot[b] @ (w[0] * u[nodes[0]] + w[1] * u[nodes[1]])
        vx, vy, om = U[U_offset[b]:U_offset[b] + 3]
        d = x - center[b]
        return np.array([vx - om * d[1], vy + om * d[0]])

    for a in range(len(cs.gap)):
        xa = cs.point[a] - cs.gap[a] * cs.n[a]
        dv = vel(cs.cand_body[a], cs.cand_nodes[a], cs.cand_w[a], cs.point[a]) - \
            vel(cs.ant_body[a], cs.ant_nodes[a], cs.ant_w[a], xa)
        assert v[a] == pytest.approx([dv @ cs.n[a], dv @ cs.t[a]], abs=1e-12)
    P = rng.standard_normal((len(cs.gap), 2))
    HP = kin.accumulate_impulse(G, P, U_offset[-1], U_offset)
    assert np.sum(P * v) == pytest.approx(HP @ U, rel=1e-12)


def test_delassus_equals_dense_G_W_Gt():
    cs, G, kind, rot, center, Wb, U_offset, Wd, Wr, nbn = scene_G(seed=3)
    B = delassus.assemble(G, *Wb, nb=3)
    nc = len(cs.gap)
    Gd = np.zeros((2 * nc, U_offset[-1]))
    for a in range(nc):
        for s in range(2):
            b = G.side_body[a, s]
            for j in range(4):
                d = G.side_dofs[a, s, j]
                if d >= 0:
                    Gd[2 * a:2 * a + 2, U_offset[b] + d] += G.side_G[a, s, :, j]
    Wfull = np.zeros((U_offset[-1], U_offset[-1]))
    Wfull[:2 * nbn, :2 * nbn] = Wd
    Wfull[2 * nbn:4 * nbn, 2 * nbn:4 * nbn] = Wd
    Wfull[4 * nbn:, 4 * nbn:] = Wr
    ref = Gd @ Wfull @ Gd.T
    D = delassus.dense(B)
    assert np.abs(D - ref).max() <= 1e-12 * np.abs(ref).max()
    assert np.allclose(D, D.T, atol=1e-12 * np.abs(D).max())
    assert np.linalg.eigvalsh(D).min() > -1e-10 * np.abs(D).max()
    assert np.array_equal(B.indices[B.diag_pos], np.arange(nc))


def test_rigid_lever_arm_closed_form():
    """One contact on a rigid body (m, I) at lever arm d from the centre, normal along x: w_NN = 1/m + d^2/I."""
    m, I, d = 2.0, 0.5, 0.3
    cs = det.ContactSet(cand_body=np.array([0]), ant_body=np.array([1]), cand_nodes=np.array([[0, 1]]),
                        ant_nodes=np.array([[0, 1]]), cand_w=np.array([[1.0, 0.0]]), ant_w=np.array([[1.0, 0.0]]),
                        point=np.array([[0.0, d]]), n=np.array([[1.0, 0.0]]), t=np.array([[0.0, 1.0]]),
                        gap=np.zeros(1), g0=np.zeros(1), area=np.ones(1), interface=np.zeros(1, int),
                        cand_edge=np.zeros(1, int), ant_edge=np.zeros(1, int), key=np.zeros(1, int))
    G = kin.build_G(cs, np.array([1, 1]), np.array([np.eye(2)] * 2), np.zeros((2, 2)), np.arange(4), np.zeros(2, int))
    W_flat = np.concatenate([np.diag([1 / m, 1 / m, 1 / I]).ravel(), np.zeros(9)])  # body 1 fully driven
    B = delassus.assemble(G, W_flat, np.array([0, 9]), np.array([3, 3]), nb=2)
    D = delassus.dense(B)
    assert D[0, 0] == pytest.approx(1 / m + d * d / I, rel=1e-14)
    assert D[1, 1] == pytest.approx(1 / m, rel=1e-14)
    assert D[0, 1] == pytest.approx(0.0, abs=1e-15)


def test_grid_pairs_2d_groups_vs_brute_force():
    # the broad phase shared with 3D, in 2D: every overlapping (touching) pair of boxes of different groups, once
    from fem_blocks.contact.broadphase import grid_pairs
    rng = np.random.default_rng(3)
    n = 300
    lo = rng.integers(0, 15, (n, 2)).astype(float)
    hi = lo + rng.integers(0, 4, (n, 2))
    lo[:2], hi[:2] = [[0, 0], [7, -2]], [[20, 1], [8, 18]]  # two long boxes
    group = rng.integers(0, 60, n)
    ov = np.all((lo[:, None] <= hi[None]) & (lo[None] <= hi[:, None]), axis=2) & (group[:, None] != group[None])
    i, j = np.nonzero(np.triu(ov, 1))
    assert len(i) > 300
    for cell in (0.5, 3.0, 50.0):
        pairs = grid_pairs(lo, hi, group, cell)
        assert np.array_equal(pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))], np.column_stack([i, j]))


def test_coupling_blocks_only_are_the_coupling_rows_of_the_whole_operator_bitwise():
    """In colour order the assembly keeps only the blocks that couple (delassus.assemble couplings=True), so the
    colour solver sweeps W's own arrays rather than a copy without the blocks of zeros: they must be
    `coupling_rows` of the whole assembly, bit for bit, also for a rank's rows. Expectation: the whole assembly
    (checked against the dense G W Gᵀ above) through coupling_rows (checked against the dense W in
    tests/test_colour.py). The rigid body is held in every dof (W = 0), so the contacts that share only it have
    blocks of zeros. Catches: a diagonal block of zeros dropped, a block kept or dropped by its first entry only,
    a row's indptr or diag_pos not moved with its blocks."""
    from fem_blocks.distributed.colour import coupling_rows
    cs, G, kind, rot, center, (W_flat, W_offset, W_size), U_offset, Wd, Wr, nbn = scene_G(seed=5)
    W_flat = W_flat.copy()
    W_flat[W_offset[2]:] = 0.0  # body 2 held in every dof
    B = delassus.assemble(G, W_flat, W_offset, W_size, nb=3)
    for rows in (None, np.array([1, 2, 5, 6]), np.array([6, 2, 5, 1])):
        E = coupling_rows(B if rows is None else delassus.assemble(G, W_flat, W_offset, W_size, nb=3, rows=rows))
        C = delassus.assemble(G, W_flat, W_offset, W_size, nb=3, rows=rows, couplings=True)
        assert C.indices.size < (B.indices.size if rows is None else B.indptr[rows + 1].sum() - B.indptr[rows].sum())
        for k in ("indptr", "indices", "blocks", "diag_pos"):
            assert np.array_equal(getattr(C, k), getattr(E, k)), k
    # a block with a single nonzero entry off its first one is kept (3 of its 4 entries zero)
    blocks = np.zeros((3, 2, 2))
    blocks[0, 0, 0] = blocks[2, 0, 0] = 1.0
    blocks[1, 1, 0] = 2.0
    ip, ix, dp = np.array([0, 2, 3]), np.array([0, 1, 1]), np.array([0, 2])
    assert delassus._drop_zero_blocks(ip, ix, blocks, dp) == 3


def test_rows_of_the_operator_are_its_rows_bitwise():
    """A rank assembles only the rows of its own contacts (delassus.assemble rows=) from the G blocks of a subset of
    the contacts (kin.build_G on cs.subset): both must be the whole operator's and the whole G's, bit for bit, or a
    distributed run would not reproduce the serial iterates. Expectation: the whole assembly, itself checked against
    the dense G W Gᵀ above. Catches: row i assembled for contact i instead of rows[i]; the diagonal position taken
    in the whole operator's numbering; a G block that depends on the other contacts of the set. Rows asked in
    another order than the contacts' (a colour solver's sweep order) come in that order: catches a row written at
    its computing position (the rows are computed in increasing contact number) instead of its output one."""
    cs, G, kind, rot, center, Wb, U_offset, Wd, Wr, nbn = scene_G(seed=5)
    B = delassus.assemble(G, *Wb, nb=3)
    for rows in (np.array([1, 4, 6]), np.array([6, 1, 4]), np.array([5, 0, 6, 2, 1, 4, 3])):
        R = delassus.assemble(G, *Wb, nb=3, rows=rows)
        assert R.n == len(rows)
        for i, a in enumerate(rows):
            s, e = B.indptr[a], B.indptr[a + 1]
            assert np.array_equal(R.indices[R.indptr[i]:R.indptr[i + 1]], B.indices[s:e]), (rows, i)
            assert np.array_equal(R.blocks[R.indptr[i]:R.indptr[i + 1]], B.blocks[s:e]), (rows, i)
            assert R.indices[R.diag_pos[i]] == a and R.diag_pos[i] - R.indptr[i] == B.diag_pos[a] - s
    sub = np.array([0, 2, 3, 6])
    Gs = kin.build_G(cs.subset(sub), kind, rot, center, np.concatenate([np.arange(nbn), np.arange(4)]),
                     np.array([0, 0, nbn]))
    for k in ("side_body", "side_dofs", "side_G"):
        assert np.array_equal(getattr(Gs, k), getattr(G, k)[sub])


def test_grid_pairs_of_a_subset_on_the_whole_grid_keep_the_whole_order():
    """broadphase.grid_pairs on a subset of the boxes with the whole set's grid (origin, top) gives exactly the whole
    set's pairs between boxes of the subset, in the same relative order (what a rank's detection relies on for
    bitwise equal sums and ties, detection_2d.detect's `bodies`). Random boxes of mixed sizes in 2D, random subsets.
    Catches: origin or top ignored (the subset's own grid: pairs reported from other cells, in another order), the
    cell's boxes not kept in increasing order."""
    from fem_blocks.contact.broadphase import grid_pairs
    rng = np.random.default_rng(2)
    n = 400
    lo = rng.uniform(0, 10, (n, 2))
    hi = lo + rng.uniform(0.05, 1.2, (n, 2))
    group = rng.integers(0, 60, n)
    whole = grid_pairs(lo, hi, group, 0.7)
    moved = 0
    for _ in range(5):
        sub = np.flatnonzero(rng.random(n) < 0.5)
        got = sub[grid_pairs(lo[sub], hi[sub], group[sub], 0.7, origin=lo.min(axis=0), top=hi.max(axis=0))]
        inside = np.isin(whole, sub).all(axis=1)
        assert np.array_equal(got, whole[inside])
        own = sub[grid_pairs(lo[sub], hi[sub], group[sub], 0.7)]  # its own grid: the same pairs, other order
        assert sorted(map(tuple, own.tolist())) == sorted(map(tuple, whole[inside].tolist()))
        moved += not np.array_equal(own, whole[inside])
    assert moved  # (so the test tells the two grids apart)


def test_body_boxes_span_their_items_in_any_order():
    """broadphase.body_boxes (the 2D and 3D detections' bodies' boxes) against each body's min and max written out:
    items given out of body order, a body without items (+inf / -inf), a body with one item. Catches a box made from
    the items' positions in the given order instead of grouped by body, a lost last item, empty bodies given a box."""
    from fem_blocks.contact.broadphase import body_boxes
    rng = np.random.default_rng(2)
    body = rng.permutation(np.r_[np.repeat([0, 1, 3], [5, 1, 7]), [5, 5]])
    lo = rng.normal(size=(body.size, 3))
    hi = lo + rng.random((body.size, 3))
    blo, bhi = body_boxes(lo, hi, body, 6)
    for b in range(6):
        on = body == b
        if on.any():
            assert np.array_equal(blo[b], lo[on].min(axis=0)) and np.array_equal(bhi[b], hi[on].max(axis=0))
        else:
            assert np.all(blo[b] == np.inf) and np.all(bhi[b] == -np.inf)
