"""The repository stands alone (issue #32): no document cites a file that is not in it.

A newcomer who clones the repository has nothing beside it, so every file a ``*.md`` page or a
docstring/comment of a ``*.py`` file cites must exist in the checkout. The map of the code is
``docs/architecture.md``; the paper is cited by its arXiv id (2602.13314), never by a path.

What counts as a citation (and nothing else, so that paths a command *writes* at run time, such
as ``out/store``, are never flagged):

* a Markdown link target, ``[text](target)``, holding a ``.`` or a ``/`` and not a URL, an
  e-mail or an ``#anchor``;
* a backticked token (``path`` or ````path````) with a ``/`` that ends in ``.md``, ``.py``,
  ``.yaml``, ``.yml``, ``.tex`` or ``.pdf``;
* a path or file name, backticked or bare, that ends in a document extension (``.md``,
  ``.tex``, ``.pdf``), such as a design note or the paper's source; a folder-less ``x.py`` or
  ``x.yaml`` is not read (most are files a run writes: ``radar.yaml``, ``scene.yaml``);
* any mention of the workspace's sibling folder (``..`` then ``/shared``), which a clone lacks.

Tokens holding a placeholder (``<run>``, ``{name}``, ``*``, ``$VAR``, ``...``) name a family of
run-time files and are skipped, and so are what a run writes: paths git ignores (``out/...``)
and document names the code itself writes (a string literal such as a sweep's ``"results.md"``).
A cited path resolves if it exists relative to the citing file's folder, to the repository
root, or to the library folder ``sim2radar/`` (the docs write ``radar/returns.py`` for
``sim2radar/radar/returns.py``); an installed name (``sim2radar/flows/...``) resolves through
``pyproject.toml``'s ``package-dir`` to its folder (``flows/...``). A folder-less document name
resolves if a file of that name is anywhere in the repository. Absolute and home paths never
resolve. Files of other projects, cited by their path there (OpenPCDet's ``pcdet/...``), are
listed in ``EXTERNAL``.

In ``*.py`` files only comments and docstrings are read (string literals in code are paths the
program uses, not citations); in the Makefile, ``*.yaml`` and ``*.toml`` files, the comments.
``python tests/test_docs_links.py`` prints every offender.
"""

from __future__ import annotations

import ast
import functools
import io
import re
import subprocess
import sys
import tokenize
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: folders whose ``*.py`` files are read (every ``*.md`` of the repository is read)
PY_FOLDERS = ("sim2radar", "flows", "tasks", "storage", "benchmarks", "scripts", "tests",
              "configs")
#: folders of the program, whose string literals name the files it writes
WRITERS = ("sim2radar", "flows", "tasks", "storage", "benchmarks", "scripts")
#: files besides the Makefile whose ``#`` comments are read
COMMENTED = (".yaml", ".yml", ".toml")
#: extensions a backticked path must end in to count as a citation
CITED = (".md", ".py", ".yaml", ".yml", ".tex", ".pdf")
#: extensions a folder-less file name must end in to count as a citation
DOCUMENTS = (".md", ".tex", ".pdf")
#: top-level folders a run writes into (.gitignore), for when git cannot say what it ignores
OUTPUTS = ("out/", "store/", "runs/", "mlruns/", "build/", "dist/", "data/")
#: paths in other projects, cited by their place there (prefix -> project)
EXTERNAL = {
    "pcdet/": "OpenPCDet",
    "tools/cfgs/": "OpenPCDet",
    "docs/CUSTOM_DATASET_TUTORIAL.md": "OpenPCDet",
    "kitti_object_eval_python/": "OpenPCDet's port of the KITTI devkit",
    "docs/onnx.md": "MoGe",
    "tools/onnx_exporter/": "X-AnyLabeling",
}

_LINK = re.compile(r"!?\[[^\]\n]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_TICKED = re.compile(r"``([^`\n]+)``|`([^`\n]+)`")
_BARE = re.compile(r"(?<![\w./`-])((?:[\w.-]+/)*[\w-][\w.-]*\.(?:md|tex|pdf))(?![\w/-])")
_SHARED = re.compile(r"\.\./shared\b")
_PLACEHOLDER = re.compile(r"[<>{}*$]|\.\.\.|\s")
_SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")


def repo_files(root: Path = ROOT) -> list[Path]:
    """The repository's files: tracked and untracked-but-not-ignored (``git ls-files``), or a
    walk that skips hidden, cache and output folders when git cannot list them."""
    try:
        out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others",
                              "--exclude-standard"], cwd=root, capture_output=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        return sorted(p for p in root.rglob("*") if p.is_file()
                      and not p.relative_to(root).as_posix().startswith(OUTPUTS)
                      and not any(part.startswith(".") or part == "__pycache__"
                                  or part.endswith(".egg-info")
                                  for part in p.relative_to(root).parts[:-1]))
    names = [n for n in out.stdout.decode().split("\0") if n]
    return sorted(root / n for n in names if (root / n).is_file())


def documents(files: list[Path], root: Path = ROOT) -> list[Path]:
    """The files whose words are checked: every ``*.md``, the ``*.py`` of the code folders and
    the comments of the Makefile and of every ``*.yaml``/``*.toml``."""
    return [f for f in files if f.suffix in (".md", *COMMENTED) or f.name == "Makefile"
            or (f.suffix == ".py" and f.relative_to(root).parts[0] in PY_FOLDERS)]


@functools.cache
def _tree(path: Path) -> ast.Module:
    """A ``*.py`` file's syntax tree (read once for ``prose`` and ``written_names``)."""
    return ast.parse(path.read_text(encoding="utf-8"), str(path))


def _statements(node: ast.AST):
    """``node`` and every statement below it: where docstrings can be (a definition is always
    a statement, so no expression is walked; a tenth of ``ast.walk``'s nodes)."""
    yield node
    for _, value in ast.iter_fields(node):
        if isinstance(value, list):
            for child in value:
                if isinstance(child, ast.stmt | ast.excepthandler | ast.match_case):
                    yield from _statements(child)


def prose(path: Path) -> list[tuple[int, str]]:
    """(line, text) of what a file says in words: all of a ``*.md``; the comments and
    docstrings of a ``*.py``; the ``#`` comments of the Makefile, a ``*.yaml`` or ``*.toml``."""
    text = path.read_text(encoding="utf-8")
    if path.suffix in COMMENTED or path.name == "Makefile":
        return [(n, m.group(1)) for n, line in enumerate(text.splitlines(), start=1)
                if (m := re.search(r"(?:^|[\s@])(#.*)", line))]
    if path.suffix != ".py":
        return list(enumerate(text.splitlines(), start=1))
    lines = [(tok.start[0], tok.string)
             for tok in tokenize.generate_tokens(io.StringIO(text).readline)
             if tok.type == tokenize.COMMENT]
    source = text.splitlines()
    for node in _statements(_tree(path)):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            doc = node.body[0] if node.body else None
            if (isinstance(doc, ast.Expr) and isinstance(doc.value, ast.Constant)
                    and isinstance(doc.value.value, str)):
                lines += [(n, source[n - 1])
                          for n in range(doc.value.lineno, doc.value.end_lineno + 1)]
    return sorted(lines)


def citations(line: str) -> list[str]:
    """The file paths one line of prose cites (see the module docstring)."""
    found = [m.group(1) for m in _LINK.finditer(line) if re.search(r"[./]", m.group(1))]
    rest = _LINK.sub(" ", line)
    for m in _TICKED.finditer(rest):
        token = (m.group(1) or m.group(2)).strip()
        if (token.endswith(CITED) and not Path(token).name.startswith(".")
                and ("/" in token or token.endswith(DOCUMENTS))):
            found.append(token)
    found += [m.group(1) for m in _BARE.finditer(_TICKED.sub(" ", rest))]
    if _SHARED.search(line) and not any(_SHARED.search(f) for f in found):
        found.append(_SHARED.search(line).group(0))
    return found


@functools.cache
def package_dirs(root: Path = ROOT) -> dict[str, str]:
    """Installed path -> folder in the repository (``sim2radar/flows/`` -> ``flows/``), from
    ``pyproject.toml``'s ``[tool.setuptools.package-dir]`` (none without one)."""
    pyproject = root / "pyproject.toml"
    if not pyproject.is_file():
        return {}
    setup = tomllib.loads(pyproject.read_text()).get("tool", {}).get("setuptools", {})
    return {name.replace(".", "/") + "/": folder.rstrip("/") + "/"
            for name, folder in setup.get("package-dir", {}).items()}


def resolves(target: str, citing: Path, names: set[str], root: Path = ROOT) -> bool:
    """Whether a cited path names a file or folder of the repository (True for what is not a
    repository path: URLs, anchors, placeholders, other projects' files)."""
    if _SHARED.search(target):
        return False
    path = target.split("#", 1)[0].split("?", 1)[0]
    if not path or _SCHEME.match(path) or _PLACEHOLDER.search(path):
        return True
    if path.startswith(("/", "~")):
        return False
    if path.startswith(tuple(EXTERNAL)):
        return True
    if "/" not in path:
        return path in names
    for installed, folder in package_dirs(root).items():
        if path.startswith(installed):
            path = folder + path.removeprefix(installed)
    for base in (citing.parent, root, root / "sim2radar"):
        candidate = (base / path).resolve()
        if candidate.is_relative_to(root.resolve()) and candidate.exists():
            return True
    return False


def ignored(paths: list[str], root: Path = ROOT) -> set[str]:
    """The paths git ignores (what a run writes: ``out/...``); without git, those under
    ``OUTPUTS``."""
    try:
        out = subprocess.run(["git", "check-ignore", "--no-index", "--stdin"], cwd=root,
                             input="\n".join(paths), capture_output=True, text=True)
    except OSError:
        out = None
    if out is None or out.returncode > 1:  # 0: some ignored, 1: none, 128: not a repository
        return {p for p in paths if p.startswith(OUTPUTS)}
    return set(out.stdout.splitlines())


def written_names(files: list[Path], root: Path = ROOT) -> set[str]:
    """Document names the code writes: string literals of the program's ``*.py`` files (not
    the tests') that are a bare file name with a document extension (``"results.md"``)."""
    names = set()
    for f in files:
        if f.suffix == ".py" and f.relative_to(root).parts[0] in WRITERS:
            for node in ast.walk(_tree(f)):
                if (isinstance(node, ast.Constant) and isinstance(node.value, str)
                        and re.fullmatch(r"[\w-][\w.-]*\.(?:md|tex|pdf)", node.value)):
                    names.add(node.value)
    return names


def offenders(root: Path = ROOT) -> list[str]:
    """``file:line: target`` for every citation that does not resolve inside the repository."""
    files = repo_files(root)
    names = {f.name for f in files} | written_names(files, root)
    bad = [(f"{f.relative_to(root)}:{n}", target) for f in documents(files, root)
           for n, line in prose(f) for target in citations(line)
           if not resolves(target, f, names, root)]
    skip = ignored(sorted({t for _, t in bad if not t.startswith(("/", "~", "."))}), root)
    return [f"{where}: {target}" for where, target in bad if target not in skip]


def test_a_citation_is_found_and_checked():
    """The rule on made-up lines: links, backticked paths and document names are citations;
    run-time outputs, placeholders, URLs and other projects' files are not."""
    assert citations("see [the map](docs/architecture.md#layout) and `radar/returns.py`") == [
        "docs/architecture.md#layout", "radar/returns.py"]
    assert citations("read DESIGN.md and ``paper/main.tex``") == ["paper/main.tex", "DESIGN.md"]
    assert citations("as in ../shared/paper (`out/store`, `radar.yaml`, A[i](u_a))") == [
        "../shared"]
    here = ROOT / "tests" / "test_docs_links.py"
    names = {"design.md"}
    assert resolves("../docs/radar_model.md", here, names)          # from the citing file
    assert resolves("docs/radar_model.md", here, names)             # from the root
    assert resolves("radar/returns.py", here, names)                # from sim2radar/
    assert resolves("sim2radar/flows/deployments.yaml", here, names)  # installed name
    assert resolves("<run>/results.md", here, names)
    assert resolves("https://arxiv.org/abs/2602.13314", here, names)
    assert resolves("pcdet/utils/loss_utils.py", here, names)
    assert not resolves("DESIGN.md", here, names)
    assert not resolves("../shared/DESIGN.md", here, names)
    assert not resolves("docs/no_such_page.md", here, names)
    assert not resolves("/elsewhere/paper.pdf", here, names)


def test_offenders_are_listed_with_file_and_line(tmp_path):
    """A made-up checkout (no git: the folder walk): every broken citation of a page, a
    docstring and a comment is reported as ``file:line: target``; code strings are not read."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "map.md").write_text("# Map\n")
    (tmp_path / "README.md").write_text(
        "See [the map](docs/map.md) and [the design](DESIGN.md).\n"
        "Outputs: `out/sweeps/demo/results.md`, `<run>/config.yaml`.\n"
        "The paper: ../shared/paper/ (arXiv 2602.13314).\n")
    (tmp_path / "tasks").mkdir()
    (tmp_path / "tasks" / "step.py").write_text(
        '"""A step (``docs/map.md``; ``docs/gone.md``)."""\n'
        "PATH = 'docs/also_gone.md'  # as in `tasks/missing.py`\n")
    assert offenders(tmp_path) == [
        "README.md:1: DESIGN.md",
        "README.md:3: ../shared",
        "tasks/step.py:1: docs/gone.md",
        "tasks/step.py:2: tasks/missing.py",
    ]


def test_every_cited_file_is_in_the_repository():
    bad = offenders()
    assert not bad, "cited files that are not in the repository:\n" + "\n".join(bad)


if __name__ == "__main__":
    bad = offenders()
    print("\n".join(bad))
    print(f"{len(bad)} citation(s) of files that are not in the repository")
    sys.exit(1 if bad else 0)
