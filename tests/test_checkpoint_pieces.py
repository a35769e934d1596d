"""Checkpoints in pieces, one per MPI rank (output/checkpoint.py split / merge / latest_checkpoint_files,
distributed/checkpoint.py; issue #24: "checkpoints per rank with the partition").

Expectations from outside the code under test:
- which entries of a real checkpoint are per contact: those whose first dimension is the contact count (the case is
  chosen so that no other entry has that length), and per body: the names "sim.body<i>.*" parsed here;
- the merged pieces are the checkpoint that was split, key for key, dtype, shape and bytes;
- which set of pieces is the newest: the rounds written here, in a known order.

One-line bugs these catch: a per-contact entry left out of ContactStep.PER_CONTACT (every rank would hold all its
rows); merge taking the rows of piece 0 only; the contacts' owner taken from the antagonist body; the newest set
chosen by the largest step (an older run's pieces in .prev win); a set taken with one rank's piece missing; a
one-process checkpoint left beside a newer set of pieces (or the reverse).
"""
import os
import re
import shutil

import numpy as np
import pytest

from fem_blocks.contact.step import ContactStep
from fem_blocks.dynamics import body_of_key
from fem_blocks.errors import InputError
from fem_blocks.output.checkpoint import (NAME, PREV, latest_checkpoint_files, load_checkpoint, merge, piece_names,
                                          read_checkpoint, remove_other_layout, split, write_checkpoint)

def case(geometry):
    """A wall with cohesive (mixed-mode) joints, 3 courses of 2 bricks, 3 steps of 1 ms (tests/dist_cases.py), in
    `geometry` with the extrapolated predictor (the previous impulses checkpointed)."""
    import dist_cases
    text = dist_cases.wall("ck", joint=dist_cases.MIXED, tol=1e-4, max_sweeps=3000, duration=0.003)
    return text.replace("[contact]\n", f'[contact]\ngeometry = "{geometry}"\npredictor = "extrapolated"\n', 1)


@pytest.fixture(scope="module", params=["frozen", "updated"])
def real(request, tmp_path_factory):
    """The checkpoint of a short serial run of a wall with cohesive joints (frozen geometry: reference gaps; updated:
    as-built offsets), and its contact and body counts."""
    from fem_blocks import cli
    d = tmp_path_factory.mktemp(f"ck_{request.param}")
    (d / "ck.toml").write_text(case(request.param))
    assert cli.main(["run", str(d / "ck.toml"), "--out", str(d / "out"), "--quiet"]) == 0
    ck = read_checkpoint(d / "out" / NAME)
    nc = len(ck["contact.cs.gap"])
    nb = 1 + max(int(m[1]) for m in (re.match(r"sim\.body(\d+)\.", k) for k in ck) if m)
    return ck, nc, nb


def _by_contact(ck, nc):
    """The entries with one row per contact, found from their shapes (independent of the code's list)."""
    return {k for k, v in ck.items() if np.ndim(v) >= 1 and np.shape(v)[0] == nc}


def test_the_per_contact_and_per_body_entries_are_the_real_ones(real):
    ck, nc, nb = real
    others = {np.shape(v)[0] for k, v in ck.items() if np.ndim(v) >= 1 and k not in _by_contact(ck, nc)}
    assert nc not in others and nc > nb  # the shapes tell the per-contact entries apart in this case
    assert {"contact.P", "contact.P_prev", "contact.state", "contact.cs.cand_body", "contact.out.r"} <= \
        _by_contact(ck, nc)
    assert set(ContactStep.per_contact_keys(ck)) == _by_contact(ck, nc)
    for k in ck:
        m = re.match(r"sim\.body(\d+)\.", k)
        assert body_of_key(k) == (int(m[1]) if m else None), k
    assert body_of_key("sim.bodyx.q") is None and body_of_key("sim.body") is None


def test_pieces_hold_their_rows_and_merge_back_bitwise(real):
    ck, nc, nb = real
    rng = np.random.default_rng(3)
    owner = rng.integers(0, 3, nb)
    owner[:3] = [0, 1, 2]
    pieces = [split(ck, p, 3, "t", owner, body_of_key, ContactStep.per_contact_keys(ck)) for p in range(3)]
    cand, ant = ck["contact.cs.cand_body"], ck["contact.cs.ant_body"]
    assert np.count_nonzero(owner[cand] != owner[ant]) > 0  # contacts across ranks
    for p, d in enumerate(pieces):
        rows = np.flatnonzero(owner[cand] == p)
        for k in _by_contact(ck, nc):
            assert np.array_equal(d[k], np.asarray(ck[k])[rows]), (p, k)
        for k in ck:
            b = body_of_key(k)
            if b is not None:
                assert (k in d) == (owner[b] == p), (p, k)
    back = merge([pieces[2], pieces[0], pieces[1]])
    assert set(back) == set(ck) - {"_digest"}
    for k in back:
        a, b = np.asarray(back[k]), np.asarray(ck[k])
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), k


def test_merge_refuses_an_incomplete_set(real):
    ck, nc, nb = real
    owner = np.arange(nb) % 2
    keys = ContactStep.per_contact_keys(ck)
    p0, p1 = (split(ck, p, 2, "t", owner, body_of_key, keys) for p in range(2))
    with pytest.raises(InputError, match="complete set"):
        merge([p0])
    with pytest.raises(InputError, match="complete set"):
        merge([p0, split(ck, 1, 2, "other", owner, body_of_key, keys)])
    p1["part.contact_ids"] = p1["part.contact_ids"][1:]
    for k in keys:
        p1[k] = p1[k][1:]
    with pytest.raises(InputError, match="each of the"):
        merge([p0, p1])


# ---------------------------------------------------------------- the newest complete set on disk

def _state(step):
    """A small checkpoint: 4 bodies, 5 contacts (rows numbered by step so that sets differ)."""
    return {"sim.step": np.int64(step), "sim.time": np.float64(step * 1e-3),
            **{f"sim.body{i}.q": np.full(3, step + i, dtype=float) for i in range(4)},
            "contact.cs.cand_body": np.array([0, 1, 2, 3, 3]), "contact.cs.ant_body": np.array([1, 2, 3, 0, 1]),
            "contact.cs.key": np.array([3, 7, 11, 15, 16]),
            "contact.P": np.arange(10, dtype=float).reshape(5, 2) + step, "contact.steps": np.int64(step)}


OWNER = np.array([0, 1, 2, 2])


def _round(d, step, ranks, size=3, token=None):
    ck = _state(step)
    for p in ranks:
        write_checkpoint(str(d), split(ck, p, size, token or f"s{step}", OWNER if size == 3 else np.arange(4) % size,
                                       body_of_key, ContactStep.per_contact_keys(ck)), piece_names(p))


def _step(d):
    return int(latest_checkpoint_files(str(d), warn=lambda m: None)[2]["sim.step"])


def test_the_newest_complete_set_is_taken(tmp_path):
    _round(tmp_path, 4, (0, 1, 2))
    _round(tmp_path, 6, (0, 1))  # rank 2 killed before it wrote step 6
    warned = []
    label, paths, ck = latest_checkpoint_files(str(tmp_path), warn=warned.append)
    assert int(ck["sim.step"]) == 4 and len(paths) == 3 and "rank 2" in warned[0]
    assert np.array_equal(ck["contact.P"], _state(4)["contact.P"])
    assert load_checkpoint(paths)["contact.P"].tobytes() == ck["contact.P"].tobytes()
    _round(tmp_path, 6, (2,))
    assert _step(tmp_path) == 6
    with open(tmp_path / piece_names(1)[0], "r+b") as f:  # rank 1's newest piece corrupted: the set before
        f.seek(200)
        f.write(b"\0" * 64)
    assert _step(tmp_path) == 4
    os.unlink(tmp_path / piece_names(1)[1])
    with pytest.raises(InputError, match="rank 1's piece"):
        latest_checkpoint_files(str(tmp_path), warn=lambda m: None)


def test_an_older_run_with_more_steps_does_not_win(tmp_path):
    """A new run's first set (step 2) against an earlier run's set of step 90 in the .prev pieces."""
    _round(tmp_path, 90, (0, 1, 2))
    _round(tmp_path, 2, (0, 1, 2))
    assert _step(tmp_path) == 2


def test_one_layout_at_a_time(tmp_path):
    """A complete checkpoint of one layout removes the other's files (no older checkpoint taken for the newest)."""
    _round(tmp_path, 4, (0, 1, 2))
    write_checkpoint(str(tmp_path), _state(5))  # one process resumes from the pieces and writes
    assert sorted(os.listdir(tmp_path)) == [NAME] and _step(tmp_path) == 5
    _round(tmp_path, 7, (0, 1), size=2)
    remove_other_layout(str(tmp_path), 2)  # (what rank 0 does once a set is complete)
    assert sorted(os.listdir(tmp_path)) == sorted(piece_names(0)[:1] + piece_names(1)[:1])
    assert _step(tmp_path) == 7
    shutil.copy(tmp_path / piece_names(0)[0], tmp_path / piece_names(2)[0])  # a piece of an earlier run on 3 ranks
    _round(tmp_path, 8, (0, 1), size=2)
    remove_other_layout(str(tmp_path), 2)
    assert _step(tmp_path) == 8
    assert not (tmp_path / piece_names(2)[0]).exists()
    assert not (tmp_path / PREV).exists()


# ---------------------------------------------------------------- the ranks write a round together

def test_ranks_write_their_pieces_together_and_share_a_failure(tmp_path):
    """On 2 ranks (tests/_ck_pieces_mpi.py): a round of pieces merges back to the checkpoint written; in a second
    round rank 1 fails: it raises its error, rank 0 a RuntimeError naming rank 1, neither is left waiting, and the
    first round's set is still the newest complete one (rank 0's new piece has no partner)."""
    import _ck_pieces_mpi
    from _mpi import run_helper
    run_helper(2, "_ck_pieces_mpi.py", tmp_path)
    assert (tmp_path / "raised1.txt").read_text() == "ValueError: no room left"
    assert (tmp_path / "raised0.txt").read_text().startswith("RuntimeError: checkpoint: rank 1 could not write")
    warned = []
    _, paths, ck = latest_checkpoint_files(str(tmp_path), warn=warned.append)
    assert len(paths) == 2 and warned
    want = _ck_pieces_mpi.state(3)
    assert set(ck) == set(want)
    for k in want:
        assert np.asarray(ck[k]).tobytes() == np.asarray(want[k]).tobytes(), k
    assert int(read_checkpoint(tmp_path / piece_names(0)[0])["sim.step"]) == 5  # rank 0's piece of round 2
    assert len(read_checkpoint(tmp_path / piece_names(1)[0])["contact.P"]) == 2  # rank 1: contacts 1, 2 (bodies 1, 2)
