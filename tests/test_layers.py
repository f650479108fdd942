"""The import graph's layering rule (run in ``make test``): no import cycles between modules and
no arrow that climbs up the layers, top-level and deferred imports alike.

Layers, lowest first (a module may import its own layer and the ones below):

  1 library   sim2radar.*  (except the four below): pure computation, no Prefect, no store
  2 storage   sim2radar.storage  (folder storage/)   the Parquet artifact store
  3 tasks     sim2radar.tasks    (folder tasks/)     Prefect tasks: keys, caching, store I/O
  4 flows     sim2radar.flows    (folder flows/)     Prefect flows
  5 cli       sim2radar.cli, benchmarks

The rule: a module imports only from its own layer or the ones below, and no import cycle
(docs/architecture.md, "Rooms and layers"; the top-level folders install as ``sim2radar.flows``
etc., README "Package layout"). The README's "Rooms" table lists every room (:func:`room`) with
its layer; :func:`test_the_readme_rooms_table_matches_the_layers` keeps the two in step.
``python tests/test_layers.py`` prints the graph's cycles and upward arrows.
"""

from __future__ import annotations

import ast
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: folder -> import name of the package it holds
FOLDERS = {"sim2radar": "sim2radar", "storage": "sim2radar.storage", "tasks": "sim2radar.tasks",
           "flows": "sim2radar.flows", "benchmarks": "benchmarks"}
LAYERS = {"sim2radar.storage": 2, "sim2radar.tasks": 3, "sim2radar.flows": 4,
          "sim2radar.cli": 5, "benchmarks": 5}


def layer(module: str) -> int:
    for prefix, n in LAYERS.items():
        if module == prefix or module.startswith(prefix + "."):
            return n
    return 1


def modules(root: Path = ROOT) -> dict[str, Path]:
    """Import name -> file of every module of the project."""
    found = {}
    for folder, package in FOLDERS.items():
        for f in sorted((root / folder).rglob("*.py")):
            rel = f.relative_to(root / folder).with_suffix("").parts
            name = ".".join((package, *rel)).removesuffix(".__init__")
            found[name] = f
    return found


def import_graph(mods: dict[str, Path]) -> dict[str, dict[str, int]]:
    """src -> {dst: line of the first import} between the project's modules."""

    def resolve(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    edges: dict[str, dict[str, int]] = defaultdict(dict)
    for src, f in mods.items():
        base = src if f.name == "__init__.py" else src.rpartition(".")[0]
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    b = base
                    for _ in range(node.level - 1):
                        b = b.rpartition(".")[0]
                    m = f"{b}.{node.module}" if node.module else b
                else:
                    m = node.module or ""
                targets = [f"{m}.{a.name}" for a in node.names] + [m]
            else:
                continue
            for t in targets:
                if t.split(".")[0] in ("sim2radar", "benchmarks"):
                    d = resolve(t)
                    if d and d != src and not src.startswith(d + "."):
                        edges[src].setdefault(d, node.lineno)
    return edges


def cycles(edges: dict[str, dict[str, int]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []
    nodes = set(edges) | {d for ds in edges.values() for d in ds}
    for start in sorted(nodes):
        if start in index:
            continue
        work = [(start, iter(sorted(edges.get(start, {}))))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on.add(start)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges.get(w, {})))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def upward(edges: dict[str, dict[str, int]], mods: dict[str, Path]) -> list[str]:
    return [f"{mods[s].relative_to(ROOT)}:{ln} ({s}, layer {layer(s)}) imports {d} "
            f"(layer {layer(d)})"
            for s, ds in sorted(edges.items()) for d, ln in sorted(ds.items())
            if layer(d) > layer(s)]


def test_the_graph_sees_every_layer():
    mods = modules()
    edges = import_graph(mods)
    assert {layer(m) for m in mods} == {1, 2, 3, 4, 5}
    # a sanity check that imports are followed: the flows import tasks, tasks import storage
    assert any(layer(s) == 4 and layer(d) == 3 for s, ds in edges.items() for d in ds)
    assert any(layer(s) == 3 and layer(d) == 2 for s, ds in edges.items() for d in ds)


def test_the_rule_catches_a_cycle_and_an_upward_arrow():
    edges = {"sim2radar.a": {"sim2radar.b": 1}, "sim2radar.b": {"sim2radar.a": 2},
             "sim2radar.storage.x": {"sim2radar.flows.y": 3}}
    assert cycles(edges) == [["sim2radar.a", "sim2radar.b"]]
    mods = {m: ROOT / "x.py" for m in ("sim2radar.storage.x", "sim2radar.flows.y")}
    assert len(upward(edges, mods)) == 1


def test_no_import_cycles():
    assert cycles(import_graph(modules())) == []


def test_no_import_climbs_up_the_layers():
    mods = modules()
    assert upward(import_graph(mods), mods) == []


def room(module: str, mods: dict[str, Path]) -> str:
    """The room of a module, as the README's "Rooms" table names it: a top-level folder
    (``storage/``, ``tasks/``, ``flows/``, ``benchmarks/``), a sub-package of the library
    (``sim2radar/radar/``, ``sim2radar/cli/``) or the library's shared modules
    (``sim2radar/*.py``)."""
    for folder, package in FOLDERS.items():
        if folder != "sim2radar" and (module == package or module.startswith(package + ".")):
            return f"{folder}/"
    parts = module.split(".")
    if len(parts) > 1 and mods.get(f"sim2radar.{parts[1]}", ROOT).name == "__init__.py":
        return f"sim2radar/{parts[1]}/"
    return "sim2radar/*.py"


def readme_rooms(readme: Path = ROOT / "README.md") -> dict[str, int]:
    """Room -> layer of the README's "Rooms" table (first two columns)."""
    text = readme.read_text(encoding="utf-8")
    assert "\n### Rooms\n" in text, f"{readme}: no '### Rooms' section"
    section = text.split("\n### Rooms\n", 1)[1].split("\n#", 1)[0]
    rows = [line.split("|") for line in section.splitlines() if line.startswith("| `")]
    return {cells[1].strip().strip("`"): int(cells[2].split()[0]) for cells in rows}


def test_the_readme_rooms_table_matches_the_layers():
    """The README's "Rooms" table names exactly the rooms of the import graph, each at the
    layer of all its modules: a new sub-package or a moved module cannot drift from it."""
    mods = modules()
    found: dict[str, set[int]] = defaultdict(set)
    for m in mods:
        found[room(m, mods)].add(layer(m))
    table = readme_rooms()
    assert sorted(table) == sorted(found), (
        f"README 'Rooms' table: missing {sorted(set(found) - set(table))}, "
        f"not a room {sorted(set(table) - set(found))}")
    wrong = {r: (table[r], sorted(found[r])) for r in table if found[r] != {table[r]}}
    assert not wrong, f"README 'Rooms' layer column (stated, actual): {wrong}"


def test_the_plain_path_does_not_import_prefect():
    """``--no-prefect`` runs use the jobs' drivers with a plain runner: they must not load
    Prefect (about 1 s of a cached rerun, BENCHMARKS.md); the Prefect runner lives in
    ``flows/``."""
    import subprocess

    code = ("import sys, sim2radar.tasks.dataset, sim2radar.tasks.common, "
            "sim2radar.tasks.worlds, sim2radar.tasks.steps, sim2radar.tasks.capture, "
            "sim2radar.tasks.radar, sim2radar.tasks.reconstruct, sim2radar.tasks.reference, "
            "sim2radar.tasks.runner, sim2radar.tasks.generate, sim2radar.tasks.sweep, "
            "sim2radar.cli._jobs; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'prefect')[:3])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]", out.stdout


#: The CLI modules that talk to Prefect itself (its server, its log handlers): every other
#: Prefect import belongs in flows/.
PREFECT_CLI_HELPERS = {"sim2radar/cli/_app.py", "sim2radar/cli/_prefect_app.py",
                       "sim2radar/cli/server.py"}


def test_prefect_is_imported_only_in_flows():
    """One answer to "where does a Prefect task go?": ``flows/``. The library, the store and
    the jobs' drivers (``tasks/``) never import Prefect; the CLI only in its server helpers."""
    import re

    pattern = re.compile(r"^\s*(from prefect\b|import prefect\b)", re.M)
    found = []
    for folder in ("tasks", "storage", "sim2radar"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel not in PREFECT_CLI_HELPERS and pattern.search(path.read_text()):
                found.append(rel)
    assert not found, f"Prefect imported outside flows/: {found}"


if __name__ == "__main__":
    mods = modules()
    edges = import_graph(mods)
    found, up = cycles(edges), upward(edges, mods)
    print(f"{len(mods)} modules, {sum(len(d) for d in edges.values())} import arrows")
    for c in found:
        print("cycle:", " <-> ".join(c))
    for line in up:
        print("upward:", line)
    print(f"{len(found)} cycle(s), {len(up)} upward arrow(s)")
    sys.exit(1 if found or up else 0)
