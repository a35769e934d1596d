"""The colour-order Gauss–Seidel on one process (fem_blocks/distributed/colour.py, `[contact] order = "colours"`).

Expectations from outside the code under test: a Delassus operator built here from random rigid bodies (3 dofs, one
of them held: W = Hᵀ M⁻¹ H with M⁻¹ = 0 on the held body), stored like the assembly stores it (a block for every pair
of contacts sharing a body, blocks of zeros through the held body); the serial kernel `nlgs.sweep` applied in the
order of the colours; `math.fsum` for the stopping test's sums.
"""
import math

import numpy as np

from fem_blocks.distributed.colour import ColourSolver, colour_groups, coupling_rows
from fem_blocks.linalg import BlockCSR
from fem_blocks.solver import nlgs


def problem(nb=9, nc=40, seed=1, held=True):
    """(W BlockCSR with the assembly's pattern, q, mu, cand, ant): body 0 is held (it couples nothing), or with
    held=False moves like the others (no block of zeros)."""
    rng = np.random.default_rng(seed)
    cand = rng.integers(1, nb, nc)
    ant = np.where(rng.random(nc) < 0.3, 0, rng.integers(1, nb, nc))
    ant = np.where(ant == cand, 0, ant)
    H = np.zeros((3 * nb, 2 * nc))
    for a in range(nc):
        for k in range(2):
            g = rng.normal(size=3)
            H[3 * cand[a]:3 * cand[a] + 3, 2 * a + k] = g
            H[3 * ant[a]:3 * ant[a] + 3, 2 * a + k] = -rng.normal(size=3)
    minv = rng.uniform(0.5, 2.0, 3 * nb)
    if held:
        minv[:3] = 0.0  # body 0 held in every dof
    Wd = H.T @ (minv[:, None] * H) + 0.05 * np.eye(2 * nc)
    indptr, idx, blocks, diag = [0], [], [], []
    for a in range(nc):
        for b in range(nc):
            if {cand[a], ant[a]} & {cand[b], ant[b]} or a == b:
                if a == b:
                    diag.append(len(idx))
                idx.append(b)
                blocks.append(Wd[2 * a:2 * a + 2, 2 * b:2 * b + 2])
        indptr.append(len(idx))
    W = BlockCSR(np.array(indptr), np.array(idx), np.ascontiguousarray(blocks), np.array(diag))
    q = rng.normal(size=2 * nc)
    return W, q, rng.uniform(0.3, 0.8, nc), cand, ant


def dense(B):
    n, d = B.n, B.dim
    out = np.zeros((d * n, d * n))
    for i in range(n):
        for k in range(B.indptr[i], B.indptr[i + 1]):
            j = B.indices[k]
            out[d * i:d * i + d, d * j:d * j + d] = B.blocks[k]
    return out


def test_coupling_rows_drop_only_off_diagonal_blocks_of_zeros():
    """Same matrix, diagonal blocks where they were, no off-diagonal block of zeros left. Catches a wrong mapping
    of the diagonal positions or dropping a diagonal block."""
    W, q, mu, cand, ant = problem()
    Wc = coupling_rows(W)
    zero = np.all(W.blocks == 0.0, axis=(1, 2))
    assert zero.sum() > 0  # the held body gives blocks of zeros
    assert Wc.indices.size == W.indices.size - zero.sum()
    assert np.array_equal(dense(Wc), dense(W))
    assert np.all(Wc.indices[Wc.diag_pos] == np.arange(W.n))
    off = np.ones(Wc.indices.size, dtype=bool)
    off[Wc.diag_pos] = False
    assert not np.any(np.all(Wc.blocks[off] == 0.0, axis=(1, 2)))


def test_colours_separate_coupled_groups_and_keep_groups_whole():
    """Two contacts of one colour and of different (candidate, antagonist) groups have W_αβ = W_βα = 0; the contacts
    of one group share a colour; the held body couples nothing (fewer colours than the structural pattern)."""
    W, q, mu, cand, ant = problem()
    colour = colour_groups(W, cand, ant, 9)
    D = dense(W)
    group = cand * 9 + ant
    for a in range(W.n):
        for b in range(W.n):
            if group[a] == group[b]:
                assert colour[a] == colour[b]
            elif colour[a] == colour[b]:
                assert not np.any(D[2 * a:2 * a + 2, 2 * b:2 * b + 2]), (a, b)
    only_held = [(a, b) for a in range(W.n) for b in range(W.n)
                 if {cand[a], ant[a]} & {cand[b], ant[b]} == {0} and colour[a] == colour[b]]
    assert only_held  # contacts that share only the held body may share a colour
    structural = BlockCSR(W.indptr, W.indices, np.ones_like(W.blocks), W.diag_pos)
    s = colour_groups(structural, cand, ant, 9)
    assert all(s[a] != s[b] for a, b in only_held)  # (the structural pattern would separate them)


def test_serial_colour_solver_is_nlgs_sweeps_in_colour_order_with_exact_sums():
    """k sweeps of ColourSolver = k passes of nlgs.sweep over the contacts sorted by colour (stable), bitwise; the
    reported change is sqrt(fsum(Δr²)/fsum(r²)) of the last sweep, bitwise. The solver sweeps its rows renumbered in
    sweep order (a colour's rows contiguous): W is left as it was. Catches a colour skipped or swept twice, a sweep
    over the whole W instead of the coupling rows with another order, a running (inexact) sum, a row's blocks,
    diagonal or columns renumbered wrongly, the impulses returned in sweep order instead of contact order, W
    changed."""
    W, q, mu, cand, ant = problem()
    keep = [np.array(getattr(W, k), copy=True) for k in ("indptr", "indices", "blocks", "diag_pos")]
    cs = ColourSolver(W, bodies=(cand, ant, 9))
    for k, a in zip(("indptr", "indices", "blocks", "diag_pos"), keep):
        assert np.array_equal(getattr(W, k), a), k
    assert not np.array_equal(cs._sweep, np.arange(W.n))  # the rows did move
    order = np.argsort(cs.colour, kind="stable").astype(np.int64)
    Wc = coupling_rows(W)
    for k in (1, 2, 7):
        res = cs.solve(q, mu, tol=1e-300, max_sweeps=k)
        r = np.zeros(2 * W.n)
        for _ in range(k):
            before = r.copy()
            nlgs.sweep(Wc.indptr, Wc.indices, Wc.blocks, Wc.diag_pos, q, mu, r, order)
        assert res.sweeps == k and not res.converged
        assert np.array_equal(res.r, r)
        dr = r - before
        assert res.change == math.sqrt(math.fsum(dr * dr) / math.fsum(r * r))


def test_ranks_whose_models_differ_stop_with_a_clear_error():
    """N ranks each build the model: the contact step compares their contact sets and Delassus operators when it
    rebuilds W and raises RankMismatchError (on every rank: the comparison is all-gathered) if one differs; equal
    copies pass; in colour order (each rank holding its part of the contact set) the whole set's contact count and
    the positions the ranks detected at are compared (one last bit of one coordinate differs: raised; another count:
    raised). (A fake communicator stands for the ranks.) Catches a check left without anything that can differ once
    the detection is split, or comparing what differs between the ranks' parts (their sizes: a false alarm)."""
    import types

    import pytest

    from fem_blocks.contact.step import ContactStep
    from fem_blocks.errors import RankMismatchError
    W, q, mu, cand, ant = problem()

    class Comm:
        def __init__(self, other):
            self.other = other

        def allgather(self, x):
            return [x, self.other(x)]

    step = ContactStep([], [])
    step.Wdel, step.cs = W, types.SimpleNamespace(gap=np.arange(W.n, dtype=float))
    step.comm = Comm(lambda x: x)
    step._check_replicas()
    step.comm = Comm(lambda x: (x[0], x[1], x[2] + 1, x[3]))
    with pytest.raises(RankMismatchError, match="ranks' copies of the model differ"):
        step._check_replicas()
    # colour order: each rank holds its part of the contact set (another size than the other rank's part here)
    from fem_blocks.contact.step import ContactOptions
    pos = np.arange(12.0).reshape(6, 2)
    step._local, step.opts = types.SimpleNamespace(n=40), ContactOptions(geometry="updated", order="colours")
    step.cs = types.SimpleNamespace(gap=np.arange(7, dtype=float))
    import zlib
    step.comm = Comm(lambda x: (40, zlib.crc32(pos.tobytes())))  # (the other rank at the same positions)
    step._check_replicas(pos)
    other = pos.copy()
    other[3, 1] = np.nextafter(other[3, 1], 10.0)
    for them in ((40, zlib.crc32(other.tobytes())), (41, zlib.crc32(pos.tobytes()))):
        step.comm = Comm(lambda x: them)
        with pytest.raises(RankMismatchError, match="ranks' copies of the model differ"):
            step._check_replicas(pos)


def _rows_in_order(W, order):
    """The rows of coupling_rows(W) of the contacts `order`, in that order (global column numbers): what
    delassus.assemble(..., rows=order, couplings=True) gives the time stepper."""
    C = coupling_rows(W)
    starts, cnt = C.indptr[order], np.diff(C.indptr)[order]
    pos = np.concatenate([np.arange(a, a + c) for a, c in zip(starts, cnt)]).astype(np.int64)
    indptr = np.concatenate([[0], np.cumsum(cnt)]).astype(np.int64)
    return BlockCSR(indptr, C.indices[pos].copy(), C.blocks[pos].copy(),
                    (C.diag_pos[order] - starts + indptr[:-1]).astype(np.int64))


def test_the_colours_read_from_the_bodies_are_those_of_the_operator():
    """sweep_plan (the time stepper's colours, before W is assembled: groups coupled when they share a moving body)
    gives colour_groups' colours on the assembled W (groups coupled by W's nonzero blocks), and the sweep order of
    ColourSolver(W): on the random bodies with a held one (body 0: W_b = 0, blocks of zeros) and without.
    moving_bodies reads W_b = 0 from the flat per-body blocks. Catches: a held body counted as coupling (more
    colours), an edge lost (a body's groups not all paired), a sweep order not by colour or not increasing within
    one."""
    from fem_blocks.distributed.colour import body_pair_groups, moving_bodies, sweep_plan
    for held in (True, False):
        W, q, mu, cand, ant = problem(seed=4, held=held)
        moving = np.arange(9) != 0 if held else np.ones(9, dtype=bool)
        group = body_pair_groups(cand, ant, 9)[0]
        plan = sweep_plan(group, cand, ant, moving)
        ref = ColourSolver(W, bodies=(cand, ant, 9))
        assert np.array_equal(plan.colour, colour_groups(W, cand, ant, 9)) and plan.n_colours == ref.n_colours
        assert np.array_equal(plan.rows, ref._sweep), held
    sizes = np.array([2, 1, 2, 0, 1])
    offsets = np.array([0, 4, 5, 9, 5])  # body 4 shares body 2's block
    flat = np.zeros(9)
    flat[[2, 4]] = [1.0, -3.0]  # body 0's last entry but one, body 1's only one
    assert moving_bodies(flat, offsets, sizes).tolist() == [True, True, False, False, False]
    flat[8] = 1e-300
    assert moving_bodies(flat, offsets, sizes).tolist() == [True, True, True, False, False]


def test_group_couplings_pair_the_groups_of_every_moving_body():
    """group_couplings against the pairs of contacts written out one by one: (g_a, g_b) is an edge iff contacts a
    and b share a body that moves; own_groups keeps the edges from those groups. Catches a segment of a body cut
    short or run into the next body's, the held bodies' pairs kept."""
    from fem_blocks.distributed.colour import body_pair_groups, body_pair_keys, group_couplings
    rng = np.random.default_rng(3)
    nb, nc = 12, 60
    cand = rng.integers(0, nb, nc)
    ant = (cand + rng.integers(1, nb, nc)) % nb
    moving = rng.random(nb) < 0.7
    group = body_pair_groups(cand, ant, nb)[0]
    want = {(int(group[a]), int(group[b])) for a in range(nc) for b in range(nc)
            if any(moving[x] for x in {cand[a], ant[a]} & {cand[b], ant[b]})}
    ga, gb = group_couplings(group, cand, ant, moving)
    assert set(zip(ga.tolist(), gb.tolist())) == want
    own = np.array([1, 4, 7])
    ga, gb = group_couplings(group, cand, ant, moving, own_groups=own)
    assert set(zip(ga.tolist(), gb.tolist())) == {e for e in want if e[0] in own}
    # the groups given by any keys (the time stepper's: body_pair_keys, cand * nb + ant): the same edges in them
    keys = body_pair_keys(cand, ant, 10**17)  # (to 1.1e18: a code body * (max key + 1) + key would overflow int64)
    ids = np.unique(keys)
    ga, gb = group_couplings(keys, cand, ant, moving, own_groups=ids[own])
    assert set(zip(ga.tolist(), gb.tolist())) == {(ids[a], ids[b]) for a, b in want if a in own}


def test_the_colours_of_groups_numbered_by_large_keys_are_those_of_their_order():
    """The time stepper numbers a group by its body pair's key, cand * nb + ant (up to nb², 10^12 for a million
    bodies): greedy_colours (on one rank here; on several, tests/test_dist_greedy.py) and sweep_plan colour such
    keys as the dense numbers of their order. Expectation: pair_colouring of the dense numbers. Catches an encoding
    of pairs a * (max + 1) + b (it overflows int64 at these keys, merging or losing edges)."""
    from mpi4py import MPI
    from fem_blocks.distributed.colour import body_pair_groups, body_pair_keys, sweep_plan
    from fem_blocks.distributed.greedy import greedy_colours
    from fem_blocks.solver.parallel import pair_colouring
    rng = np.random.default_rng(8)
    n, m = 300, 1500
    a, b = rng.integers(0, n, m), rng.integers(0, n, m)
    key = np.sort(rng.choice(10**6, n, replace=False)) * 10**12 + 7  # increasing, up to 1e18
    want = pair_colouring(n, np.concatenate([a, b]), np.concatenate([b, a]))
    ids, col, rounds = greedy_colours(key, key[a], key[b], lambda x: np.zeros(len(x), dtype=np.int64), MPI.COMM_SELF)
    assert np.array_equal(ids, key) and np.array_equal(col, want) and rounds == 1
    W, q, mu, cand, ant = problem(seed=4, held=True)
    moving = np.arange(9) != 0
    ref = sweep_plan(body_pair_groups(cand, ant, 9)[0], cand, ant, moving)
    for nb in (9, 10**17):  # (keys to 8e17 + 8)
        got = sweep_plan(body_pair_keys(cand, ant, nb), cand, ant, moving)
        assert np.array_equal(got.colour, ref.colour) and np.array_equal(got.rows, ref.rows)


def test_rows_in_sweep_order_solve_as_the_whole_operator():
    """ColourSolver.from_sweep_rows (the time stepper: rows assembled in the plan's sweep order, global columns)
    sweeps as ColourSolver(W) on the whole operator: the same colours' order, r, u and sweep count, bit for bit; W's
    arrays become the solver's (no second copy of its column numbers). Catches local column numbers in another order
    than the sweep's, a diagonal position not carried, the rows' arrays copied."""
    from fem_blocks.distributed.colour import SweepPlan, body_pair_groups, sweep_plan
    W, q, mu, cand, ant = problem(seed=4)
    n = W.n
    ref = ColourSolver(W, bodies=(cand, ant, 9))
    plan = sweep_plan(body_pair_groups(cand, ant, 9)[0], cand, ant, np.arange(9) != 0)
    rows = _rows_in_order(W, plan.rows)
    got = ColourSolver.from_sweep_rows(rows, plan, np.arange(n), n)
    assert all(a is b for a, b in zip((rows.indptr, rows.indices, rows.blocks, rows.diag_pos), got.rows))
    assert got.n_colours == ref.n_colours
    for c in range(ref.n_colours):
        assert np.array_equal(got.order[c], ref.order[c])
    a = ref.solve(q, mu, tol=1e-10, max_sweeps=300)
    b = got.solve(q, mu, tol=1e-10, max_sweeps=300)
    assert a.sweeps == b.sweeps and np.array_equal(a.r, b.r) and np.array_equal(a.u, b.u)
    # a plan that does not cover every contact on one process is refused
    import pytest
    from fem_blocks.errors import InputError
    part = SweepPlan(plan.rows[:-1], plan.colour, plan.n_colours, 0)
    with pytest.raises(InputError, match="rows of all"):
        ColourSolver.from_sweep_rows(_rows_in_order(W, part.rows), part, np.arange(n), n)


def test_colour_order_run_sweeps_the_delassus_arrays_without_a_copy(tmp_path):
    """A run in colour order holds W's rows once: the contact step assembles only the blocks that couple, and the
    colour solver sweeps those arrays themselves (a copy without the blocks of zeros doubled the largest array of a
    run). The wall stands on a fixed foundation, whose contacts share only it: blocks of zeros in the whole
    operator. Expectation: the whole operator assembled here from the step's own G, through coupling_rows.
    Catches: the couplings flag not passed (blocks of zeros in the rows: they differ from coupling_rows'), the
    rows not in sweep order, the solver sweeping a copy."""
    import dist_cases
    from _case_steps import stepping
    from fem_blocks import delassus
    path = tmp_path / "w.toml"
    path.write_text(dist_cases.wall("w", courses=2, per=3))
    _, model, sim, _ = stepping(str(path), None)
    sim.step()
    step = model.contact
    W = step.Wdel
    ip, ix, bl, dp = step._colours.rows
    assert np.shares_memory(bl, W.blocks) and np.shares_memory(ix, W.indices)  # W's arrays, put in sweep order
    whole = delassus.assemble(step.G, *step.scene.W_blocks(None), step.scene.nb)
    assert whole.indices.size > W.indices.size  # the foundation's blocks of zeros
    C = coupling_rows(whole)
    sweep = step._colours._sweep  # the contact of each row, in sweep order
    assert sorted(sweep.tolist()) == list(range(C.n))
    for i, g in enumerate(sweep.tolist()):  # row i is contact g's row of the whole operator, blocks in order
        a, b, c0, c1 = ip[i], ip[i + 1], C.indptr[g], C.indptr[g + 1]
        assert np.array_equal(sweep[ix[a:b]], C.indices[c0:c1]) and np.array_equal(bl[a:b], C.blocks[c0:c1]), g
        assert dp[i] - a == C.diag_pos[g] - c0
    colour = step._colours._colour_local  # (one process: the colour of each row, in sweep order)
    ref = colour_groups(whole, step.cs.cand_body, step.cs.ant_body, step.scene.nb)  # from the values of W
    assert np.array_equal(colour, ref[sweep]) and colour.max() + 1 == step._colours.n_colours
    assert np.all(np.diff(colour) >= 0)  # a colour's rows one after the other ...
    for c in range(step._colours.n_colours):  # ... in increasing contact number
        assert np.all(np.diff(sweep[colour == c]) > 0)
        assert np.array_equal(step._colours.order[c], np.flatnonzero(colour == c))



def test_a_step_after_close_assembles_w_again(tmp_path):
    """The colour solver holds W's arrays, their column numbers made its own (from_sweep_rows): after
    ContactStep.close() drops it, the next step must assemble W again, not hand those arrays to a new solver.
    Expectation: the same run without close(), bitwise. Catches close() leaving W_dirty unset (the next step finds
    no sweep plan: RuntimeError)."""
    import dist_cases
    from _case_steps import stepping
    path = tmp_path / "w.toml"
    path.write_text(dist_cases.wall("w", courses=2, per=3))
    got = []
    for close in (False, True):
        _, model, sim, _ = stepping(str(path), None)
        sim.step()
        if close:
            model.contact.close()
        sim.step()
        got.append(sim.last_contact.P.tobytes())
    assert got[0] == got[1]


def test_permute_rows_moves_the_rows_in_place_as_a_gather_would():
    """linalg.permute_rows (the rows put in sweep order in place, block by block along the permutation's cycles) against
    the same rows gathered into new arrays: 2×2 and 3×3 blocks, rows of 0 to 5 blocks, a permutation with fixed
    points and long cycles, the identity, no rows. Catches a cycle closed one block early or late, a block moved but
    its column not relabelled, the row pointers of the old order kept."""
    from fem_blocks.linalg import permute_rows
    rng = np.random.default_rng(7)
    for d, n, ident in ((2, 200, False), (3, 150, False), (2, 30, True), (2, 0, False)):
        lens = rng.integers(0, 6, n)
        indptr = np.concatenate([[0], np.cumsum(lens)]).astype(np.int64)
        m = int(indptr[-1])
        indices = rng.integers(0, max(n, 1), m).astype(np.int64)
        blocks = rng.normal(size=(m, d, d))
        perm = np.arange(n, dtype=np.int64) if ident else np.argsort(rng.integers(0, 6, n), kind="stable")
        relabel = rng.permutation(max(n, 1)).astype(np.int64)
        new_lens = lens[perm]
        src = np.concatenate([np.arange(indptr[a], indptr[a + 1]) for a in perm]).astype(np.int64) if n else \
            np.zeros(0, dtype=np.int64)
        ix, bl = indices.copy(), blocks.copy()
        ptr = permute_rows(indptr, ix, bl, perm.astype(np.int64), relabel)
        assert np.array_equal(ptr, np.concatenate([[0], np.cumsum(new_lens)]))
        assert np.array_equal(ix, relabel[indices[src]]) and np.array_equal(bl, blocks[src]), (d, n, ident)


def _same_pattern(W, seed):
    """W's pattern with other blocks (the next step's operator of the same contacts)."""
    rng = np.random.default_rng(seed)
    return BlockCSR(W.indptr.copy(), W.indices.copy(), W.blocks * rng.uniform(0.5, 1.5, W.blocks.shape),
                    W.diag_pos.copy())


def test_a_solver_of_the_same_structure_takes_over_the_previous_one():
    """from_sweep_rows(..., previous=): the rows of the next step with the same contacts, sweep order, colours and
    block pattern (other values) take over the previous solver's layout (its index arrays, scatters on N > 1) with
    the new blocks, and solve as a solver built from scratch, bit for bit (r, u, sweeps, change), again after a
    take-over. It does not take over another structure: a block pattern that differs (a block less; a column
    number changed, the same row lengths), colours that differ with the same sweep order and count, another sweep
    order. Catches: the new blocks not taken (the previous values swept),
    the comparison of the colours or of the column numbers left out, a spent solver taken over again (the
    comparisons of the sweep order, ghosts, row starts and diagonal positions are not tested alone: a change of the
    sweep order or of a row's length changes the column numbers too)."""
    from fem_blocks.distributed.colour import SweepPlan, body_pair_groups, sweep_plan
    W, q, mu, cand, ant = problem(seed=5, held=False)
    n = W.n
    plan = sweep_plan(body_pair_groups(cand, ant, 9)[0], cand, ant, np.ones(9, dtype=bool))
    make = lambda A, p=plan, **kw: ColourSolver.from_sweep_rows(_rows_in_order(A, p.rows), p, np.arange(n), n,  # noqa
                                                                **kw)
    ref = make(_same_pattern(W, 1)).solve(q, mu, tol=1e-10, max_sweeps=200)
    first = make(W)
    first.solve(q, mu, tol=1e-10, max_sweeps=200)
    ix = first.rows[1]
    second = make(_same_pattern(W, 1), previous=first)
    assert first.rows is None and second.rows[1] is ix and second.W.indices is ix  # taken over
    got = second.solve(q, mu, tol=1e-10, max_sweeps=200)
    assert got.sweeps == ref.sweeps and got.change == ref.change
    assert got.r.tobytes() == ref.r.tobytes() and got.u.tobytes() == ref.u.tobytes()
    third = make(_same_pattern(W, 1), previous=second)  # (and again: the taken-over solver keeps its layout)
    assert second.rows is None and third.rows[1] is ix
    assert third.solve(q, mu, tol=1e-10, max_sweeps=200).r.tobytes() == ref.r.tobytes()
    assert make(W, previous=second).rows[1] is not ix  # (spent: nothing to take over)
    # not the same structure: a fresh build, the previous solver left whole
    Wp = _same_pattern(W, 2)
    k = Wp.diag_pos[0] + 1 if Wp.diag_pos[0] + 1 < Wp.indptr[1] else Wp.diag_pos[0] - 1
    Wp.blocks[k] = 0.0  # one coupling block less in row 0 (coupling_rows drops it)
    other = make(Wp, previous=third)
    assert third.rows is not None and other.rows[1] is not ix
    R = _rows_in_order(W, plan.rows)  # a column number of row 0 changed (the same row lengths)
    k = R.diag_pos[0] + 1 if R.diag_pos[0] + 1 < R.indptr[1] else R.diag_pos[0] - 1
    R.indices[k] = next(j for j in range(n) if j not in set(R.indices[R.indptr[0]:R.indptr[1]].tolist()))
    assert ColourSolver.from_sweep_rows(R, plan, np.arange(n), n, previous=third).rows[1] is not ix
    assert third.rows is not None
    c = plan.colour.copy()
    first1 = plan.rows[np.flatnonzero(c[plan.rows] == 1)[0]]
    c[c == c[first1]] = -7  # colour 1 merged into colour 0: the same sweep order and number of colours
    c[c == -7] = 0
    moved = SweepPlan(plan.rows, c, plan.n_colours, 0)
    assert np.array_equal(moved.rows, plan.rows[np.argsort(c[plan.rows], kind="stable")])
    assert make(W, p=moved, previous=third).rows[1] is not ix and third.rows is not None
    shuffled = SweepPlan(plan.rows[::-1].copy(), plan.colour, plan.n_colours, 0)
    assert make(W, p=shuffled, previous=third).rows[1] is not ix and third.rows is not None


def test_updated_geometry_takes_over_the_colour_solver_between_redetections(tmp_path, monkeypatch):
    """Updated geometry assembles W at every step; between re-detections (redetect_every = 3) the contacts are the
    same and the contact step's colour solver takes over the previous one (contact/step.py `_colour_solver`). The
    run is the run whose solver is built from scratch at every step (take-over refused), bit for bit: impulses and
    bodies' displacements after each of 5 steps. Catches a take-over that keeps the previous step's blocks, or one
    across a re-detection with another contact set."""
    import dist_cases
    from _case_steps import stepping
    from fem_blocks.distributed import colour
    path = tmp_path / "w.toml"
    path.write_text(dist_cases.wall("w", courses=2, per=3).replace(
        "[contact]\n", '[contact]\ngeometry = "updated"\nredetect_every = 3\n'))
    real = colour.ColourSolver._take_over
    runs, taken = [], []

    def counted(self, previous, lr, colour_local):
        ok = real(self, previous, lr, colour_local)
        taken.append(ok)
        return ok
    for refuse in (False, True):
        monkeypatch.setattr(colour.ColourSolver, "_take_over",
                            (lambda self, p, lr, c: False) if refuse else counted)
        _, model, sim, _ = stepping(str(path), None)
        out = []
        for _ in range(5):
            sim.step()
            cs = model.contact.cs
            out.append((sim.last_contact.P.tobytes(), b"".join(b.q.tobytes() for b in model.bodies),
                        (cs.key.tobytes(), cs.cand_body.tobytes(), cs.ant_body.tobytes())))
        runs.append(out)
    sets = [s for _, _, s in runs[0]]
    # taken over at steps 2, 3 and 5 (the contacts of the step before), at 4 (re-detected) iff the set is the same
    assert taken[:3] == [False, True, True] and taken[4] is True
    assert taken[3] == (sets[3] == sets[2])
    assert runs[0] == runs[1]
    assert len(set(p for p, _, _ in runs[0])) == 5


def test_a_detection_error_of_one_rank_is_raised_on_every_rank(tmp_path, monkeypatch):
    """With the 2D detection split among the ranks, an error only one rank finds (its own bodies' contacts, e.g. a
    node facing more than SLOTS bodies) must stop every rank with the same message, not leave the others waiting in
    the gather of the parts (the ranks' messages all-gathered before it). A fake communicator of 2 ranks stands for
    the other rank: its error is raised here though this rank's detection succeeded, and this rank's error is raised
    after the all-gather. Catches the error raised only where it was found (the other ranks hang)."""
    import dist_cases
    import pytest
    from _case_steps import stepping
    from fem_blocks.contact import detection_2d
    from fem_blocks.errors import InputError
    path = tmp_path / "w.toml"
    path.write_text(dist_cases.wall("w", courses=2, per=3))
    _, model, sim, _ = stepping(str(path), None)
    sim.step()
    step = model.contact
    seen = []

    class Comm:
        def __init__(self, other):
            self.other = other

        def Get_rank(self):
            return 0

        def Get_size(self):
            return 2

        def allgather(self, x):
            seen.append(x)
            return [x, self.other]

    step.body_owner = np.zeros(step.scene.nb, dtype=np.int64)
    step.comm = Comm("contact detection: a boundary node of body 3 faces more than 8 bodies")
    with pytest.raises(InputError, match="body 3 faces more than 8"):
        step._detect(step.scene.positions())
    assert seen == [None]  # (this rank's detection succeeded; the message came from the other)
    real = detection_2d.detect

    def failing(*a, **kw):
        assert kw.get("bodies") is not None  # (the split detection)
        raise InputError("this rank's error")
    monkeypatch.setattr(detection_2d, "detect", failing)
    step.comm = Comm(None)
    with pytest.raises(InputError, match="this rank's error"):
        step._detect(step.scene.positions())
    assert seen[-1] == "this rank's error"
    monkeypatch.setattr(detection_2d, "detect", real)


def test_a_rank_that_finds_the_ranks_disagree_stops_every_rank():
    """On N > 1 ranks a rank looks contacts up by id among sorted ids (`_lookup`: the old own rows its new rows
    continue, a contact's number asked of its owner, `_numbers`); a contact its owner does not hold (ranks whose
    copies diverged) must stop every rank with the same error, not only the rank that found it while the others wait
    in the next collective (`_fail_together`: an all-reduce of the flag). A fake communicator of 2 ranks stands for
    the other rank. Catches the error raised only where it was found, and a lookup that takes the next contact for
    one that is not there."""
    import pytest
    from fem_blocks.contact.step import ContactStep
    from fem_blocks.contact.step import _lookup
    assert _lookup(np.array([2, 5, 9]), np.array([5, -1, 9, 2, 4, 10])).tolist() == [1, -1, 2, 0, -1, -1]
    assert _lookup(np.zeros(0, dtype=np.int64), np.array([3])).tolist() == [-1]
    seen = []

    class Comm:
        def __init__(self, other):
            self.other = other

        def allreduce(self, x, op=None):
            seen.append(x)
            return max(x, self.other)

    step = ContactStep.__new__(ContactStep)
    step.comm = Comm(1)
    with pytest.raises(RuntimeError, match="contact step: rows differ \\(found by a rank\\)"):
        step._fail_together(False, "rows differ")  # (the other rank found it)
    step.comm = Comm(0)
    step._fail_together(False, "rows differ")
    with pytest.raises(RuntimeError, match="rows differ"):
        step._fail_together(True, "rows differ")
    assert seen == [0, 0, 1]  # (every call all-reduces, also where nothing was found)


def test_a_rank_whose_part_is_dry_takes_the_cohesive_path_of_the_set():
    """contact/step.py ContactStep._assign_laws on N > 1 ranks in colour order: whether the contact set has a cohesive
    contact (the interface-law path of the solve and the commit, which every rank must take alike through the
    collective sweep) is read from the interfaces of every rank's part, all-reduced. A rank whose part has only dry
    (Coulomb) contacts takes the cohesive path when the other rank's part has a mixed-law contact, and not when the
    other's is dry too. A fake 2-rank communicator gives the other rank's interfaces in use. Catches the flag read
    from the rank's own part only (the ranks would part ways in the sweep)."""
    from types import SimpleNamespace
    from fem_blocks.contact.step import ContactStep
    from fem_blocks.specs import ContactOptions, InterfaceSpec
    glue = dict(k_n=82e9, k_s=36e9, f_t=0.25e6, c=0.35e6, G_I=18.0, G_II=125.0, tan_phi=0.75)
    itfs = [InterfaceSpec("dry", ("b", "b"), mu=0.7), InterfaceSpec("glued", ("b", "g"), law="mixed", params=glue)]

    class Comm:
        def __init__(self, other):
            self.other = np.array(other, dtype=np.int64)

        def Allreduce(self, send, recv, op=None):
            recv[:] = np.maximum(send, self.other)
    for other, cohesive in (([0, 1], True), ([1, 0], False)):
        step = ContactStep(itfs, ["b", "b", "g"], ContactOptions(order="colours"))
        step.comm, step.dim = Comm(other), 2
        step.cs = SimpleNamespace(interface=np.zeros(3, dtype=np.int64), cand_body=np.array([0, 1, 0]),
                                  ant_body=np.array([1, 0, 1]), gap=np.zeros(3))
        step._assign_laws(np.array([0, 2]))
        assert step.cohesive is cohesive and step.law.tolist() == [0, 0]
