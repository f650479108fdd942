"""Atomic file writes for the library's own outputs (dataset exports, reports, run records).

A file is written under a temporary name in its folder and renamed over the target, so a
killed process leaves the old file or the new one, never half of one (POSIX rename within one
file system). The Parquet artifact store publishes the same way (:mod:`storage.store`).
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path
from typing import Any

__all__ = ["atomic_write", "write_json", "abandoned_temp_files"]

_TEMP = re.compile(r"^\..+\.tmp(\d+)$")


def atomic_write(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (the parent folder must exist); returns the path."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_bytes(data)
    os.replace(tmp, path)
    return path


def abandoned_temp_files(folder: str | os.PathLike) -> list[Path]:
    """Temporary files of :func:`atomic_write` in ``folder`` whose writing process is gone (a
    killed run's leftovers, ``.<name>.tmp<pid>``); a live process's file is not listed."""
    out = []
    for p in sorted(Path(folder).glob(".*.tmp*")):
        m = _TEMP.match(p.name)
        if m is None or int(m.group(1)) == os.getpid():
            continue
        try:
            os.kill(int(m.group(1)), 0)
        except ProcessLookupError:
            out.append(p)
        except PermissionError:  # another user's live process
            continue
    return out


def write_json(path: str | os.PathLike, doc: Any, *, sort_keys: bool = False) -> Path:
    """Write ``doc`` as indented JSON atomically, creating the parent folder; values JSON cannot
    hold are written as their ``str``. Returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(doc, indent=1, sort_keys=sort_keys, default=str) + "\n"
    return atomic_write(path, text.encode())
