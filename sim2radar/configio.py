"""Reading YAML config files: one place for the checks every loader needs.

Each stage's loader (radar, worlds, reconstruction, detector, scenes, intrinsics) validates its
own fields; this module only turns a path into a top-level mapping, or raises an error that
names the file and says what is wrong with it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

__all__ = ["read_yaml_mapping"]


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
