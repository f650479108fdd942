"""Task helpers shared by every stage: store handles, retry policy, scene ids, JSON-safe stats.

Plain functions (no Prefect engine needed) so tests call them directly.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from storage import ArtifactStore

__all__ = ["open_store", "REMOTE_IO_RETRIES", "REMOTE_IO_RETRY_DELAYS_S", "scene_id_for", "jsonable"]

#: Prefect retries for tasks whose work is storage I/O (remote object stores can flake).
#: Simulation tasks get none: a deterministic failure would only fail again.
REMOTE_IO_RETRIES = 3
#: Backoff between those retries [s].
REMOTE_IO_RETRY_DELAYS_S = [1.0, 4.0, 16.0]


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


def jsonable(obj: Any) -> Any:
    """Best-effort conversion of stats/timings dicts to JSON-safe values (for provenance)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist()) if obj.size <= 64 else f"<array {obj.shape} {obj.dtype}>"
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else repr(v)
    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    return repr(obj)
