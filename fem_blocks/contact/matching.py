"""Matching an old contact set to a new one after a re-detection (both dimensions), to carry impulses and law
states: the new contact j continues the old contact i when both have the same candidate point `key` and the same
antagonist body,

    m[j] = i  if (key_i, ant_body_i) = (key_j, ant_body_j),  else -1,

the lowest such i if several (detection keeps one contact per (key, antagonist body) in 3D and one per key in 2D,
so there is at most one). Keys are the detection modules' stable candidate-point ids (contact/detection_2d.py,
contact/detection_3d.py: position points from their edge/face and index, node points from the node).

A contact's id (`contact_ids`), the same number on every MPI rank without the whole contact set,

    id = key · nb + ant_body        (nb bodies, 0 <= ant_body < nb),

increases with (key, ant_body) in lexicographic order, which is the detections' order of their contacts: sorting
contacts by id gives them in the whole detection's order, and the contacts of two detections continue each other
when their ids are equal.
"""
from __future__ import annotations

import numpy as np


def match(old, new) -> np.ndarray:
    """(len(new),) int64: index into `old` of each contact of `new` with the same (key, ant_body), or -1. `old`
    and `new` are ContactSets of either dimension (anything with int arrays `key` and `ant_body`)."""
    if len(old) == 0 or len(new) == 0:
        return -np.ones(len(new), dtype=np.int64)
    # (key, ant_body) as one int64 increasing with the pair in lexicographic order: the key's rank among the keys
    # times the number of bodies, plus the body (one sort of integers, not of rows)
    _, kid = np.unique(np.concatenate([old.key, new.key]), return_inverse=True)
    ant = np.concatenate([old.ant_body, new.ant_body]).astype(np.int64)
    cid = kid.ravel().astype(np.int64) * (int(ant.max()) + 1) + ant
    co, cn = cid[:len(old)], cid[len(old):]
    o = np.argsort(co, kind="stable")
    pos = np.minimum(np.searchsorted(co[o], cn), len(co) - 1)
    hit = co[o][pos] == cn
    return np.where(hit, o[pos], -1).astype(np.int64)


def contact_ids(key, ant_body, nb: int) -> np.ndarray:
    """(n,) int64: the contacts' ids key · nb + ant_body (module docstring). OverflowError if a key is too large for
    the ids to fit in int64 with nb bodies."""
    key = np.asarray(key, dtype=np.int64)
    if key.size and int(np.abs(key).max()) >= (2 ** 62) // max(int(nb), 1):
        raise OverflowError(f"contact ids: keys up to {int(np.abs(key).max())} with {nb} bodies exceed int64")
    return key * np.int64(nb) + np.asarray(ant_body, dtype=np.int64)
