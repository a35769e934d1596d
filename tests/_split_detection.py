"""The check of a rank's part of the detection (`detect(..., bodies=mask)`), shared by the 2D and 3D tests
(tests/test_placement.py, tests/test_detection3d.py): for five partitions of the bodies into 3 parts (cyclic,
random, two halves, two cyclic parts and an empty third, the first body alone on the third rank: a rank without
bodies, a rank whose only body may be no contact's candidate), each part must be the whole detection's rows of the
contacts whose candidate body is in it, every field bit for bit and in the same order, and the parts merged in the
whole detection's order (key, then antagonist body: ContactStep._gather_set's) must be the whole set."""
import numpy as np


def check_parts(detect, args, whole, nb: int, rng, label):
    """Run the check with `detect(*args, bodies=mask)` against the whole detection `whole` of `nb` bodies; rng draws
    the random partition; label names the case in the assertion messages."""
    for owner in (np.arange(nb) % 3, rng.integers(0, 3, nb), (np.arange(nb) >= nb // 2).astype(int), np.arange(nb) % 2,
                  np.where(np.arange(nb) == 0, 2, np.arange(nb) % 2)):
        parts = []
        for p in range(3):
            mask = owner == p
            part = detect(*args, bodies=mask)
            want = whole.subset(np.flatnonzero(mask[whole.cand_body]))
            for k, v in want.__dict__.items():
                assert getattr(part, k).tobytes() == v.tobytes(), (label, p, k)
            parts.append(part)
        cat = {k: np.concatenate([getattr(q, k) for q in parts]) for k in whole.__dict__}
        o = np.lexsort((cat["ant_body"], cat["key"]))
        for k, v in whole.__dict__.items():
            assert cat[k][o].tobytes() == v.tobytes(), (label, k)
