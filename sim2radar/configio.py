"""Reading YAML config files: one place for the checks every loader needs.

Each stage's loader (radar, worlds, reconstruction, detector, scenes, intrinsics) validates its
own fields; this module only turns a path into a top-level mapping, or raises an error that
names the file and says what is wrong with it; :func:`whole_number` and :func:`real_number`
check one scalar field of such a mapping (YAML reads ``[1]``, ``two``, ``2.5`` and ``true`` as
a list, a string, a float and a bool: none of them may pass as a count or be truncated).

:func:`config_path` turns a bundled config's *name* (``demo``, ``production``, ``small``) into
its file. The bundled configs are the package data ``sim2radar.configs`` (the ``configs/``
folder of the checkout, installed under that name) and are found through
:mod:`importlib.resources`, never through the checkout's layout, so a name works the same from
a clone, an editable install and a wheel.
"""

from __future__ import annotations

import importlib.resources
import math
import reprlib
from pathlib import Path
from typing import Any

import yaml

__all__ = ["CONFIG_KINDS", "DEFAULT_RADAR", "bundled_configs", "config_path", "looks_like_path",
           "read_yaml_mapping", "real_number",
           "whole_number"]

#: The radar preset (``sim2radar/radar/presets/<name>.yaml``) every command and function uses
#: when no radar is named: TI's 4-chip cascade imaging radar (MMWCAS-RF-EVM), the paper's sensor.
DEFAULT_RADAR = "ti-mmwcas"
#: folders of ``sim2radar.configs``: the kinds of config a command loads by name
CONFIG_KINDS = ("detect", "evaluation", "experiment", "generate", "reconstruct", "worlds")


def _bundled_dir(kind: str) -> Path:
    if kind not in CONFIG_KINDS:
        raise ValueError(f"unknown config kind {kind!r}; known: {list(CONFIG_KINDS)}")
    folder = importlib.resources.files("sim2radar.configs") / kind
    # installed packages are folders on disk (a wheel unpacks, an editable install points at the
    # checkout); a zipped install would need importlib.resources.as_file, which nothing here uses
    return Path(str(folder))


def bundled_configs(kind: str) -> list[str]:
    """Names (file stems) of the bundled configs of ``kind``, e.g. ``["demo", "paper", ...]``."""
    folder = _bundled_dir(kind)
    return sorted(p.stem for p in folder.glob("*.yaml")) if folder.is_dir() else []


def looks_like_path(value: str | Path) -> bool:
    """True for text with a folder separator or a YAML suffix, or naming a file that exists;
    False for a bare name such as ``demo`` (also as a :class:`~pathlib.Path`, as command-line
    options arrive)."""
    text = str(value)
    return text.endswith((".yaml", ".yml")) or "/" in text or "\\" in text \
        or Path(text).exists()


def config_path(name_or_path: str | Path, kind: str, *, what: str = "config") -> Path:
    """The file of a config given as a path (returned as it is) or as the name of a bundled
    config of ``kind`` (``config_path("demo", "experiment")``).

    Raises
    ------
    FileNotFoundError — a name with no bundled config; the message lists the bundled ones.
    """
    if looks_like_path(name_or_path):
        return Path(name_or_path)
    path = _bundled_dir(kind) / f"{name_or_path}.yaml"
    if not path.is_file():
        raise FileNotFoundError(f"no bundled {what} {str(name_or_path)!r}; bundled: "
                                f"{bundled_configs(kind)} (or pass a YAML path)")
    return path


#: The most values (scalars, lists, mappings) a YAML document may hold once its aliases
#: (``*name`` of an ``&name`` anchor) are expanded: a 1 KB "billion laughs" document of nested
#: aliases expands to ~10^9 and took 3-4 GB while error messages were built.
MAX_YAML_VALUES = 200_000
#: The largest YAML file read [bytes] (configs and scene files are kilobytes).
MAX_YAML_BYTES = 16 * 1024 * 1024


class YamlTooLargeError(yaml.YAMLError):
    """A YAML document over :data:`MAX_YAML_BYTES` or whose aliases expand past
    :data:`MAX_YAML_VALUES` values (a ``yaml.YAMLError``: callers report it as invalid YAML,
    naming the file)."""


def _expanded_values(doc: Any, limit: int) -> int:
    """How many values ``doc`` holds with every alias expanded (shared lists and mappings
    counted once per reference), stopping early past ``limit``; computed once per distinct
    object, so a bomb costs a few microseconds, not its expansion."""
    memo: dict[int, int] = {}

    def size(x: Any) -> int:
        if not isinstance(x, list | dict):
            return 1
        known = memo.get(id(x))
        if known is not None:
            return known
        memo[id(x)] = limit + 1  # a cycle (a self-referencing anchor) counts as too large
        items = list(x.keys()) + list(x.values()) if isinstance(x, dict) else x
        total = 1
        for item in items:
            total += size(item)
            if total > limit:
                break
        memo[id(x)] = total
        return total

    try:
        return size(doc)
    except RecursionError:
        return limit + 1


def load_yaml(text: str | bytes) -> Any:
    """``yaml.safe_load`` with limits checked before anything uses the document: at most
    :data:`MAX_YAML_BYTES` of text and :data:`MAX_YAML_VALUES` values once aliases are
    expanded (:class:`YamlTooLargeError`, a ``yaml.YAMLError``, otherwise)."""
    if len(text) > MAX_YAML_BYTES:
        raise YamlTooLargeError(f"the file has {len(text)} bytes, more than the "
                                f"{MAX_YAML_BYTES} a YAML config or scene file may have")
    doc = yaml.safe_load(text)
    if _expanded_values(doc, MAX_YAML_VALUES) > MAX_YAML_VALUES:
        raise YamlTooLargeError(
            f"its aliases (*name of an &name anchor) expand to more than {MAX_YAML_VALUES} "
            "values (a 'billion laughs' document?) or refer to themselves; write the values "
            "out instead of nesting aliases")
    return doc


def read_yaml_mapping(
    path: str | Path,
    *,
    what: str = "config file",
    expect: str = "a mapping",
    error: type[Exception] = ValueError,
    missing_error: type[Exception] | None = None,
) -> dict[str, Any]:
    """Read a YAML file whose top level must be a mapping (an empty file reads as ``{}``).

    Parameters
    ----------
    path : the YAML file.
    what : how to call the file in the "not found" message, e.g. ``"scene file"``.
    expect : what the top level should be, for the message, e.g. ``"a mapping with 'meshes'"``.
    error : exception type raised for invalid YAML or a non-mapping top level.
    missing_error : exception type for a missing file (default: ``error``).
    """
    path = Path(path)
    if not path.is_file():
        raise (missing_error or error)(f"{path}: {what} not found")
    try:
        doc = load_yaml(path.read_text())
    except yaml.YAMLError as exc:
        raise error(f"{path}: invalid YAML: {short_text(exc)}") from None
    if doc is None:
        return {}
    if not isinstance(doc, dict):
        raise error(f"{path}: expected {expect} at the top level, got {type(doc).__name__}")
    return doc


def short_text(value: Any, limit: int = 200) -> str:
    """``str(value)`` cut to ``limit`` characters (error messages quote user values, which can
    be huge)."""
    text = str(value)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def short_repr(value: Any, limit: int = 80) -> str:
    """``repr(value)`` of a user value for an error message, cut to ``limit`` characters; a
    large list or mapping is described by its type and length, never rendered whole."""
    if isinstance(value, list | tuple | dict | set) and len(value) > 20:
        return f"<a {type(value).__name__} of {len(value)} items>"
    text = reprlib.repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def whole_number(value: Any, path: str | Path, field: str, *, minimum: int | None = None,
                 example: int | None = None) -> int:
    """``value`` of ``field`` in the file ``path`` as an int: an integer, or a float with no
    fractional part (``4.0``).

    Raises
    ------
    ValueError ``"<path>: <field>: must be a whole number, got <value>; write e.g. '<field>: N'"``
    for anything else (a list, a word, ``2.5``, ``true``), or below ``minimum``.
    """
    ok = isinstance(value, int) or (isinstance(value, float) and value.is_integer())
    if isinstance(value, bool) or not ok:
        example = example if example is not None else max(minimum or 0, 1)
        raise ValueError(f"{path}: {field}: must be a whole number, got {short_repr(value)}; "
                         f"write e.g. '{field}: {example}'")
    if minimum is not None and value < minimum:
        raise ValueError(f"{path}: {field}: must be >= {minimum}, got {short_repr(value)}")
    return int(value)


def real_number(value: Any, path: str | Path, field: str, *, unit: str = "",
                example: float = 1.0) -> float:
    """``value`` of ``field`` in the file ``path`` as a finite float (an int or a float).

    Raises
    ------
    ValueError ``"<path>: <field>: must be a number [unit], got <value>; write e.g. ..."`` for a
    list, a string, a bool, NaN or inf.
    """
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    if not ok or not math.isfinite(value):
        unit = f" [{unit}]" if unit else ""
        raise ValueError(f"{path}: {field}: must be a number{unit}, got {short_repr(value)}; "
                         f"write e.g. '{field}: {example}'")
    return float(value)
