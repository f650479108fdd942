"""Atomic file writes and JSON-able values for the library's own outputs (dataset exports,
reports, run records, provenance).

A file is written under a temporary name in its folder and renamed over the target, so a
killed process leaves the old file or the new one, never half of one (POSIX rename within one
file system). The Parquet artifact store publishes the same way (:mod:`sim2radar.storage.store`).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import socket
import sys
import time
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["atomic_write", "atomic_write_with", "write_json", "jsonable", "abandoned_temp_files",
           "json_text", "FolderBusyError", "WRITER_LOCK", "writer_lock"]

_TEMP = re.compile(r"^\..+\.tmp(\d+)$")


def atomic_write_with(path: str | os.PathLike, write: Callable[[Path], object]) -> Path:
    """Publish what ``write(tmp_path)`` writes as ``path`` atomically (the parent folder must
    exist), for writers that take a path (``torch.save``, ``pq.write_table``); a writer that
    raises leaves no temporary file behind. Returns the path."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def atomic_write(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (the parent folder must exist); returns the path."""
    return atomic_write_with(path, lambda tmp: tmp.write_bytes(data))


def jsonable(obj: Any, *, max_array: int | None = None) -> Any:
    """A copy of ``obj`` that :func:`json.dumps` writes as standard JSON.

    Mappings become dicts with ``str`` keys, tuples and lists lists, NumPy scalars Python
    numbers, NaN and +-inf ``None`` (JSON has no such numbers), arrays lists — or, above
    ``max_array`` elements, the text ``"<array (shape) dtype>"`` — and anything else its
    ``str``."""
    if obj is None or isinstance(obj, bool | str):
        return obj
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v, max_array=max_array) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v, max_array=max_array) for v in obj]
    if isinstance(obj, np.ndarray):
        if max_array is not None and obj.size > max_array:
            return f"<array {obj.shape} {obj.dtype}>"
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, bool | int | str):
        return obj
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    return str(obj)


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
    """Write ``doc`` as indented JSON atomically, creating the parent folder; values go
    through :func:`jsonable` (NumPy values as numbers, NaN/inf as null, anything else JSON
    cannot hold as its ``str``). Returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(jsonable(doc), indent=1, sort_keys=sort_keys) + "\n"
    return atomic_write(path, text.encode())


def json_text(path: str | os.PathLike) -> str | None:
    """The text of a JSON file, or of its gzip-compressed copy ``<path>.gz`` where only that
    exists (a published sweep keeps its large JSON files compressed); None when neither does.

    Raises OSError / UnicodeDecodeError for a file that cannot be read (gzip's BadGzipFile is an
    OSError)."""
    import gzip

    path = Path(path)
    if path.is_file():
        return path.read_text(encoding="utf-8")
    packed = path.with_name(path.name + ".gz")
    if packed.is_file():
        return gzip.decompress(packed.read_bytes()).decode("utf-8")
    return None


#: The suffix of the lock file a writer holds beside a folder it writes (an OpenPCDet export):
#: ``.<folder name>.sim2radar-writer.lock``.
WRITER_LOCK = ".sim2radar-writer.lock"


class FolderBusyError(RuntimeError):
    """Another live process holds the folder's writer lock (:func:`writer_lock`)."""


@contextlib.contextmanager
def writer_lock(folder: str | os.PathLike, what: str = "folder") -> Iterator[Path]:
    """Hold ``folder``'s writer lock (an exclusive ``fcntl`` lock on ``.<folder name>
    .sim2radar-writer.lock`` beside it, so the folder's own files stay exactly the dataset's)
    while the block runs: a second run writing the same folder is refused at once with
    :class:`FolderBusyError` naming the first (its pid, host, start time and command), instead
    of both writing it and the last one winning. The lock goes with its process: a killed run
    leaves nothing to clean up (the small file stays; the next writer takes it)."""
    import fcntl

    folder = Path(folder).absolute()
    folder.parent.mkdir(parents=True, exist_ok=True)
    fh = open(folder.parent / f".{folder.name}{WRITER_LOCK}", "a+")  # noqa: SIM115
    try:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            owner = fh.read().strip() or "a process that did not say who it is"
            raise FolderBusyError(f"{folder}: another run is writing this {what} ({owner}); "
                                  f"wait for it to finish, or choose another {what}") from None
        fh.seek(0)
        fh.truncate()
        fh.write(f"pid {os.getpid()} on {socket.gethostname()} since "
                 f"{time.strftime('%Y-%m-%d %H:%M:%S')}: {' '.join(sys.argv)[:300]}\n")
        fh.flush()
        yield folder
    finally:
        fh.close()  # releases the lock
