"""Reading YAML config files: one place for the checks every loader needs.

Each stage's loader (radar, worlds, reconstruction, detector, scenes, intrinsics) validates its
own fields; this module only turns a path into a top-level mapping, or raises an error that
names the file and says what is wrong with it; :func:`whole_number` and :func:`real_number`
check one scalar field of such a mapping (YAML reads ``[1]``, ``two``, ``2.5`` and ``true`` as
a list, a string, a float and a bool: none of them may pass as a count or be truncated).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import yaml

__all__ = ["read_yaml_mapping", "real_number", "whole_number"]


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
        doc = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise error(f"{path}: invalid YAML: {exc}") from None
    if doc is None:
        return {}
    if not isinstance(doc, dict):
        raise error(f"{path}: expected {expect} at the top level, got {type(doc).__name__}")
    return doc


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
        raise ValueError(f"{path}: {field}: must be a whole number, got {value!r}; "
                         f"write e.g. '{field}: {example}'")
    if minimum is not None and value < minimum:
        raise ValueError(f"{path}: {field}: must be >= {minimum}, got {value!r}")
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
        raise ValueError(f"{path}: {field}: must be a number{unit}, got {value!r}; "
                         f"write e.g. '{field}: {example}'")
    return float(value)
