"""Generate the interface-law parameter table of docs/case-files.md from fem_blocks/specs.py (LAW_PARAMS).

    python scripts/schema_tables.py          # rewrite the table between the markers in docs/case-files.md
    python scripts/schema_tables.py --check  # exit 1 if the doc is out of date (tests/test_schema_docs.py)

The table sits between `<!-- schema:law_params -->` and `<!-- /schema:law_params -->`; the rest of the doc is
written by hand (tests/test_schema_docs.py checks that its key tables name exactly the schema's keys).
"""
from __future__ import annotations

import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "case-files.md")
BEGIN, END = "<!-- schema:law_params -->", "<!-- /schema:law_params -->"
# unit of each unit kind in the two unit systems of case files (case.UNIT_SYSTEMS, case.DERIVED)
UNITS = {"stiffness": "N/m³ (MPa/mm)", "stress": "Pa (MPa)", "length": "m (mm)", "energy": "J/m² (N/mm)",
         "viscosity": "J s/m² (N s/mm)", "time": "s", None: "—"}


def law_params_table() -> str:
    sys.path.insert(0, ROOT)
    from fem_blocks.specs import LAW_PARAMS, LAWS, REQUIRED
    rows = ["| key | unit (SI, mm-N-MPa) | laws: default (required: —) | range | meaning |", "|---|---|---|---|---|"]
    for k, p in LAW_PARAMS.items():
        laws = ", ".join(f"{law}: {'—' if p.laws[law] is REQUIRED else repr(p.laws[law]).replace(chr(39), chr(34))}"
                         for law in LAWS if law in p.laws)
        if p.choices is not None:
            rng = " \\| ".join(f'`"{c}"`' for c in p.choices)
        else:
            rng = ("> " if p.lo_open else "≥ ") + f"{p.lo:g}"
            over = {law: ("> " if r.get("lo_open", p.lo_open) else "≥ ") + f"{p.lo:g}" for law, r in p.per_law.items()}
            rng += "".join(f" ({law}: {v})" for law, v in over.items())
        rows.append(f"| `{k}` | {UNITS[p.unit]} | {laws} | {rng} | {p.doc} |")
    return "\n".join(rows)


def render(doc: str) -> str:
    a, b = doc.index(BEGIN) + len(BEGIN), doc.index(END)
    return doc[:a] + "\n" + law_params_table() + "\n" + doc[b:]


def main(argv) -> int:
    with open(DOC, encoding="utf-8") as f:
        doc = f.read()
    new = render(doc)
    if "--check" in argv:
        if new != doc:
            print(f"{DOC}: the law parameter table is out of date; run python scripts/schema_tables.py")
            return 1
        return 0
    if new != doc:
        with open(DOC, "w", encoding="utf-8") as f:
            f.write(new)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
