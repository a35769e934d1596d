"""bench/compare_outputs.py pairs the reference tree's cases with the working tree's: `--rename OLD=NEW` for demo
files renamed between the two (the shear walls of issue #21). The pairing is pure bookkeeping: a wrong one would
compare two different models and report their difference as a behaviour change (or, worse, hide one)."""
import importlib.util
import os

import pytest

_PATH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "bench", "compare_outputs.py")
_spec = importlib.util.spec_from_file_location("compare_outputs", _PATH)
C = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(C)

REF = {"shear_wall": ["ref-fc"], "shear_wall_p030_mixed_split": ["ref-split"], "arch": ["ref-arch"]}


def test_rename_pairs_old_case_under_new_name():
    out = C.rename_cases(REF, "shear_wall=shear_wall_fc_p030,shear_wall_p030_mixed_split=shear_wall_p030")
    assert out == {"shear_wall_fc_p030": ["ref-fc"], "shear_wall_p030": ["ref-split"], "arch": ["ref-arch"]}
    assert REF["shear_wall"] == ["ref-fc"] and len(REF) == 3  # the reference's own table is not modified


def test_rename_chain_swaps_without_losing_a_case():
    # a=b, b=c: REF's a becomes b and REF's b becomes c (applied at once, not one after the other)
    out = C.rename_cases({"a": [1], "b": [2]}, "a=b,b=c")
    assert out == {"b": [1], "c": [2]}


def test_no_rename_is_identity():
    assert C.rename_cases(REF, "") == REF


@pytest.mark.parametrize("spec, words", [("nope=x", "'nope' is not a case"), ("shear_wall", "expected OLD=NEW"),
                                         ("shear_wall=", "expected OLD=NEW"),
                                         ("shear_wall=x,arch=x", "same new name"),
                                         ("arch=x,arch=y", "same old name")])
def test_bad_rename_names_the_pair(spec, words):
    with pytest.raises(ValueError, match=words):
        C.rename_cases(REF, spec)
