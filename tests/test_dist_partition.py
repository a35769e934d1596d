"""Partition of bodies across ranks (fem_blocks/distributed/partition.py) on small running-bond walls.

Expectations, each from a source independent of the code under test:
* reach: the bodies within the search distance r = max(g0 + alert) of each other are those of a brute-force
  all-pairs distance between the axis-aligned rectangles of the expanded case (bricks and foundation, from the case
  geometry, not from the meshes): d = hypot(max(0, gap_x), max(0, gap_y)).
  Catches: enlarging the broad-phase boxes by r instead of r/2 or forgetting the exact distance (too many pairs),
  `<` instead of `<=`, or a missing pair from a too small box (too few).
* owned contacts: the union over ranks of the owned contacts is the serial contact set of the production path
  (ContactStep detection on a Simulation's ContactScene), each contact exactly once, same points and gaps bitwise.
  Catches: detecting on owned bodies only (contacts with a ghost antagonist lost), keeping ghost-candidate contacts
  (duplicates), or a renumbering that changes the detection's choices.
* exchange lists: rank p sends to q exactly its contacts that share a body with a contact of q (brute force over
  all contact pairs), and q's receive list from p is the same. Catches: coupling through the candidate body only.
* mpirun -n 2, 3 (one rank: in-process tests): the owner array is the same on every rank, every body owned exactly once, ghosts of rank p =
  {j not owned by p: d(i, j) <= r for an owned i} from the brute force, edge cut = the brute-force cut; 3 ranks on
  a 2-body case: a rank with no bodies, no ghosts, no contacts.
"""
import shutil
import subprocess
import sys

import numpy as np
import pytest

from fem_blocks.case import load_case
from fem_blocks.expand import expand
from fem_blocks.model import build_model
from fem_blocks.distributed import partition as dp

from _mpi import ENV  # noqa: E402
from _paths import ROOT  # noqa: E402

CASE = """name = "w"
gravity = [0.0, -9.81]
[materials.brick]
E = 5e9
nu = 0.2
rho = 1800.0
thickness = 0.12
[wall]
{layout}
material = "brick"
brick_length = 0.25
brick_height = 0.06
joint = {joint}
mesh_size = 0.03
cell = "quad"
group = "bricks"
[wall.foundation]
depth = 0.2
overhang = 0.1
[[interfaces]]
name = "j"
between = ["bricks", "bricks"]
mu = 0.7
g0 = {g0}
alert = {alert}
[[interfaces]]
name = "f"
between = ["bricks", "foundation"]
mu = 0.7
g0 = {g0}
alert = {alert}
[[stages]]
name = "g"
duration = 0.01
h = 1e-3
"""



def bond(courses, per):
    return f'type = "running_bond"\ncourses = {courses}\nbricks_per_course = {per}'


# (layout, joint, g0, alert): r = g0 + alert
WALLS = {
    "dry": (bond(4, 4), 0.0, 0.0, 1e-3),        # touching bricks: reach = the bricks sharing an edge or a corner
    "thick": (bond(4, 3), 0.01, 0.01, 0.002),   # 1 cm joints, r = 1.2 cm
    "far": (bond(5, 3), 0.0, 0.0, 0.065),       # r = 6.5 cm > brick height: bricks two courses apart within reach
    # stack bond, 1 cm joints, r = 1.2 cm: diagonal bricks are 1.41 cm apart (corner to corner), out of reach,
    # but their boxes enlarged by r/2 overlap: only the exact distance separates them
    "stack": ('type = "courses"\nrows = [[1, 1, 1], [1, 1, 1], [1, 1, 1]]', 0.01, 0.01, 0.002),
}


def write_case(tmp_path, name, layout, joint, g0, alert):
    p = tmp_path / f"{name}.toml"
    p.write_text(CASE.format(layout=layout, joint=joint, g0=g0, alert=alert))
    return str(p)


def rectangles(case_path):
    """(nb, 4) [x0, y0, x1, y1] of every body in model order (blocks, then rigid bodies), from the expanded case."""
    case = expand(load_case(case_path))
    out = []
    for b in case.blocks:
        t = case.block_types[b.type]
        out.append([b.position[0], b.position[1], b.position[0] + t.lx, b.position[1] + t.ly])
    for r in case.rigid_bodies:
        V = np.asarray(r.vertices, dtype=float)
        out.append([V[:, 0].min(), V[:, 1].min(), V[:, 0].max(), V[:, 1].max()])
    return np.array(out)


def brute_force_reach(rects, r):
    """(nb, nb) bool: i != j and the distance between rectangles i and j <= r (all pairs)."""
    gx = np.maximum(0.0, np.maximum(rects[None, :, 0] - rects[:, None, 2], rects[:, None, 0] - rects[None, :, 2]))
    gy = np.maximum(0.0, np.maximum(rects[None, :, 1] - rects[:, None, 3], rects[:, None, 1] - rects[None, :, 3]))
    near = np.hypot(gx, gy) <= r
    np.fill_diagonal(near, False)
    return near


def serial_contacts(model):
    """The production detection: ContactStep on a Simulation's scene, reference configuration."""
    from fem_blocks.dynamics import Simulation
    sim = Simulation(model.bodies, h=1e-3, theta=1.0, contact=model.contact)
    cstep = model.contact
    cstep._setup(sim)
    return cstep._detect(cstep.scene.positions(reference=True))


def rows(cand, ant, cand_nodes, ant_nodes, point, gap):
    """Contacts as sortable rows (bodies, nodes, point, gap), lexicographically sorted."""
    R = np.column_stack([cand, ant, cand_nodes, ant_nodes, point, gap]).astype(float)
    return R[np.lexsort(R.T[::-1])]


@pytest.mark.parametrize("wall", sorted(WALLS))
def test_near_pairs_are_the_bodies_within_reach(tmp_path, wall):
    path = write_case(tmp_path, wall, *WALLS[wall])
    model = build_model(load_case(path))
    r = dp.search_distance(model)
    pairs = dp.near_pairs(dp.boundaries(model), r)
    near = brute_force_reach(rectangles(path), r)
    expected = np.argwhere(np.triu(near))
    assert np.array_equal(pairs, expected)
    if wall == "far":  # the setting reaches past the neighbours: more pairs than those sharing an edge
        assert len(pairs) > len(np.argwhere(np.triu(brute_force_reach(rectangles(path), 1e-9))))
    if wall == "stack":  # 9 bricks + foundation: 12 joints between bricks + 3 on the foundation, no diagonal
        assert len(pairs) == 15


def test_one_rank_owns_everything_and_the_serial_contacts(tmp_path):
    from mpi4py import MPI
    model = build_model(load_case(write_case(tmp_path, "dry", *WALLS["dry"])))
    rp = dp.partition_model(model, MPI.COMM_SELF)
    nb = len(model.bodies)
    assert np.array_equal(rp.owned, np.arange(nb)) and len(rp.ghost) == 0 and rp.edge_cut == 0
    cs = serial_contacts(model)
    c = rp.contacts
    assert np.array_equal(rows(c.cand_body, c.ant_body, c.cand_nodes, c.ant_nodes, c.point, c.gap),
                          rows(cs.cand_body, cs.ant_body, cs.cand_nodes, cs.ant_nodes, cs.point, cs.gap))


def test_check_catches_a_missing_ghost(tmp_path):
    from mpi4py import MPI
    model = build_model(load_case(write_case(tmp_path, "dry", bond(2, 2), 0.0, 0.0, 1e-3)))
    rp = dp.partition_model(model, MPI.COMM_SELF)
    rp.owned = rp.owned[1:]  # body 0 now neither owned nor ghost, but candidate or antagonist of some contact
    with pytest.raises(AssertionError):
        rp.check()


def run_mpi(n, case, out, tmp_path):
    p = subprocess.run(["mpirun", "-n", str(n), sys.executable, "-m", "fem_blocks.distributed.partition", case, out],
                       capture_output=True, text=True, cwd=ROOT, env=ENV, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    return [dict(np.load(f"{out}.rank{k}.npz")) for k in range(n)]


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")
@pytest.mark.parametrize("n,wall", [(3, "far")])
def test_mpirun_partition_ghosts_and_contacts(tmp_path, n, wall):
    path = write_case(tmp_path, wall, *WALLS[wall])
    ranks = run_mpi(n, path, str(tmp_path / "p"), tmp_path)
    model = build_model(load_case(path))
    nb = len(model.bodies)
    owner = ranks[0]["owner"]
    # the same owner array on every rank; each body owned exactly once
    assert all(np.array_equal(R["owner"], owner) for R in ranks)
    assert np.array_equal(np.sort(np.concatenate([R["owned"] for R in ranks])), np.arange(nb))
    assert all(np.array_equal(R["owned"], np.flatnonzero(owner == k)) for k, R in enumerate(ranks))
    if n > 1:
        assert all(len(R["owned"]) > 0 for R in ranks)  # ptscotch gives every rank bodies on these walls
    # ghosts: exactly the bodies within reach of an owned body, owned elsewhere (brute force)
    near = brute_force_reach(rectangles(path), dp.search_distance(model))
    for k, R in enumerate(ranks):
        mine = owner == k
        expected = np.flatnonzero(near[mine].any(axis=0) & ~mine)
        assert np.array_equal(R["ghost"], expected)
    # owned contacts of all ranks = the serial contact set, each once; every contact's bodies owned or ghost
    cs = serial_contacts(model)
    got = rows(*(np.concatenate([R[k] for R in ranks]) for k in ("cand_body", "ant_body", "cand_nodes",
                                                                  "ant_nodes", "point", "gap")))
    assert np.array_equal(got, rows(cs.cand_body, cs.ant_body, cs.cand_nodes, cs.ant_nodes, cs.point, cs.gap))
    for k, R in enumerate(ranks):
        assert np.all(owner[R["cand_body"]] == k)
        # the contact ownership over the serial contact set (its detection order): the candidate's rank
        assert np.array_equal(R["contact_owner"], owner[cs.cand_body])
        assert np.count_nonzero(R["contact_owner"] == k) == len(R["cand_body"])
        assert np.all(np.isin(R["ant_body"], np.concatenate([R["owned"], R["ghost"]])))
    # exchange lists: contacts sharing a body (brute force over all contact pairs) owned by different ranks
    c, a = cs.cand_body, cs.ant_body
    share = (c[:, None] == c[None, :]) | (c[:, None] == a[None, :]) | (a[:, None] == c[None, :]) | \
        (a[:, None] == a[None, :])
    co = owner[cs.cand_body]
    for p in range(n):
        for q in range(n):
            if p == q:
                continue
            expected = np.flatnonzero((co == p) & share[:, co == q].any(axis=1))
            assert np.array_equal(ranks[p].get(f"send{q}", np.zeros(0, dtype=np.int64)), expected)
            assert np.array_equal(ranks[q].get(f"recv{p}", np.zeros(0, dtype=np.int64)), expected)
    if n > 1:
        assert all(any(k.startswith("send") for k in R) for R in ranks)  # every rank has interface contacts
    # edge cut: contact counts (at least 1) on the pairs within reach or in contact, cut by the owner array
    w = np.zeros((nb, nb), dtype=np.int64)
    np.add.at(w, (np.minimum(cs.cand_body, cs.ant_body), np.maximum(cs.cand_body, cs.ant_body)), 1)
    edge = np.triu(near) | (w > 0)
    cut = np.maximum(w, 1)[edge & (owner[:, None] != owner[None, :])].sum()
    assert int(ranks[0]["edge_cut"]) == cut and all(int(R["edge_cut"]) == cut for R in ranks)


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")
def test_more_ranks_than_bodies(tmp_path):
    """One brick on its foundation (2 bodies) on 3 ranks: a rank owns nothing and the contacts are still all
    there, once."""
    path = write_case(tmp_path, "one", 'type = "courses"\nrows = [[1]]', 0.0, 0.0, 1e-3)
    ranks = run_mpi(3, path, str(tmp_path / "p"), tmp_path)
    model = build_model(load_case(path))
    assert len(model.bodies) == 2
    owner = ranks[0]["owner"]
    assert np.array_equal(np.sort(np.concatenate([R["owned"] for R in ranks])), np.arange(2))
    empty = [R for R in ranks if len(R["owned"]) == 0]
    assert len(empty) >= 1
    assert all(len(R["ghost"]) == 0 and len(R["cand_body"]) == 0 for R in empty)
    cs = serial_contacts(model)
    assert sum(len(R["cand_body"]) for R in ranks) == len(cs.gap) > 0
    assert all(np.all(owner[R["cand_body"]] == R["rank"]) for R in ranks)


@pytest.mark.parametrize("n", [2, 3])
def test_vertex_weights_balance_the_weight_of_each_rank(tmp_path, n):
    """distributed/graph.py partition_graph with vertex weights (set in PETSc through ctypes: petsc4py 3.18 has no
    MatPartitioningSetVertexWeights) on a 36 x 20 grid graph whose corner x < 12, y < 10 weighs 6 per vertex, the rest
    1 (total 6 x 120 + 600 = 1 320): every rank's weight is within 3 % of 1 320 / n (PT-Scotch's imbalance tolerance
    is 1 %; a vertex weighs at most 6 = 1.4 % of a share on 3 ranks), the same owner array on every rank. Without
    weights the same graph is split by vertex count (within 3 % of 720 / n), which leaves the weights at least 20 %
    apart: the weights reach PT-Scotch. Catches: the weights not passed (the plain split),
    every rank passing the first rows' weights instead of its own block's (rank 1 of 2 would pass heavy weights for
    light vertices)."""
    from _mpi import rank_results, run_helper
    run_helper(n, "_weights_mpi.py", tmp_path / "w")
    ranks = rank_results(tmp_path / "w", n)
    assert all(r == ranks[0] for r in ranks)
    w = np.array(ranks[0]["w"])
    assert w.sum() == 1320 and w.size == 720
    weighted, plain = np.array(ranks[0]["weighted"]), np.array(ranks[0]["plain"])
    per = np.bincount(weighted, weights=w, minlength=n)
    assert np.all(np.abs(per - w.sum() / n) <= 0.03 * w.sum() / n), per
    counts = np.bincount(plain, minlength=n)
    assert np.all(np.abs(counts - w.size / n) <= 0.03 * w.size / n), counts
    plain_w = np.bincount(plain, weights=w, minlength=n)
    assert plain_w.max() >= 1.2 * plain_w.min(), plain_w


class _Ranks:
    """A stand-in communicator of `size` ranks for the contact step's rule (one process: its all-reduce returns
    this rank's value, which every rank computes alike)."""

    def __init__(self, size, rank=0):
        self.size, self.rank = size, rank

    def Get_size(self):
        return self.size

    def Get_rank(self):
        return self.rank

    def allreduce(self, x, op=None):
        return x


def _stepper(counts, bound, new):
    """A ContactStep holding only what `_rebalance` reads: one candidate body per contact, owned as `counts` says
    (contact c's candidate body is nc - 1 - c), and a partition stub returning `new`."""
    from types import SimpleNamespace
    from fem_blocks.contact.step import ContactStep
    from fem_blocks.specs import ContactOptions
    owner = np.repeat(np.arange(len(counts)), counts)
    step = ContactStep.__new__(ContactStep)
    step.comm = _Ranks(len(counts))
    step.cs = SimpleNamespace(cand_body=np.arange(owner.size)[::-1].copy(), gap=np.zeros(owner.size))
    step.body_owner = owner[::-1].copy()
    step.opts = ContactOptions(geometry="updated", rebalance=bound)
    step.rebalanced = 0
    step._partition = lambda rows: new
    step._given = lambda: np.arange(owner.size)  # (this one "rank" counts every contact: the stand-in's sums)
    return step


@pytest.mark.parametrize("counts, bound, again", [
    ((12, 8), 1.2, False),      # 12 = 1.2 x the mean 10 (24 = 1.2 x 20 exactly in doubles): at the bound, kept
    ((12, 8), 1.1, True),       # 12 > 11: partitioned again
    ((12, 8), 1.25, False),     # 12 <= 12.5
    ((10, 10, 0), 1.1, True),   # a rank without contacts counts in the mean (20 / 3): 10 > 7.33
    ((8, 6, 6), 1.0, True),     # rebalance = 1: any imbalance
    ((5, 5, 5, 5), 1.0, False),  # none
])
def test_rebalance_partitions_again_beyond_the_bound(counts, bound, again):
    """contact/step.py ContactStep._rebalance against its rule (docs/case-files.md `rebalance`): the bodies are
    partitioned again iff the rank that owns most contacts (those of its candidate bodies) owns more than
    rebalance x (contacts / ranks); the new partition is then the one in use, and the count of re-partitions grows.
    One body per contact here, each owned as `counts` says; the partition is a stub (the rule is under test, not
    PT-Scotch: it returns an even split, which is better in every case here). Catches: >= for > (the first case),
    the mean over the ranks that own contacts (the fourth), the new partition computed but not kept (the last
    assertion)."""
    n, size = sum(counts), len(counts)
    new = (np.arange(n) * size // n).astype(np.int64)  # (as even as n allows)
    step = _stepper(counts, bound, new)
    assert step._rebalance() is again
    assert step.rebalanced == int(again)
    assert (step.body_owner is new) is again


def test_a_new_partition_no_better_is_not_kept():
    """contact/step.py ContactStep._rebalance keeps a new partition only if its busiest rank owns fewer contacts
    than the partition in use: PT-Scotch returning the same imbalance (14 + 6 contacts again, the ranks swapped)
    leaves the partition in use, and nothing is counted; one contact better (13 + 7) is kept. Catches: the new
    partition kept whatever it gives (the rows moved between ranks for nothing at every re-detection)."""
    swapped = np.repeat([1, 0], [14, 6])[::-1].copy()
    step = _stepper((14, 6), 1.1, swapped)
    before = step.body_owner
    assert step._rebalance() is False and step.body_owner is before and step.rebalanced == 0
    better = np.repeat([0, 1], [13, 7])[::-1].copy()
    step = _stepper((14, 6), 1.1, better)
    assert step._rebalance() is True and step.body_owner is better and step.rebalanced == 1


def test_a_partition_from_a_whole_set_takes_each_contact_from_one_rank(monkeypatch):
    """contact/step.py ContactStep._owner's partition from a whole contact set on every rank (a checkpoint resumed
    without a usable partition; the run's first partition is made from a provisional split, `_first_partition`)
    gives the graph (distributed/graph.partition_contact_graph, stubbed here) a contiguous share of the contacts per
    rank: over 3 ranks the shares are the 7 contacts once each, in order. Catches: every rank giving the whole set
    (each contact counted 3 times in the edge and vertex weights), or shares that overlap or leave a contact out."""
    from types import SimpleNamespace
    import fem_blocks.distributed.graph as graph
    from fem_blocks.contact.step import ContactStep
    seen = []

    def stub(nb, cand, ant, comm, method="ptscotch"):
        seen.append((np.asarray(cand).tolist(), np.asarray(ant).tolist()))
        return np.zeros(nb, dtype=np.int64)
    monkeypatch.setattr(graph, "partition_contact_graph", stub)
    cand, ant = [0, 0, 3, 3, 3, 2, 4], [1, 2, 0, 4, 1, 4, 0]
    for rank in range(3):
        step = ContactStep.__new__(ContactStep)
        step.comm = _Ranks(3, rank)
        step.scene = SimpleNamespace(nb=5)
        step.body_owner = None
        step.cs = SimpleNamespace(cand_body=np.array(cand), ant_body=np.array(ant), gap=np.zeros(7))
        assert step._owner().tolist() == [0] * 7
    assert sum((c for c, _ in seen), []) == cand and sum((a for _, a in seen), []) == ant
    assert all(len(c) in (2, 3) for c, _ in seen)


@pytest.mark.parametrize("n", [1, 2, 3])
def test_the_body_graph_is_assembled_from_the_contacts_each_rank_gives(tmp_path, n):
    """distributed/graph.py contact_graph_rows on n ranks, each giving an interleaved share of 120 contacts among
    23 bodies (pairs repeated and in both orientations, a self pair, a body without contacts): every rank's rows of
    the graph (CSR and edge weights) and its vertex weights are those of body_graph and contact_weights of the
    whole list, its block of rows PETSc's default. Catches: an edge sent one way only, an edge's weight 1 instead of
    its contacts, the vertex weights counted from the antagonists or not summed over the ranks, rows sent to the
    wrong rank."""
    from _mpi import rank_results, run_helper
    run_helper(n, "_graph_rows_mpi.py", tmp_path / "g")
    for r in rank_results(tmp_path / "g", n):
        assert r["got"] == r["want"]
        assert len(r["want"]["ja"]) > 0


@pytest.mark.parametrize("err", [0, 73])
def test_the_vertex_weights_buffer_is_freed_when_petsc_does_not_take_it(monkeypatch, err):
    """distributed/graph._set_vertex_weights hands MatPartitioningSetVertexWeights a PetscMalloc copy of the weights,
    which the MatPartitioning then owns; if the call fails, the buffer is still ours and is freed (PetscFreeA, given
    the pointer's address as PetscFree passes it) before the error. The PETSc library is a stand-in that records the
    calls (PETSc's own call cannot be made to fail). Catches: the buffer leaked on failure, freed on success (PETSc
    would free it twice), or PetscFreeA given the pointer instead of its address."""
    import ctypes
    from types import SimpleNamespace
    from mpi4py import MPI
    from petsc4py import PETSc
    import fem_blocks.distributed.graph as graph

    class Lib:
        def __init__(self):
            self.freed, self.got, self.buf = [], None, None

        def PetscMallocA(self, n, clear, line, func, file, size, pptr):
            self.buf = ctypes.create_string_buffer(size.value)
            pptr._obj.value = ctypes.addressof(self.buf)  # (byref's object: the caller's pointer)
            return 0

        def MatPartitioningSetVertexWeights(self, part, ptr):
            self.got = np.frombuffer(self.buf, dtype=PETSc.IntType).tolist()
            return err

        def PetscFreeA(self, n, line, func, file, pptr):
            self.freed.append(pptr._obj.value)
            return 0
    lib = Lib()
    monkeypatch.setattr(graph, "_petsc_library", lambda: lib)
    part = SimpleNamespace(handle=1)
    if err:
        with pytest.raises(RuntimeError, match="MatPartitioningSetVertexWeights failed \\(PETSc error 73\\)"):
            graph._set_vertex_weights(part, np.array([3, 1, 2]), MPI.COMM_SELF)
        assert lib.freed == [ctypes.addressof(lib.buf)]
    else:
        assert graph._set_vertex_weights(part, np.array([3, 1, 2]), MPI.COMM_SELF) is True
        assert lib.freed == []
    assert lib.got == [3, 1, 2]
