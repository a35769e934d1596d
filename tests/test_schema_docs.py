"""docs/case-files.md cannot drift from the schema (fem_blocks/specs.py).

* `[contact]`, `[[interfaces]]`, `[[stages]]` (with "Load protocol"), `[checks]`, `[output]`, `[materials.NAME]` and
  `[[reference]]`: the keys of the hand-written tables are
  exactly the schema's TOML keys (a key added to a dataclass without a doc row, or a doc row left for a removed
  key, fails), and where the doc's default column holds a literal it is the field's default;
* the interface-law parameter table is generated from `LAW_PARAMS` (scripts/schema_tables.py) and must be up to
  date.
"""
import ast
import dataclasses
import importlib.util
import os
import re

import pytest

from fem_blocks.specs import (ChecksSpec, ContactOptions, CyclicProtocol, InterfaceSpec, MaterialSpec, OutputSpec,
                              ReferenceSpec, StageSpec, schema_fields, toml_key)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "case-files.md")


def sections() -> dict:
    """'## heading' -> its text (up to the next '## ' heading)."""
    with open(DOC, encoding="utf-8") as f:
        text = f.read()
    parts = re.split(r"^## ", text, flags=re.M)
    return {p.split("\n", 1)[0]: p for p in parts[1:]}


def section(prefix: str) -> str:
    """The section whose heading is `prefix`, or else the one heading that starts with it."""
    secs = sections()
    hits = [secs[prefix]] if prefix in secs else [t for h, t in secs.items() if h.startswith(prefix)]
    assert len(hits) == 1, f"expected one section '## {prefix}...' in {DOC}, found {len(hits)}"
    return hits[0]


def rows(text: str) -> list:
    """Table rows as lists of cells (header and separator rows dropped)."""
    out = []
    for line in text.splitlines():
        if line.startswith("| `"):
            out.append([c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]])
    return out


def documented(text: str) -> dict:
    """Top-level key -> its row, from the first cell of each row: `a`, `b` or `[stages.KEY...]`."""
    out = {}
    for r in rows(text):
        for tok in re.findall(r"`([^`]+)`", r[0]):
            m = re.match(r"\[+\w+\.(\w+)", tok)
            out[m.group(1) if m else tok] = r
    return out


def schema_keys(cls) -> set:
    return {toml_key(f) for f in schema_fields(cls) if f.metadata["toml"]}


@pytest.mark.parametrize("cls, heads", [(ContactOptions, ["`[contact]`"]),
                                        (InterfaceSpec, ["`[[interfaces]]`"]),
                                        (StageSpec, ["`[[stages]]`", "Load protocol"]),
                                        (ChecksSpec, ["`[checks]`"]), (OutputSpec, ["`[output]`"]),
                                        (MaterialSpec, ["`[materials.NAME]`"]),
                                        (ReferenceSpec, ["`[[reference]]`"]),
                                        (CyclicProtocol, ["Cyclic displacement protocol"])])
def test_doc_tables_name_exactly_the_schema_keys(cls, heads):
    doc = {}
    for h in heads:
        doc.update(documented(section(h)))
    keys = schema_keys(cls)
    top = {k.split(".")[0] for k in keys}
    assert top - set(doc) == set(), f"{cls.__name__}: keys without a row in docs/case-files.md"
    assert set(doc) - top == set(), f"docs/case-files.md {heads}: rows for keys {cls.__name__} does not have"
    for k in keys:  # a key of a sub-table ([stages.stop_at_equilibrium] max_velocity) is named in its row
        if "." in k:
            head, sub = k.split(".", 1)
            assert f"`{sub}`" in " ".join(doc[head]), f"{k}: not named in the row of [stages.{head}]"


def _literal(cell: str):
    s = cell.strip().strip("`")
    if s in ("true", "false"):
        return s == "true"
    try:
        return ast.literal_eval(s)
    except (ValueError, SyntaxError):
        return dataclasses.MISSING


@pytest.mark.parametrize("cls, head", [(ContactOptions, "`[contact]`"), (InterfaceSpec, "`[[interfaces]]`"),
                                       (ChecksSpec, "`[checks]`"), (OutputSpec, "`[output]`")])
def test_doc_defaults_are_the_schema_defaults(cls, head):
    doc = documented(section(head))
    checked = 0
    for f in schema_fields(cls):
        if not f.metadata["toml"] or f.metadata["required"] or toml_key(f) not in doc:
            continue
        v = _literal(doc[toml_key(f)][1])
        if v is dataclasses.MISSING or f.name == "mu":  # mu: required in a case file (0.5 in the Python API)
            continue
        assert v == (list(f.default) if isinstance(f.default, tuple) else f.default), \
            f"{cls.__name__}.{f.name}: docs/case-files.md says {v!r}, the schema {f.default!r}"
        checked += 1
    assert checked >= 2


def test_law_parameter_table_is_generated_from_the_schema():
    spec = importlib.util.spec_from_file_location("schema_tables", os.path.join(ROOT, "scripts", "schema_tables.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    with open(DOC, encoding="utf-8") as f:
        doc = f.read()
    assert mod.render(doc) == doc, "docs/case-files.md: law parameter table out of date; run scripts/schema_tables.py"
    assert "`G_fc`" in mod.law_params_table() and "| `damage_viscosity` | s |" in mod.law_params_table()
