"""On N > 1 ranks in colour order each rank holds the contact step's per-contact arrays (impulses, warm start, law
state and parameters, reference gaps) for its own contacts only, and computes, solves and commits those rows alone;
so does the step's record (contact/result.py: `rows`), whose whole() gathers every contact's rows on demand; per
step only the totals cross ranks (contact/step.py ContactStep.ROWS, _own_rows, _L_impulses). No rank detects or holds
the whole contact set: each keeps its part L (the contacts with a body among its own and its own contacts' bodies).

Expectation (from outside the distributed code): the same steps on ONE process in colour order. After each of 3
steps the record of every contact (impulses, reactions, velocities, law state, end gaps, status, dissipation, law
codes), its totals and statistics and the velocities of the bodies each rank steps are the serial ones bit for bit
on every rank; each rank
and its record hold exactly the rows of the contacts whose candidate body it owns (their union is every contact
once); each rank's contact set at the end is exactly L computed from the serial set and the partition, smaller than
the whole set; the first partition is made once, from a graph given every contact of the first step once; the
runner's snapshot of a step (what a refined or
adaptive step restores) holds those rows, and restoring it and stepping again gives the same step again, bitwise;
written as the runner's checkpoint one step later (what a failed step writes; "rebalanced" partitions again in that
step), its pieces merge into the serial snapshot.
Cases: a wall with mixed-mode cohesive joints (law state carried and committed per rank) in frozen geometry, a
dry wall in updated geometry re-detected every other step (at step 3, and again after the restore: the impulses
carried to the new contact set by their owners; at step 2 the contacts are those of step 1, and the colour solver
of the new W takes over the previous one's colours and PETSc scatters: contact/step.py `_colour_solver`), a
wall with mixed-mode joints in updated geometry re-detected at every step with `rebalance = 1.0`, whose bodies are
partitioned again at a re-detection (contact/step.py `_rebalance`; the helper's first partition is lopsided and its
next one balanced with the ranks' labels turned, so that bodies and their contacts' impulses and law states move to
another rank, sent to it by their old owners: contact/step.py `_carry_rows`; the one offered after it is no better
and is not kept), and a 3D wall (node points, the law state one column wider) in
updated geometry re-detected at every step, partitioned again as "rebalanced": each rank detects the contacts of the
candidates around its bodies (detection_3d.detect's `bodies`, contact/step.py `_candidates`) and keeps its part.

One-line bugs these catch (checked): the ghosts' warm start left at zero instead of exchanged (the iterates differ
from the second step); the own rows gathered in rank order but not put back in contact order; a re-detected
contact's impulse carried from its old place in the rank's set instead of the old own rows; the impulses of the
contacts L owned elsewhere not scattered (the bodies' velocities differ); at a new partition, the old rows sent
in the old contacts' order instead of grouped by the rank they go to, or looked up in their arrival order instead of
sorted by id (rows misplaced: the helper's first partition gives a rank rows from several ranks interleaved); a rank
keeping the whole set, or detecting the candidates of one ring of neighbours only (L incomplete); its own contacts
numbered from 0 instead of after the ranks before; the first partition given every contact a rank holds; the
checkpoint of a snapshot taken before a step that partitioned again (what a failed step
writes) split with the new partition instead of the snapshot's (its pieces do not merge).
"""
import numpy as np
import pytest

import dist_cases
from _mpi import rank_results, run_alone, run_helper

HELPER = "_own_rows_mpi.py"
CASES = {
    "mixed": dist_cases.wall("mixed", courses=3, per=3, joint=dist_cases.MIXED),
    "updated": dist_cases.wall("updated", courses=3, per=3).replace(
        "[contact]\n", '[contact]\ngeometry = "updated"\nredetect_every = 2\npredictor = "extrapolated"\n'
        'rebalance = 100.0\n'),
    "rebalanced": dist_cases.wall("rebalanced", courses=3, per=3, joint=dist_cases.MIXED).replace(
        "[contact]\n", '[contact]\ngeometry = "updated"\nrebalance = 1.0\n'),
    "rebalanced3d": dist_cases.WALL3D.format(name="rebalanced3d").replace("courses = 2", "courses = 3").replace(
        "bricks_per_course = 2", "bricks_per_course = 3").replace(
        "[contact]\n", '[contact]\ngeometry = "updated"\nrebalance = 1.0\n').replace(
        "duration = 0.03", "duration = 0.05"),
}


@pytest.fixture(scope="module")
def launches(tmp_path_factory):
    """Both cases on one process and on 2 and 3 ranks: one launch each, the cases one after the other in it (the
    helper steps each as if launched alone). Returns (d, {case: serial results})."""
    d = tmp_path_factory.mktemp("own")
    for name, text in CASES.items():
        (d / f"{name}.toml").write_text(text)

    def pairs(tag):
        return [str(x) for name in sorted(CASES) for x in (d / f"{name}.toml", d / f"{name}.{tag}")]
    run_alone(HELPER, *pairs("serial"))
    for n in (2, 3):
        run_helper(n, HELPER, *pairs(n), timeout=300)
    return d, {name: rank_results(d / f"{name}.serial", 1)[0] for name in CASES}


@pytest.fixture(params=sorted(CASES))
def serial(request, launches):
    d, one = launches
    return d, request.param, one[request.param]


@pytest.mark.parametrize("n", [2, 3])
def test_each_rank_holds_and_steps_its_own_contacts_rows(serial, n):
    d, name, one = serial
    ranks = rank_results(d / f"{name}.{n}", n)
    nc = one["n_contacts"]
    assert nc > 20 and all(r["n_contacts"] == nc for r in ranks)
    owns = [r["own"] for r in ranks]
    assert sorted(sum(owns, [])) == one["own"] and len(one["own"]) == nc  # every contact owned by one rank
    assert sum(1 for o in owns if o) >= 2  # the contacts are shared
    pairs = {c: (cand, ant) for c, cand, ant in one["pairs"]}  # (id -> bodies, of the whole set)
    for r in ranks:  # the contacts a rank keeps: L = those with a body in B (its bodies, those of its own contacts)
        B = set(np.flatnonzero(np.array(r["owner_end"]) == r["rank"]).tolist())
        B |= {b for c in r["own"] for b in pairs[c]}
        assert r["held"] == sorted(c for c, (cand, ant) in pairs.items() if cand in B or ant in B)
        assert len(r["held"]) < nc  # (no rank holds the whole set)
    for r in ranks:
        k = len(r["own"])
        assert r["rows"]["P"] == r["rows"]["state"] == r["rows"]["par"] == r["rows"]["mu"] == k
        assert r["own_counts"][2] == k and r["snapshot_rows"] == r["own_counts"][1]
        for mine, ref, k_step in zip(r["steps"], one["steps"], r["own_counts"]):
            assert mine["record_rows"] == k_step  # the record holds the rank's own rows; whole(), every contact's
            assert {key: v for key, v in mine.items() if key not in ("warm", "record_rows", "u")} == \
                {key: v for key, v in ref.items() if key not in ("warm", "record_rows", "u")}
            assert mine["u"] and all(ref["u"][i] == v for i, v in mine["u"].items())  # the bodies it steps
        assert r["restored"] == {key: one["steps"][1][key] for key in ("P", "state")}
        assert r["snapshot_pieces"] == one["snapshot_pieces"] == {key: one["steps"][0][key] for key in ("P", "state")}
        assert r["again"] == r["steps"][2]
    assert one["again"] == one["steps"][2]
    if name.startswith("rebalanced"):  # partitioned again at the re-detection of step 2, from the helper's lopsided first
        # partition; the one offered at step 3 is no better and is not kept
        assert all(r["rebalanced"] == 1 for r in ranks)
        owners = ranks[0]["owners"]
        assert all(r["owners"] == owners for r in ranks) and owners[0] != owners[1] == owners[2]
        assert (np.array(owners[0]) != np.array(owners[1])).sum() >= 3  # (bodies, and their contacts' rows, moved)
    else:  # rebalance = 100 ("updated"), frozen geometry ("mixed"): the partition of the first step kept
        assert all(r["rebalanced"] == 0 for r in ranks) and ranks[0]["owners"][0] == ranks[0]["owners"][2]
        # made once, at the first step, from a graph to which the ranks gave every contact of that step once
        assert all(r["given"] == [one["steps"][0]["stats"][0]] for r in ranks)
    total = 0.0  # the totals: exact sums of the contacts' terms, rounded once (math.fsum), on one process too
    for st in one["steps"]:
        total += st["fsum"][1]
        assert st["dissipated"] == st["fsum"][0] and st["friction_total"] == total
    assert len(set(s["P"] for s in one["steps"])) == 3  # the steps differ (not a trivial state)
    assert all(s["record_rows"] == nc for s in one["steps"])


@pytest.mark.parametrize("n", [2, 3])
def test_the_own_rows_gather_orders_by_contact_id(tmp_path, n):
    """distributed/sweep.py OwnRowsGather and gather_fields on n ranks, each holding the rows of a random share of 23
    contact ids (-40, -35, ..., 70): every rank receives every row in increasing id order, integer, float, bool and
    (n, 2, 3) arrays with their dtypes and shapes; a contact held by two ranks raises on every rank (no rank left
    waiting). Catches: the rows in rank order (the layout's inverse not taken), the ids not checked for overlap, a
    field's trailing shape or dtype lost in the packing."""
    from _mpi import rank_results, run_helper
    run_helper(n, "_gather_mpi.py", tmp_path / "g")
    for r in rank_results(tmp_path / "g", n):
        want = np.array(r["want"])
        assert r["i"] == want.tolist()
        assert np.array_equal(np.array(r["f"]), np.column_stack([want * 0.5, -want * 0.25]))
        assert r["b"] == (want % 2 == 0).tolist()
        assert np.array_equal(np.array(r["t"]), np.repeat(want, 6).reshape(-1, 2, 3))
        assert r["dtypes"] == ["int64", "float64", "bool", "float64"]
        assert "held by two ranks" in r["twice"]


def test_leaving_colour_order_carries_every_old_row(tmp_path):
    """A run that leaves colour order through the Python API (ContactStep.set_options: "given" order with the interface
    coarse correction, under which every rank runs the same serial solve on the whole contact set) on 2 and 3 ranks:
    at the re-detection after the switch the old rows, each held by its owner with the rank's part of the set, are
    gathered whole by contact id (contact/step.py `_carry_rows`) and the run goes on as one process's, bit for bit
    (the records of the two steps before and the two after the switch). Catches the old rows gathered in rank order,
    or matched to the new contacts by place instead of id."""
    import dist_cases
    from _mpi import rank_results, run_helper
    case = tmp_path / "lv.toml"
    case.write_text(dist_cases.wall("lv", courses=3, per=3).replace(
        "[contact]\n", '[contact]\ngeometry = "updated"\nredetect_every = 1\n', 1))
    run_helper(1, "_leave_colours_mpi.py", case, tmp_path / "one")
    one = rank_results(tmp_path / "one", 1)[0]
    assert [s["order"] for s in one] == ["colours", "colours", "given", "given"] and one[0]["n"] > 20
    assert len({s["P"] for s in one}) == 4
    for n in (2, 3):
        run_helper(n, "_leave_colours_mpi.py", case, tmp_path / f"n{n}")
        for r in rank_results(tmp_path / f"n{n}", n):
            assert [s["part"] for s in r] == [True, True, False, False]  # (its part of the set, then the whole set)
            assert [{k: s[k] for k in ("P", "state", "n")} for s in r] == \
                [{k: s[k] for k in ("P", "state", "n")} for s in one]
