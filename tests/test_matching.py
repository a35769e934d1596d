"""contact/matching.match after a re-detection, 2D and 3D: contacts appear, vanish and reorder; the carried impulses
land on the contacts that continue the same candidate point against the same antagonist body. The expectation is
built from the geometry (candidate body, antagonist body, candidate point in the candidate body's frame), written
out by hand, never from the contact keys."""
import numpy as np

from fem_blocks.contact import detection_2d as det
from fem_blocks.contact import detection_3d as d3
from fem_blocks.contact.matching import match
from test_detection3d import box, detect
from test_detection_delassus import squares, table


def identities(cs, shift):
    """(candidate body, antagonist body, candidate point moved back to the first configuration) per contact."""
    return [(int(c), int(a), tuple(np.round(p - shift[c], 9) + 0.0)) for c, a, p in zip(cs.cand_body, cs.ant_body,
                                                                                        cs.point)]


def carry(old_ids, new_ids, P_old):
    """What a re-detection must carry: the impulse of the old contact with the same identity, else 0."""
    return np.array([P_old[old_ids.index(k)] if k in old_ids else np.zeros(P_old.shape[1]) for k in new_ids])


def check(old, new, old_ids, new_ids, n_carried):
    P_old = np.arange(1.0, 1.0 + old.point.shape[1] * len(old)).reshape(len(old), -1)
    m = match(old, new)
    P = np.zeros((len(new), P_old.shape[1]))
    ok = m >= 0
    P[ok] = P_old[m[ok]]  # as ContactStep carries impulses and law states
    assert np.array_equal(P, carry(old_ids, new_ids, P_old))
    assert ok.sum() == n_carried


def test_match_2d_appear_vanish_reorder_and_new_antagonist():
    # body 0 at the origin; 1 on it, 2 beside it; 3 and 4 far away. Then 1 leaves, 3 takes its place (same
    # candidate points of body 0, another antagonist: not the same contacts), 4 comes under body 0.
    n = 5
    old_c = [(0, 0), (0, 1), (1, 0), (5, 5), (8, 8)]
    new_c = [(0, 0), (0, 3), (1, 0), (0, 1), (0, -1)]
    shift = np.array(new_c, float) - np.array(old_c, float)
    cs = [det.detect(*squares(c), np.zeros(n, int), np.zeros(n, int), table()) for c in (old_c, new_c)]
    old_ids, new_ids = identities(cs[0], 0 * shift), identities(cs[1], shift)
    assert sorted(old_ids) == [(0, 1, (0.25, 1.0)), (0, 1, (0.75, 1.0)), (0, 2, (1.0, 0.25)), (0, 2, (1.0, 0.75))]
    assert sorted(new_ids) == [(0, 2, (1.0, 0.25)), (0, 2, (1.0, 0.75)), (0, 3, (0.25, 1.0)), (0, 3, (0.75, 1.0)),
                               (0, 4, (0.25, 0.0)), (0, 4, (0.75, 0.0))]
    assert new_ids[:2] != old_ids[:2]  # the order changed
    check(cs[0], cs[1], old_ids, new_ids, 2)


def test_match_3d_same_point_on_two_antagonists():
    # unit boxes, node placement: 0 on top of 1 and 2 (its nodes at x = 1 touch both: one candidate point, two
    # antagonist bodies); then 1 moves down by 0.5 and 3 comes beside 0 (its nodes at x = 2 then touch 2 and 3).
    # The contact (node, antagonist 2) continues although the node's first contact in the old set was with 1.
    tab = d3.simple_table(placement="nodes")
    old_o = [(1, 0, 1), (0, 0, 0), (1, 0, 0), (5, 0, 1)]
    new_o = [(1, 0, 1), (0, 0, -0.5), (1, 0, 0), (2, 0, 1)]
    shift = np.array(new_o, float) - np.array(old_o, float)
    cs = [detect([box(o) for o in origins], tab)[0] for origins in (old_o, new_o)]
    old_ids, new_ids = identities(cs[0], 0 * shift), identities(cs[1], shift)
    assert sorted(old_ids) == sorted([
        (1, 2, (1.0, 1.0, 1.0)), (1, 2, (1.0, 0.0, 1.0)), (1, 2, (1.0, 1.0, 0.0)), (1, 2, (1.0, 0.0, 0.0)),
        (0, 1, (1.0, 1.0, 1.0)), (0, 1, (1.0, 0.0, 1.0)), (0, 2, (1.0, 1.0, 1.0)), (0, 2, (1.0, 0.0, 1.0)),
        (0, 2, (2.0, 1.0, 1.0)), (0, 2, (2.0, 0.0, 1.0))])
    assert sorted(new_ids) == sorted([
        (2, 3, (2.0, 1.0, 1.0)), (2, 3, (2.0, 0.0, 1.0)), (1, 2, (1.0, 1.0, 1.0)), (1, 2, (1.0, 0.0, 1.0)),
        (0, 3, (2.0, 1.0, 2.0)), (0, 3, (2.0, 0.0, 2.0)), (0, 3, (2.0, 1.0, 1.0)), (0, 3, (2.0, 0.0, 1.0)),
        (0, 2, (1.0, 1.0, 1.0)), (0, 2, (1.0, 0.0, 1.0)), (0, 2, (2.0, 1.0, 1.0)), (0, 2, (2.0, 0.0, 1.0))])
    check(cs[0], cs[1], old_ids, new_ids, 6)


def test_match_is_the_lowest_old_contact_with_the_same_key_and_antagonist():
    """match against its definition, by brute force: random keys of both signs (the detection's node and overlap keys
    are negative) far apart in magnitude, repeated (key, antagonist) pairs in the old set (the lowest index wins),
    antagonists up to the largest body. Catches a pair code that confuses two pairs (a key times too few bodies), a
    match that is not the lowest old contact, or the old contacts' order lost."""
    class Set:
        def __init__(self, key, ant):
            self.key, self.ant_body = key, ant

        def __len__(self):
            return len(self.key)
    rng = np.random.default_rng(3)
    values = np.array([-(2 ** 50), -12345678901, -7, -1, 0, 3, 9, 2 ** 40])
    for trial in range(20):
        nb = int(rng.integers(1, 6))
        old, new = (Set(rng.choice(values, m), rng.integers(0, nb, m)) for m in rng.integers(0, 30, 2))
        want = []
        for k, a in zip(new.key, new.ant_body):
            hits = [i for i in range(len(old)) if old.key[i] == k and old.ant_body[i] == a]
            want.append(hits[0] if hits else -1)
        assert match(old, new).tolist() == want, trial
