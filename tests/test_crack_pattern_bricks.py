"""crack_pattern.png on a split-brick wall (output/figures.brick_cracks, crack_pattern_data): the bricks whose crack
(the "crack" interface between their halves) is open by at least figures.BRICK_CRACK_WIDTH are the cracked ones,
shaded, their crack drawn apart from the joints, counted in the legend and in summary.json `cracked_bricks`.

A small split-brick wall (3 courses of 2 bricks, Frémond–Cangémi brick cracks) settled under gravity for two steps;
then, in a copy of the contact record, the crack of one brick is forced open by 0.2 mm (twice the threshold) and the
crack of another by 0.05 mm (half of it): the figure's data must name the first brick as cracked and no other (a
threshold compared the wrong way, a crack counted per contact instead of per brick, joints taken for brick cracks,
or the other brick's partial opening counted would each fail), draw exactly that brick's crack contacts as brick
cracks and none of the crack contacts among the joints, and say "1 of N" with N the number of split bricks of the
builder (its full bricks)."""
import dataclasses

import numpy as np
import pytest

from fem_blocks.case import load_case
from fem_blocks.expand import expand
from fem_blocks.laws import S_UN

from test_split_bricks import CASE

pytestmark = pytest.mark.dolfinx


def _settled(tmp_path):
    from fem_blocks.dynamics import Simulation
    from fem_blocks.model import build_model
    from fem_blocks.runner import _enter_stage
    p = tmp_path / "c.toml"
    p.write_text(CASE)
    case = expand(load_case(str(p)))
    model = build_model(case)
    st = case.stages[0]
    sim = Simulation(model.bodies, h=st.h, theta=st.theta, gravity=model.gravity, velocity_reset=st.velocity_reset,
                     contact=model.contact)
    _enter_stage(model, sim, case, 0, 0.0)
    for _ in range(2):
        sim.step()
    return case, model, sim


def test_the_brick_forced_open_is_the_only_cracked_one(tmp_path):
    from fem_blocks.output.figures import BRICK_CRACK_WIDTH, crack_pattern_data, write_crack_pattern
    from fem_blocks.runner import _cracked_bricks
    case, model, sim = _settled(tmp_path)
    rec = sim.last_contact
    full = sorted({b.parent for b in case.blocks if b.parent >= 0})
    names = model.names
    parent = {b.name: b.parent for b in case.blocks}
    cs = rec.cs
    pc = np.array([parent.get(names[i], -1) for i in cs.cand_body])
    pa = np.array([parent.get(names[i], -1) for i in cs.ant_body])
    crack = (pc >= 0) & (pc == pa)              # contacts between the two halves of one brick (the test's own rule)
    bricks_with_contacts = sorted(set(pc[crack]))
    assert len(full) >= 3 and len(bricks_with_contacts) >= 2
    k_open, k_part = bricks_with_contacts[0], bricks_with_contacts[-1]
    st = rec.state.copy()
    st[crack & (pc == k_open), S_UN] = 2 * BRICK_CRACK_WIDTH
    st[crack & (pc == k_part), S_UN] = 0.5 * BRICK_CRACK_WIDTH
    forced = dataclasses.replace(rec, state=st)

    d = crack_pattern_data(sim, forced, model.contact)
    b = d["bricks"]
    halves = sorted(b_.name for b_ in case.blocks if b_.parent == k_open)
    assert len(halves) == 2
    assert b["n_bricks"] == len(full) and b["n_cracked"] == 1
    assert [sorted(x) for x in b["cracked_names"]] == [halves]
    assert sorted(names[i] for i in b["cracked_bodies"]) == halves
    assert np.array_equal(b["crack"], crack)
    assert np.array_equal(b["open"], crack & (pc == k_open))
    assert len(d["crack_seg"]) == int((crack & (pc == k_open)).sum()) and len(d["seg"]) == int((~crack).sum())
    assert d["crack_label"].startswith(f"brick cracks: 1 of {len(full)} bricks cracked")
    assert _cracked_bricks(b)["cracked_bricks"]["count"] == 1
    assert _cracked_bricks(b)["cracked_bricks"]["threshold_mm"] == pytest.approx(1e3 * BRICK_CRACK_WIDTH)

    # as settled: no brick cracked; the figure is written with the same data
    d0 = write_crack_pattern(tmp_path / "crack_pattern.png", sim, rec, model.contact)
    assert d0["bricks"]["n_cracked"] == 0 and len(d0["crack_seg"]) == 0
    assert (tmp_path / "crack_pattern.png").stat().st_size > 1000


def test_walls_without_brick_cracks_have_no_brick_data(tmp_path):
    """No 'crack' interface (the unsplit wall): brick_cracks is None, the summary has no cracked_bricks."""
    from fem_blocks.output.figures import brick_cracks
    from fem_blocks.runner import _cracked_bricks
    case, model, sim = _settled(tmp_path)
    itfs = [dataclasses.replace(i, orientation="any") for i in model.contact.interfaces]

    class Unsplit:  # what brick_cracks reads of the contact step, with no crack interface
        interfaces, body_parent, body_names = itfs, model.contact.body_parent, model.contact.body_names

    assert brick_cracks(sim.last_contact, Unsplit) is None and _cracked_bricks(None) == {}
