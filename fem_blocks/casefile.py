"""Case files as written: one TOML file, its bases (``extends``) and its named joint laws (``[laws.NAME]``),
composed into the one table of keys that `fem_blocks.case` validates. Stdlib only (+ errors).

Composition of a file F (docs/case-files.md, "Bases and named laws"):

* ``extends = "base.toml"`` or ``extends = ["a.toml", "b.toml"]`` (paths relative to F): the bases are composed
  first (recursively), in order, then F's own keys are merged on top. Merge of a value ``over`` onto ``base``:
  ``merge(base, over) = {k: merge(base[k], over[k]) if both are tables else over.get(k, base.get(k))}``: tables
  merge key-wise (recursively), anything else (numbers, strings, arrays, arrays of tables such as
  ``[[stages]]`` and ``[[interfaces]]``, inline tables replaced by a non-table) is replaced whole.
* ``unset = ["stages[1].drivers.beam.y", "laws.joint"]``: key paths (``.`` between keys, ``[i]`` for an
  element of an array) deleted from the composition of F's bases before F's own keys are merged; each must exist.
* A missing or unreadable base, a base naming itself through a chain (a -> b -> a, a -> a) and a malformed
  ``extends``/``unset`` are InputErrors naming the file and the key.

Named laws, resolved after the whole composition: a top-level ``[laws.NAME]`` table holds a joint-law block
(``law = KIND`` and that law's parameters). An ``[[interfaces]]`` entry with ``law = "NAME"`` takes every key of
``[laws.NAME]``; its own keys (other than ``law``) override them:
``interface = laws[NAME] | {k: v for k, v in interface.items() if k != "law"}``. A law NAME may not be a law kind,
a named law's ``law`` must be a kind, and (when the file has a ``[laws]`` table) an interface's ``law`` must be a
kind or a defined name. ``laws``, ``extends`` and ``unset`` do not reach `case.parse_case`.

Provenance: `read` returns the composed data and a `Source`, a ``str`` (the path of F, so every existing
``f"{source}: ..."`` message is unchanged) that also knows, per key path, which file (and which named law) the
value came from: ``Source.at("materials.brick.E")`` is ``"base/wall.toml (via wall_p121.toml)"`` when the value
was read from the base, F itself otherwise. `origin(source, key)` works on any source (a plain str: itself).
"""
from __future__ import annotations

import copy
import difflib
import os
import re
import tomllib

from .errors import InputError

EXTENDS, UNSET, LAWS = "extends", "unset", "laws"
KEYS = (EXTENDS, UNSET, LAWS)            # top-level keys consumed here, never seen by case.parse_case
LAW_IDENTITY_KEYS = ("name", "between", "candidate", "orientation")  # say which interface, not which law


class Source(str):
    """The path of the case file (a str) + where each composed value came from.

    `files`: the case file then every base read, in composition order (each once): what a run depends on.
    `origins`: key path -> (file, named law or ""), for every value that is not an (array) element's key."""

    files: tuple = ()
    origins: dict = {}

    def at(self, key: str) -> str:
        """The file label for key path `key` (its longest recorded prefix): the case file itself, or
        "FILE (laws.NAME; via CASE)" for a value read from a base file and/or a named law."""
        k = key
        while k:
            if k in self.origins:
                f, law = self.origins[k]
                notes = ([f"laws.{law}"] if law else []) + ([f"via {str(self)}"] if f != str(self) else [])
                return f"{f} ({'; '.join(notes)})" if notes else f
            k = _parent(k)
        return str(self)


def origin(source, key: str) -> str:
    """The file to name for key path `key` in a message: `Source.at`, or `source` itself for a plain str."""
    return source.at(key) if isinstance(source, Source) else str(source)


def origin_of_message(source, message: str) -> str:
    """`origin` of the key path a message starts with (``"interfaces[0].c_N = -1: ..."``)."""
    return origin(source, re.split(r"[\s:=]", str(message), maxsplit=1)[0])


def read(path, law_kinds, resolve: bool = True) -> tuple[dict, Source]:
    """Load case file `path`, follow its ``extends``, apply ``unset``, resolve named laws (`law_kinds`: the law
    kinds, e.g. laws.LAW_KEYS) -> (data for case.parse_case, Source). `resolve` False: the ``[laws]`` table is
    kept (a `[lab]` file's generated interfaces name its laws; fem_blocks.lab resolves them per specimen)."""
    src = os.fspath(path)
    origins: dict = {}
    files: list = []
    data = _compose(src, src, [], origins, files)
    source = _source(src, files, origins)
    if resolve:
        resolve_laws(data, source, law_kinds)
    return data, source


def compose(data: dict, src: str, law_kinds) -> tuple[dict, Source]:
    """The same for an already loaded top-level table `data` of file name `src` (bases relative to its folder)."""
    origins: dict = {}
    files = [src]
    data = _compose_loaded(copy.deepcopy(data), src, src, [os.path.realpath(src)], origins, files)
    source = _source(src, files, origins)
    resolve_laws(data, source, law_kinds)
    return data, source


def _source(src: str, files: list, origins: dict) -> Source:
    s = Source(src)
    s.files, s.origins = tuple(files), origins
    return s


def load_toml(path: str, named_by: str | None = None) -> dict:
    """tomllib.load with one-line InputErrors; `named_by`: the file whose ``extends`` names `path`."""
    where = f"{named_by}: {EXTENDS}: base file {path!r}" if named_by else f"{path}: case file"
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise InputError(f"{where} not found" + (" (paths are relative to the file that names them)"
                                                 if named_by else "")) from None
    except IsADirectoryError:
        raise InputError(f"{where}: expected a TOML case file, got a directory" if named_by else
                         f"{path}: expected a TOML case file, got a directory") from None
    except PermissionError:
        raise InputError(f"{where} not readable (permission denied)") from None
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{path}: invalid TOML: {e}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: invalid TOML: not UTF-8 text") from None


def _compose(path: str, top: str, chain: list, origins: dict, files: list, named_by: str | None = None) -> dict:
    real = os.path.realpath(path)
    if real in chain:
        names = [os.path.basename(p) for p in chain + [real]]
        raise InputError(f"{named_by}: {EXTENDS}: {os.path.basename(path)!r} extends itself through "
                         f"{' -> '.join(names)}; expected a chain of bases without cycles")
    data = load_toml(path, named_by)
    if path not in files:
        files.append(path)
    return _compose_loaded(data, path, top, chain + [real], origins, files)


def _compose_loaded(data: dict, path: str, top: str, chain: list, origins: dict, files: list) -> dict:
    _check_spelling(data, path)
    ext = data.pop(EXTENDS, None)
    unset = data.pop(UNSET, None)
    own: dict = {}
    _mark(data, "", path, own)
    if ext is None:
        if unset is not None:
            raise InputError(f"{path}: {UNSET}: needs {EXTENDS} (it deletes keys of the base files)")
        origins.update(own)
        return data
    if isinstance(ext, str):
        ext = [ext]
    if not (isinstance(ext, list) and ext and all(isinstance(x, str) and x for x in ext)):
        raise InputError(f"{path}: {EXTENDS}: expected a file name or a list of file names (relative to this "
                         f"file), got {ext!r}")
    out: dict = {}
    here = os.path.dirname(path)
    for name in ext:
        bo: dict = {}
        base = _compose(os.path.normpath(os.path.join(here, name)), top, chain, bo, files, named_by=path)
        _merge(out, base, "", origins, bo)
    if unset is not None:
        if not (isinstance(unset, list) and all(isinstance(x, str) for x in unset)):
            raise InputError(f"{path}: {UNSET}: expected a list of key paths, e.g. [\"stages[1].drivers.beam.y\"], "
                             f"got {unset!r}")
        for i, key in enumerate(unset):
            _delete(out, key, origins, f"{path}: {UNSET}[{i}] = {key!r}")
    _merge(out, data, "", origins, own)
    return out


def _check_spelling(data: dict, path: str):
    """A top-level key that looks like a misspelt `extends`, `unset` or `laws` (same letters up to case, or a
    difflib similarity >= 0.75) is an error here: case.parse_case would only call it unknown."""
    for k in data:
        if not isinstance(k, str) or k in KEYS:
            continue
        for good in KEYS:
            if k.lower() == good or difflib.SequenceMatcher(None, k.lower(), good).ratio() >= 0.75:
                raise InputError(f"{path}: {k}: unknown key {k!r} — did you mean {good!r}?")


def _join(path: str, k) -> str:
    return f"{path}[{k}]" if isinstance(k, int) else (f"{path}.{k}" if path else str(k))


def _parent(key: str) -> str:
    m = re.match(r"^(.*)(\[\d+\]|\.[^.\[\]]*)$", key)
    return m.group(1) if m else ""


def _under(k: str, p: str) -> bool:
    return k == p or k.startswith(p + ".") or k.startswith(p + "[")


def _mark(v, path: str, file: str, origins: dict):
    """Record `file` for every leaf and array of table `v` (key paths under `path`)."""
    if isinstance(v, dict):
        for k, x in v.items():
            _mark(x, _join(path, k), file, origins)
    else:
        origins[path] = (file, "")


def _take(origins: dict, src: dict, p: str):
    for k in [k for k in origins if _under(k, p)]:
        del origins[k]
    origins.update({k: v for k, v in src.items() if _under(k, p)})


def _merge(base: dict, over: dict, path: str, origins: dict, over_origins: dict):
    """merge(base, over) in place (see the module docstring); origins follow the values."""
    for k, v in over.items():
        p = _join(path, k)
        if isinstance(v, dict) and isinstance(base.get(k), dict):
            _merge(base[k], v, p, origins, over_origins)
        else:
            base[k] = v
            _take(origins, over_origins, p)


def _delete(data: dict, key: str, origins: dict, label: str):
    parts = re.findall(r"\[(\d+)\]|([^.\[\]]+)", key)
    if not parts or "".join(f"[{i}]" if i else f".{n}" for i, n in parts).lstrip(".") != key:
        raise InputError(f"{label}: expected a key path such as \"stages[1].drivers.beam.y\"")
    parent, path = data, ""
    steps = [int(i) if i else n for i, n in parts]
    for n, s in enumerate(steps):
        ok = (isinstance(parent, dict) and isinstance(s, str) and s in parent) or \
             (isinstance(parent, list) and isinstance(s, int) and s < len(parent))
        if not ok:
            raise InputError(f"{label}: no such key in the base files ({_join(path, s)} does not exist)")
        if n == len(steps) - 1:
            del parent[s]
            if isinstance(s, str):
                _take(origins, {}, _join(path, s))
            return
        parent, path = parent[s], _join(path, s)


def resolve_laws(data: dict, source: Source, law_kinds):
    """Replace ``law = NAME`` of each ``[[interfaces]]`` entry by the ``[laws.NAME]`` block (module docstring);
    remove ``[laws]``. Errors name the file the offending key came from."""
    laws = data.pop(LAWS, None)
    kinds = sorted(law_kinds)
    if laws is None:
        return
    if not isinstance(laws, dict):
        raise InputError(f"{origin(source, LAWS)}: {LAWS}: expected tables [laws.NAME] of law blocks, got "
                         f"{type(laws).__name__}")
    for name, block in laws.items():
        key = f"{LAWS}.{name}"
        if not isinstance(block, dict):
            raise InputError(f"{origin(source, key)}: {key}: expected a table (law = KIND and its parameters), "
                             f"got {block!r}")
        if name in law_kinds:
            raise InputError(f"{origin(source, key)}: {key}: the name {name!r} is a law kind; expected another "
                             f"name (law kinds: {kinds})")
        kind = block.get("law")
        if kind not in law_kinds:
            what = "missing" if "law" not in block else f"= {kind!r}"
            hint = " (a named law cannot refer to another)" if kind in laws else ""
            raise InputError(f"{origin(source, key + '.law')}: {key}.law: {what}; expected a law kind, one of "
                             f"{kinds}{hint}")
        for k in block:
            if k in LAW_IDENTITY_KEYS:
                raise InputError(f"{origin(source, key + '.' + k)}: {key}.{k}: a key of the interface, not of the "
                                 f"law; expected it in [[interfaces]]")
    itfs = data.get("interfaces")
    if not isinstance(itfs, list):
        return
    for i, itf in enumerate(itfs):
        if not isinstance(itf, dict):
            continue
        name = itf.get("law")
        if name in law_kinds or name is None or not isinstance(name, str):
            continue
        key = f"interfaces[{i}].law"
        if name not in laws:
            raise InputError(f"{origin(source, key)}: {key} = {name!r}: expected a law kind {kinds} or a "
                             f"[laws] name {sorted(laws)}")
        block = laws[name]
        itfs[i] = {**copy.deepcopy(block), **{k: v for k, v in itf.items() if k != "law"}, "law": block["law"]}
        for k in block:
            if k not in itf or k == "law":
                f, _ = source.origins.get(f"{LAWS}.{name}.{k}", (str(source), ""))
                source.origins[f"interfaces[{i}].{k}"] = (f, name)
