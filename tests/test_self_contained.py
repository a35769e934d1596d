"""The repository cites nothing outside itself (issue #20, "self-contained docs").

Every text file of the project (code, tests, benchmarks, scripts, demos, meshes, docs, README, CI) is scanned for
references to files that live outside the repository: the method digest and stack notes that used to sit in
../shared (now docs/method.md and docs/stack-facts.md), absolute paths of a machine, and, in code that runs
outside the tests, hard-coded scratch directories. The one thing allowed beside the project is the FCLIB data,
../shared/data/fclib (CI lays shared/ there; tests/_paths.py). Catches e.g. a docstring citing the old digest
again, or a bench script defaulting to an absolute path.
"""
import os
import re

from _paths import ROOT

TEXT = (".py", ".md", ".toml", ".geo", ".txt", ".sh", ".cfg", ".ini", ".json", ".yml", ".yaml")
SCAN = ["fem_blocks", "tests", "bench", "scripts", "demos", "meshes", "postprocess", "docs", ".ci",
        "README.md", "Makefile", "pyproject.toml"]
CODE = ("fem_blocks", "bench", "scripts", "demos", "postprocess", ".ci")  # runs outside the test suite
# Each pattern is written so that it does not match itself in this file.
EVERYWHERE = [
    (r"\bDESIG" r"N\b", "cites the old method digest: cite docs/method.md §n"),
    (r"STACK-" r"FACTS", "cites the old stack notes: cite docs/stack-facts.md §n"),
    (r"\.\./shared/(?!data/fclib)", "a file beside the project: only ../shared/data/fclib (FCLIB data) is allowed"),
    (r"(?<![\w.~])/(?:wor" r"k|hom" r"e|roo" r"t|Use" r"rs)/", "an absolute path of one machine"),
]
IN_CODE = [(r"(?<![\w.~])/tm" r"p\b", "a hard-coded scratch directory: take it from the user or tempfile")]


def _files():
    for top in SCAN:
        path = os.path.join(ROOT, top)
        if os.path.isfile(path):
            yield top
            continue
        for d, dirs, files in os.walk(path):
            dirs[:] = sorted(x for x in dirs if x != "__pycache__")
            for f in sorted(files):
                if f.endswith(TEXT) or f in ("run", "Makefile"):
                    yield os.path.relpath(os.path.join(d, f), ROOT)


def test_no_reference_outside_the_repository():
    bad = []
    files = list(_files())
    assert len(files) > 100 and "fem_blocks/runner.py" in files and "docs/method.md" in files  # the scan sees the tree
    for rel in files:
        with open(os.path.join(ROOT, rel), encoding="utf-8", errors="replace") as fh:
            lines = fh.read().splitlines()
        rules = EVERYWHERE + (IN_CODE if rel.split(os.sep)[0] in CODE else [])
        for k, line in enumerate(lines, 1):
            for pat, why in rules:
                if re.search(pat, line):
                    bad.append(f"{rel}:{k}: {why}: {line.strip()[:100]}")
    assert not bad, "\n".join(bad)


def test_the_cited_docs_exist_with_their_sections():
    """docs/method.md keeps the section numbers §1-§7 that docstrings cite, docs/stack-facts.md §1-§4."""
    for name, n in (("method.md", 7), ("stack-facts.md", 4)):
        with open(os.path.join(ROOT, "docs", name), encoding="utf-8") as fh:
            heads = re.findall(r"^## (\d+)\. ", fh.read(), flags=re.M)
        assert heads == [str(k) for k in range(1, n + 1)], (name, heads)
    cited = set()
    for rel in _files():
        with open(os.path.join(ROOT, rel), encoding="utf-8", errors="replace") as fh:
            cited |= {(m.group(1), m.group(2)) for m in re.finditer(r"docs/(method|stack-facts)\.md §(\d+)", fh.read())}
    limit = {"method": 7, "stack-facts": 4}
    assert cited and all(1 <= int(s) <= limit[d] for d, s in cited), sorted(cited)
