"""Provenance: what made an artifact, stored in its Parquet key-value metadata.

Each artifact file carries one JSON document under the metadata key ``sim2radar.provenance``::

    {"stage": "radar_points", "stage_version": 1, "schema_version": 1, "key": "…",
     "inputs": {"scene": "…"}, "config": {…resolved…}, "seed": 0,
     "versions": {"sim2radar": "0.1.0", "mitsuba": "3.9.1", "drjit": "1.5.0", "torch": "2.13.0",
                  "numpy": "…", "pyarrow": "…", "python": "3.11.…"},
     "model_files": {"depth.onnx": "sha256…"}, "timings_s": {"simulate": 0.41},
     "created_utc": "2026-…Z", "host": "…", "extra": {…}}
"""

from __future__ import annotations

import functools
import importlib.metadata as md
import platform
import socket
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from sim2radar.storage.keys import _normalise, file_digest

__all__ = ["PROVENANCE_KEY", "package_versions", "build_provenance", "model_file_hashes",
           "combine_provisional", "git_commit"]

#: Parquet key-value metadata key holding the provenance JSON.
PROVENANCE_KEY = b"sim2radar.provenance"

#: Packages whose versions every artifact records (read from installed metadata, not imported).
TRACKED_PACKAGES: tuple[str, ...] = (
    "sim2radar",
    "mitsuba",
    "drjit",
    "torch",
    "numpy",
    "pyarrow",
    "prefect",
    "onnxruntime",
)


@functools.cache
def package_versions() -> dict[str, str]:
    """Installed versions of :data:`TRACKED_PACKAGES` (``"not installed"`` when absent)."""
    out = {"python": platform.python_version()}
    for name in TRACKED_PACKAGES:
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            out[name] = "not installed"
    return out


def model_file_hashes(paths: Mapping[str, str | Path]) -> dict[str, str]:
    """``{label: sha256}`` for model weight files (e.g. ``{"depth": "moge.onnx"}``)."""
    return {label: file_digest(p) for label, p in paths.items()}


def build_provenance(
    *,
    stage: str,
    stage_version: int,
    schema_version: int,
    key: str,
    provenance: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Assemble the provenance document of one artifact.

    ``provenance`` is the caller's part; recognised fields are ``inputs``, ``config``, ``seed``,
    ``timings_s``, ``model_files`` (label -> sha256) and ``extra``; anything else is kept under
    ``extra``. The store adds stage, versions, key, package versions, time and host.
    """
    given = dict(provenance or {})
    known = ("inputs", "config", "seed", "timings_s", "model_files")
    doc: dict[str, Any] = {
        "stage": stage,
        "stage_version": stage_version,
        "schema_version": schema_version,
        "key": key,
    }
    for name in known:
        doc[name] = _normalise(given.pop(name, None), f"provenance.{name}")
    extra = dict(given.pop("extra", None) or {})
    extra.update(given)
    doc["extra"] = _normalise(extra, "provenance.extra")
    doc["versions"] = package_versions()
    doc["created_utc"] = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")
    doc["host"] = socket.gethostname()
    return doc


def combine_provisional(records) -> dict[str, Any] | None:
    """The ``provisional`` record of an artifact made from several inputs (e.g. a radar frame
    from a scene fused with its views), from theirs (None: a result): fallbacks summed, the
    first reason kept; None when no input was provisional."""
    records = [r for r in records if r]
    if not records:
        return None
    return {"fallbacks": sum(int(r.get("fallbacks", 0)) for r in records),
            "reason": str(records[0].get("reason", ""))}


@functools.cache
def git_commit() -> str | None:
    """The git commit of the sim2radar checkout this code runs from, with ``-dirty`` when
    tracked files differ from it; None for an installed package (no checkout) or without git.
    Provenance only: never part of a content key."""
    import subprocess

    repo = Path(__file__).resolve().parents[1]
    if not (repo / ".git").exists():
        return None
    try:
        head = subprocess.run(["git", "-C", str(repo), "rev-parse", "HEAD"], capture_output=True,
                              text=True, timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(repo), "status", "--porcelain",
                                "--untracked-files=no"], capture_output=True, text=True,
                               timeout=10, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return head + ("-dirty" if dirty else "")
