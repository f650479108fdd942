"""Task helpers shared by every stage: store handles, retry policy, scene ids and scene-file
expansion, JSON-safe stats.

Plain functions (no Prefect engine needed) so tests call them directly.
"""

from __future__ import annotations

import glob
import logging
import os
import re
from collections.abc import Sequence
from pathlib import Path

import yaml
from sim2radar.storage import ArtifactStore, is_transient_io_error

from sim2radar.fileio import jsonable

__all__ = [
    "FRAME_ROW",
    "failed_scene_ids",
    "expand_scenes",
    "open_store",
    "REMOTE_IO_RETRIES",
    "REMOTE_IO_RETRY_DELAYS_S",
    "retry_transient_io",
    "scene_id_for",
    "jsonable",
]

log = logging.getLogger(__name__)

#: Prefect retries for tasks whose work is storage I/O (remote object stores can flake).
#: Simulation tasks get none: a deterministic failure would only fail again.
REMOTE_IO_RETRIES = 3
#: Backoff between those retries [s].
REMOTE_IO_RETRY_DELAYS_S = [1.0, 4.0, 16.0]


def retry_transient_io(task, task_run, state) -> bool:
    """Prefect ``retry_condition_fn`` of every task retried with :data:`REMOTE_IO_RETRIES`:
    retry only errors that can flake (:func:`storage.is_transient_io_error`: timeouts, dropped
    connections), never ones that repeat on every attempt (a read-only or unwritable store,
    a full disk, a missing file, a schema or value error), which fail at once."""
    exc = state.data if isinstance(state.data, BaseException) else None
    if exc is None:
        try:
            exc = state.result(raise_on_failure=False)
        except Exception:  # noqa: BLE001 - an unreadable result is not a reason to retry
            return False
    return isinstance(exc, BaseException) and is_transient_io_error(exc)


#: A frame's manifest row id: ``<scene or world id>_f<frame index, 3+ digits>``.
FRAME_ROW = re.compile(r"^(.+)_f(\d{3,})$")


def failed_scene_ids(store, dataset: str) -> list[str]:
    """Ids of the scenes (worlds, capture scenes; not their frame rows) the ``dataset``
    manifest records as ``failed``: what ``--retry-failed`` reruns.

    Raises
    ------
    ValueError — the dataset has no manifest rows (naming the store and the datasets it has).
    """
    st = open_store(store)
    rows = st.manifest(dataset).rows()
    if not rows:
        raise ValueError(f"store {st.root}: dataset {dataset!r} has no manifest rows, nothing "
                         f"to retry; known datasets: {st.manifests()}")
    return sorted(r["scene_id"] for r in rows
                  if r["status"] == "failed" and not FRAME_ROW.match(r["scene_id"]))


def open_store(store: str | os.PathLike | ArtifactStore) -> ArtifactStore:
    """An :class:`~storage.ArtifactStore` from a path/URI (or the store itself)."""
    return store if isinstance(store, ArtifactStore) else ArtifactStore(store)


def scene_id_for(scene_path: str | os.PathLike) -> str:
    """The scene's id: the YAML ``name`` field if the file parses, else the file stem.

    Never raises, so a broken scene still gets a manifest row under a stable id.
    """
    path = Path(scene_path)
    try:
        doc = yaml.safe_load(path.read_text())
        if isinstance(doc, dict) and isinstance(doc.get("name"), str) and doc["name"].strip():
            return doc["name"].strip()
    except (OSError, yaml.YAMLError, UnicodeDecodeError):
        pass
    return path.stem


def expand_scenes(scenes: Sequence[str | os.PathLike]) -> list[str]:
    """Scene paths from files, folders (every ``*.yaml`` inside, recursively) and globs.

    A glob that matches nothing is logged and ignored (e.g. an empty ``scenes/`` folder on a
    nightly schedule); nothing found at all is an error.
    """
    out: list[str] = []
    for item in scenes:
        text = os.fspath(item)
        if any(c in text for c in "*?["):
            matches = sorted(glob.glob(text, recursive=True))
            if not matches:
                log.warning("scene pattern %r matches no file", text)
            out.extend(matches)
        elif Path(text).is_dir():
            found = sorted(str(p) for p in Path(text).rglob("*.yaml"))
            if not found:
                raise FileNotFoundError(f"scene folder {text!r} holds no *.yaml scene file")
            out.extend(found)
        else:
            out.append(text)  # a missing file is recorded as a failed scene by the flow
    if not out:
        raise FileNotFoundError(f"no scene files found in {[os.fspath(s) for s in scenes]}")
    return list(dict.fromkeys(out))  # de-duplicated, order kept
