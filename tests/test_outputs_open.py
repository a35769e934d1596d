"""Every file a run writes opens in a reader: each .vtu in meshio and in VTK's XML reader (2D and 3D runs, the
t = 0 contact frame with no contact point included), each .pvd as XML naming files that exist, history.csv,
summary.json. Issue: `contacts_000000.vtu` held no point and meshio raised IndexError on it."""
import json
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

from fem_blocks.case import parse_case
from fem_blocks.output.history import read_history
from fem_blocks.runner import run_case

from test_case3d import STACK
from test_output import _vtk_read
from test_run_contact import CASE as PRISM

pytestmark = pytest.mark.dolfinx


def _run(tmp_path, text, name):
    import tomllib
    data = tomllib.loads(text)
    for st in data["stages"]:
        st["duration"] = 3 * st["h"]  # three steps: the t = 0 frame (no contact yet) and contact frames
        st["output_every"] = 1
        st.pop("stop_at_equilibrium", None)
    out = tmp_path / name
    run_case(parse_case(data, str(tmp_path / f"{name}.toml")), str(out), progress=False)
    return out


@pytest.mark.parametrize("text, name", [(PRISM, "prism2d"), (STACK, "stack3d")], ids=["2d", "3d"])
def test_every_output_file_opens(tmp_path, text, name):
    out = _run(tmp_path, text, name)
    pv = out / "paraview"
    vtus = sorted(pv.glob("*.vtu"))
    assert any(f.name.startswith("contacts_") for f in vtus) and any(f.name.startswith("blocks_") for f in vtus)
    counts = {}
    for f in vtus:
        m = meshio.read(f)
        g = _vtk_read(f)
        assert g.GetNumberOfPoints() == len(m.points)
        counts[f.name] = len(m.points)
    assert counts["contacts_000000.vtu"] == 0  # the frame with no contact point is among those read
    assert max(v for k, v in counts.items() if k.startswith("contacts_")) > 0
    for pvd in pv.glob("*.pvd"):
        files = [d.get("file") for d in ET.parse(pvd).getroot().iter("DataSet")]
        assert files and all((pv / f).exists() for f in files)
    h = read_history(out / "history.csv")
    assert len(h["step"]) >= 3 and np.all(np.isfinite(h["time"]))
    json.loads((out / "summary.json").read_text())
