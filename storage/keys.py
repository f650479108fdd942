"""Content keys: the identity of an artifact is the hash of what produced it.

``key = sha256(canonical JSON of {stage, stage_version, inputs, config})``, hex, truncated to
:data:`KEY_LENGTH` characters. Changing an input key, a resolved config value or the stage's
version changes the key, so the stage runs again; an identical request maps to the identical key,
so the stage is skipped. Dictionary order never matters (keys are sorted); NumPy scalars/arrays,
paths, tuples, sets and dataclasses are normalised before hashing.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
from collections.abc import Mapping
from pathlib import Path, PurePath
from typing import Any

import numpy as np

__all__ = ["KEY_LENGTH", "canonical_json", "content_key", "file_digest", "bytes_digest", "is_key"]

#: Hex characters kept from the SHA-256 digest (80 bits: collisions are not a practical concern
#: for datasets of any size this factory makes, and paths stay short).
KEY_LENGTH = 20

_KEY_RE = re.compile(rf"^[0-9a-f]{{{KEY_LENGTH}}}$")
_STAGE_RE = re.compile(r"^[a-z][a-z0-9_]*$")


def _normalise(obj: Any, where: str) -> Any:
    """Turn ``obj`` into plain JSON types, deterministically."""
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        value = float(obj)
        if not math.isfinite(value):
            # JSON has no NaN/inf; keep them distinguishable from numbers and from each other
            return {"__float__": repr(value)}
        # 0.1 + 0.2 style noise must not change keys; 12 significant digits is far below any
        # physical tolerance here and far above float32 resolution.
        return float(f"{value:.12g}")
    if isinstance(obj, complex):
        return {"__complex__": [_normalise(obj.real, where), _normalise(obj.imag, where)]}
    if isinstance(obj, np.ndarray):
        return {"__ndarray__": _normalise(obj.tolist(), where), "dtype": str(obj.dtype)}
    if isinstance(obj, PurePath):
        return obj.as_posix()
    if isinstance(obj, Mapping):
        out = {}
        for k, v in obj.items():
            if not isinstance(k, str):
                raise TypeError(f"{where}: mapping keys must be strings for hashing, got {k!r}")
            out[k] = _normalise(v, f"{where}.{k}")
        return out
    if isinstance(obj, (list, tuple)):
        return [_normalise(v, f"{where}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, (set, frozenset)):
        return sorted((_normalise(v, where) for v in obj), key=lambda v: json.dumps(v))
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return _normalise(dataclasses.asdict(obj), where)
    if hasattr(obj, "model_dump"):  # pydantic v2 model
        return _normalise(obj.model_dump(mode="json"), where)
    if hasattr(obj, "to_dict"):
        return _normalise(obj.to_dict(), where)
    raise TypeError(
        f"{where}: cannot hash a {type(obj).__name__} into a content key; pass plain data "
        "(dict/list/str/number/ndarray), a dataclass, or an object with .to_dict()"
    )


def canonical_json(obj: Any) -> str:
    """Deterministic JSON text of ``obj`` (sorted keys, no whitespace, normalised numbers)."""
    return json.dumps(_normalise(obj, "value"), sort_keys=True, separators=(",", ":"))


def content_key(
    *,
    stage: str,
    stage_version: int,
    inputs: Mapping[str, Any] | None = None,
    config: Any = None,
) -> str:
    """The content key of one artifact.

    Parameters
    ----------
    stage : str
        Stage name, lowercase snake case (``"radar_points"``); also the store's folder name.
    stage_version : int
        Bump it whenever the stage's code changes its output: every artifact of that stage is
        recomputed (and only those, plus stages downstream whose inputs change).
    inputs : mapping, optional
        Name -> content key (or digest) of each upstream input, e.g. ``{"scene": scene_key}``.
    config : any, optional
        The *resolved* configuration (every value that influences the output, seeds included).

    Returns
    -------
    str
        :data:`KEY_LENGTH` lowercase hex characters.
    """
    if not isinstance(stage, str) or not _STAGE_RE.match(stage):
        raise ValueError(f"stage must be lowercase snake case like 'radar_points', got {stage!r}")
    if isinstance(stage_version, bool) or not isinstance(stage_version, int) or stage_version < 0:
        raise ValueError(f"stage_version must be a non-negative int, got {stage_version!r}")
    payload = {
        "stage": stage,
        "stage_version": stage_version,
        "inputs": dict(inputs or {}),
        "config": config,
    }
    return hashlib.sha256(canonical_json(payload).encode("utf-8")).hexdigest()[:KEY_LENGTH]


def bytes_digest(data: bytes) -> str:
    """SHA-256 hex digest of ``data`` (full length; used for model files and scene files)."""
    return hashlib.sha256(data).hexdigest()


def file_digest(path: str | Path, *, chunk_bytes: int = 1 << 20) -> str:
    """SHA-256 hex digest of a local file's bytes (for model weights and input files)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(chunk_bytes):
            h.update(chunk)
    return h.hexdigest()


def is_key(text: str) -> bool:
    """True if ``text`` looks like a content key."""
    return bool(_KEY_RE.match(text))
