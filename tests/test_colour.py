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
    sweep order (a colour's rows contiguous): W is left as it was, and with take_rows=True (its arrays moved in place)
    the iterates are the same. Catches a colour skipped or swept twice, a sweep over the whole W instead of the
    coupling rows with another order, a running (inexact) sum, a row's blocks, diagonal or columns renumbered
    wrongly, the impulses returned in sweep order instead of contact order, W changed without take_rows."""
    W, q, mu, cand, ant = problem()
    keep = [np.array(getattr(W, k), copy=True) for k in ("indptr", "indices", "blocks", "diag_pos")]
    cs = ColourSolver(W, bodies=(cand, ant, 9))
    for k, a in zip(("indptr", "indices", "blocks", "diag_pos"), keep):
        assert np.array_equal(getattr(W, k), a), k
    taken = ColourSolver(BlockCSR(*[a.copy() for a in keep]), bodies=(cand, ant, 9), take_rows=True)
    assert not np.array_equal(taken._sweep, np.arange(W.n))  # the rows did move
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
        assert taken.solve(q, mu, tol=1e-300, max_sweeps=k).r.tobytes() == res.r.tobytes()
        dr = r - before
        assert res.change == math.sqrt(math.fsum(dr * dr) / math.fsum(r * r))


def test_ranks_whose_models_differ_stop_with_a_clear_error():
    """N ranks each build the model: the contact step compares their contact sets and Delassus operators when it
    rebuilds W and raises RankMismatchError (on every rank: the comparison is all-gathered) if one differs; equal
    copies pass. (A fake communicator stands for the ranks.)"""
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


def test_a_ranks_rows_give_the_colours_and_iterates_of_the_whole_operator():
    """ColourSolver.from_rows (a rank holding only the rows of its own contacts, here one rank holding them all, on
    MPI.COMM_SELF): the colours are colour_groups' on the whole W (the group graph from the rows' nonzero blocks) and
    the solve gives the whole-operator solver's r, u and sweep count, bit for bit. Catches: groups coupled through a
    block of zeros (the held body, 25 colours instead of 6 on a wall), a colour per group read in contact order. (Rows
    split among ranks, the gathered group graph: tests/test_dist_run.py, bitwise against one process.)"""
    from mpi4py import MPI
    from fem_blocks.distributed.colour import body_pair_groups
    W, q, mu, cand, ant = problem(seed=4)
    n = W.n
    ref = ColourSolver(W, bodies=(cand, ant, 9))
    rows = BlockCSR(W.indptr.copy(), W.indices.copy(), W.blocks.copy(), W.diag_pos.copy())
    ids = np.arange(n)
    got = ColourSolver.from_rows(rows, ids, ids, n, body_pair_groups(cand, ant, 9)[0], np.zeros(n, int),
                                 MPI.COMM_SELF)
    try:
        assert got.n_colours == ref.n_colours
        for c in range(ref.n_colours):
            assert np.array_equal(got.order[c], ref.order[c])
        a = ref.solve(q, mu, tol=1e-10, max_sweeps=300)
        b = got.solve(q, mu, tol=1e-10, max_sweeps=300)
        assert a.sweeps == b.sweeps and np.array_equal(a.r, b.r) and np.array_equal(a.u, b.u)
    finally:
        got.destroy()


def test_colour_order_run_sweeps_the_delassus_arrays_without_a_copy(tmp_path):
    """A run in colour order holds W's rows once: the contact step assembles only the blocks that couple, and the
    colour solver sweeps those arrays themselves (a copy without the blocks of zeros doubled the largest array of a
    run). The wall stands on a fixed foundation, whose contacts share only it: blocks of zeros in the whole
    operator. Expectation: the whole operator assembled here from the step's own G, through coupling_rows.
    Catches: the couplings flag not passed (the solver copies), the blocks of zeros kept."""
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
    colour = step._colours.colour[sweep]
    assert np.all(np.diff(colour) >= 0)  # a colour's rows one after the other ...
    for c in range(step._colours.n_colours):  # ... in increasing contact number
        assert np.all(np.diff(sweep[colour == c]) > 0)
        assert np.array_equal(step._colours.order[c], np.flatnonzero(colour == c))



def test_a_step_after_close_assembles_w_again(tmp_path):
    """The colour solver holds W's arrays in its own order (take_rows): after ContactStep.close() drops it, the next
    step must assemble W again, not hand the reordered arrays to a new solver. Expectation: the same run without
    close(), bitwise. Catches close() leaving W_dirty unset (the next solver reads the rows as if in contact order)."""
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
    """ColourSolver(..., previous=): the operator of the next step with the same contacts, body pairs and block
    pattern (other values) takes over the previous solver's colours, sweep order and rows (its blocks array, refilled)
    and solves as a solver built from scratch, bit for bit (r, u, sweeps, change); on one process and through
    from_rows (one rank, MPI.COMM_SELF). It does not take over another structure: the bodies renumbered (other
    groups), a block of zeros (colours from the values), or a previous solver that did not keep its layout.
    Catches: the new blocks not taken (the previous values swept), taken in contact order instead of sweep order, the
    signature without the body pairs; a solver built from scratch with take_rows leaving W its own arrays (its column
    indices before the renumbering, a second int64 per block)."""
    from mpi4py import MPI
    from fem_blocks.distributed.colour import body_pair_groups
    W, q, mu, cand, ant = problem(seed=5, held=False)
    W2 = _same_pattern(W, 1)
    fresh = ColourSolver(_same_pattern(W, 1), bodies=(cand, ant, 9))
    ref = fresh.solve(q, mu, tol=1e-10, max_sweeps=200)
    ids, n = np.arange(W.n), W.n
    group = body_pair_groups(cand, ant, 9)[0]
    for how in ("serial", "rows"):
        if how == "serial":
            make = lambda A, **kw: ColourSolver(A, bodies=(cand, ant, 9), take_rows=True, **kw)  # noqa: E731
        else:
            make = lambda A, **kw: ColourSolver.from_rows(A, ids, ids, n, group, np.zeros(n, int),  # noqa: E731
                                                          MPI.COMM_SELF, take_rows=True, **kw)
        A1 = BlockCSR(*[np.array(a, copy=True) for a in (W.indptr, W.indices, W.blocks, W.diag_pos)])
        first = make(A1, reusable=True)
        # take_rows: W's arrays are the solver's (no array of W's own beside them, e.g. its column indices before
        # the renumbering for the sweep)
        assert all(a is b for a, b in zip((A1.indptr, A1.indices, A1.blocks, A1.diag_pos), first.rows)), how
        first.solve(q, mu, tol=1e-10, max_sweeps=200)
        held = first.rows[2]
        A2 = BlockCSR(*[np.array(a, copy=True) for a in (W2.indptr, W2.indices, W2.blocks, W2.diag_pos)])
        second = make(A2, previous=first)
        assert first.rows is None and second.rows[2] is held and A2.blocks is held, how  # taken over, refilled
        got = second.solve(q, mu, tol=1e-10, max_sweeps=200)
        assert got.sweeps == ref.sweeps and got.change == ref.change, how
        assert got.r.tobytes() == ref.r.tobytes() and got.u.tobytes() == ref.u.tobytes(), how
        third = make(_same_pattern(W, 2), previous=second)  # (and again: the taken-over solver keeps its layout)
        assert second.rows is None and third.rows[2] is held
        third.destroy()
    # not the same structure: a fresh build, the previous solver left whole
    prev = ColourSolver(_same_pattern(W, 3), bodies=(cand, ant, 9), take_rows=True, reusable=True)
    other = ColourSolver(_same_pattern(W, 1), bodies=((cand + 1) % 9, (ant + 1) % 9, 9), take_rows=True,
                         previous=prev)
    assert prev.rows is not None and other.rows[2] is not prev.rows[2]
    Wz, *_ = problem(seed=5)  # body 0 held: blocks of zeros
    zp = ColourSolver(_same_pattern(Wz, 3), bodies=(cand, ant, 9), take_rows=True, reusable=True)
    zn = ColourSolver(_same_pattern(Wz, 1), bodies=(cand, ant, 9), take_rows=True, previous=zp)
    assert zp.rows is not None and zn.rows[2] is not zp.rows[2]
    plain = ColourSolver(_same_pattern(W, 3), bodies=(cand, ant, 9), take_rows=True)  # (not reusable)
    again = ColourSolver(_same_pattern(W, 1), bodies=(cand, ant, 9), take_rows=True, previous=plain)
    assert plain.rows is not None
    b = again.solve(q, mu, tol=1e-10, max_sweeps=200)
    assert b.r.tobytes() == ref.r.tobytes()


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

    def counted(self, previous, W, take_rows):
        ok = real(self, previous, W, take_rows)
        taken.append(ok)
        return ok
    for refuse in (False, True):
        monkeypatch.setattr(colour.ColourSolver, "_take_over",
                            (lambda self, p, W, t: False) if refuse else counted)
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
