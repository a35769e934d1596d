"""The import graph of fem_blocks (issue #20, "one fact, one home"): data flows one way.

Every module's imports are read with `ast` — at module level and inside functions alike (a deferred import is
still a dependency) — and resolved to fem_blocks modules. Two rules:

* no import cycle (a cycle means two modules each need the other: one of them holds a fact of the other's);
* the input layer (case files: case.py, specs.py, casefile.py, errors.py) imports nothing of the engine —
  builders*, bodies, meshing, fem_backend, dynamics, runner, contact.*, solver.*, output.* — so a case can be
  parsed and validated without building anything, and the engine depends on the schema, not the reverse.
"""
import ast
import os

PKG = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "fem_blocks")

INPUT_LAYER = ("fem_blocks.case", "fem_blocks.specs", "fem_blocks.casefile", "fem_blocks.errors")
ENGINE = ("fem_blocks.builders", "fem_blocks.bodies", "fem_blocks.meshing", "fem_blocks.fem_backend",
          "fem_blocks.dynamics", "fem_blocks.runner", "fem_blocks.contact", "fem_blocks.solver", "fem_blocks.output")


def modules() -> dict:
    """fem_blocks module name -> file path (packages as NAME for their __init__.py)."""
    out = {}
    for d, _, files in os.walk(PKG):
        for f in files:
            if not f.endswith(".py"):
                continue
            rel = os.path.relpath(os.path.join(d, f), os.path.dirname(PKG))[:-3].split(os.sep)
            if rel[-1] == "__init__":
                rel = rel[:-1]
            out[".".join(rel)] = os.path.join(d, f)
    return out


def imports_of(name: str, path: str, known: set) -> set:
    """The fem_blocks modules that module `name` imports anywhere in its file (absolute or relative imports;
    `from PKG import x` counts x when x is a module of PKG, else PKG)."""
    is_pkg = path.endswith("__init__.py")
    package = name if is_pkg else name.rpartition(".")[0]
    out = set()
    with open(path, encoding="utf-8") as fh:
        tree = ast.parse(fh.read(), path)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name == "fem_blocks" or a.name.startswith("fem_blocks."):
                    out.add(a.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if not (mod == "fem_blocks" or mod.startswith("fem_blocks.")):
                continue
            for a in node.names:
                sub = f"{mod}.{a.name}"
                out.add(sub if sub in known else mod)
    out.discard(name)
    return {m for m in out if m in known}


def graph() -> dict:
    mods = modules()
    known = set(mods)
    return {m: imports_of(m, p, known) for m, p in mods.items()}


def cycles(g: dict) -> list:
    """The strongly connected components of more than one module (Tarjan), each sorted; and self-loops."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(g[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))
    for v in sorted(g):
        if v not in index:
            visit(v)
    return sorted(out)


def _in(mod: str, prefixes) -> bool:
    return any(mod == p or mod.startswith(p + ".") or (p == "fem_blocks.builders" and mod.startswith(p))
               for p in prefixes)


def test_the_reader_sees_deferred_and_relative_imports(tmp_path):
    """The parser itself: a relative import inside a function, `from . import module`, `from .. import x`."""
    pkg = tmp_path / "fem_blocks"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from .b import thing\n")
    (pkg / "b.py").write_text("from . import a\nimport os\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "c.py").write_text("from .. import b\nfrom ..a import f\nfrom . import d\n")
    (pkg / "sub" / "d.py").write_text("")
    known = {"fem_blocks", "fem_blocks.a", "fem_blocks.b", "fem_blocks.sub", "fem_blocks.sub.c", "fem_blocks.sub.d"}
    assert imports_of("fem_blocks.a", str(pkg / "a.py"), known) == {"fem_blocks.b"}
    assert imports_of("fem_blocks.b", str(pkg / "b.py"), known) == {"fem_blocks.a"}
    assert imports_of("fem_blocks.sub.c", str(pkg / "sub" / "c.py"), known) == {
        "fem_blocks.a", "fem_blocks.b", "fem_blocks.sub.d"}
    g = {m: set() for m in known}
    g.update({"fem_blocks.a": {"fem_blocks.b"}, "fem_blocks.b": {"fem_blocks.a"}})
    assert cycles(g) == [["fem_blocks.a", "fem_blocks.b"]]


def test_no_import_cycle():
    found = cycles(graph())
    assert not found, f"import cycles: {found}"


def test_input_layer_imports_no_engine_module():
    g = graph()
    bad = sorted((m, d) for m in g if _in(m, INPUT_LAYER) for d in g[m] if _in(d, ENGINE))
    assert not bad, f"input-layer modules importing engine modules: {bad}"


def test_schema_is_imported_by_the_engine_not_copied():
    """The engine's spec classes are the schema's: contact.step takes InterfaceSpec and ContactOptions from specs."""
    g = graph()
    assert "fem_blocks.specs" in g["fem_blocks.contact.step"]
    assert g["fem_blocks.specs"] <= {"fem_blocks.errors"}, g["fem_blocks.specs"]
