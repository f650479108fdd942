"""Per-dataset manifests: one row per scene with status, error, artifact keys and timings.

A manifest is stored as one small Parquet file per scene under
``<root>/manifests/<dataset>/``, each published atomically, so many workers (threads,
processes, Dask) can record scenes concurrently without a lock or a lost update, and a killed
run loses at most the scene it was on. :meth:`Manifest.table` gathers the rows.

Status vocabulary:

``ok``
    the scene's artifacts were computed and written by the latest run;
``skipped``
    every artifact already existed under its content key, nothing was recomputed;
``failed``
    the latest run raised; ``error`` holds the message.

Resume = run again (done scenes are skipped by content key); retry the failed scenes = run
again (they have no artifact, so they are computed again) or pass ``manifest.failed()``.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
from collections.abc import Mapping
from datetime import UTC, datetime
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from sim2radar.storage._files import FileRoot
from sim2radar.storage.integrity import is_corrupt_file_error
from sim2radar.storage.schemas import MANIFEST
from sim2radar.vocab import MAX_ID_LENGTH, STATUSES, id_problem

__all__ = ["MANIFESTS", "MAX_ID_LENGTH", "MAX_NAME_LENGTH", "Manifest", "STATUSES",
           "check_dataset_name", "id_problem"]

#: folder of the store root that holds one folder of row files per dataset
MANIFESTS = "manifests"
_DATASET_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


#: The longest dataset name (one folder of the store).
MAX_NAME_LENGTH = 100


def check_dataset_name(dataset: str) -> str:
    """``dataset``, if it is a valid dataset name (one folder name: letters, digits, ``_ . -``,
    not starting with a dot, at most :data:`MAX_NAME_LENGTH` characters); ValueError
    otherwise."""
    if not isinstance(dataset, str) or not _DATASET_RE.match(dataset):
        raise ValueError(
            f"dataset name must match {_DATASET_RE.pattern} (letters, digits, _ . -), got {dataset!r}"
        )
    if len(dataset) > MAX_NAME_LENGTH:
        raise ValueError(f"dataset name must be at most {MAX_NAME_LENGTH} characters, got "
                         f"{len(dataset)} ({dataset[:40]!r}...)")
    return dataset


@contextlib.contextmanager
def _file_lock(path: str):
    """Hold an exclusive ``fcntl`` lock on the local file ``path`` (created with its folder)."""
    import fcntl

    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _row_name(scene_id: str) -> str:
    """A file name for ``scene_id``: readable prefix + hash (ids may contain '/' etc.)."""
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", scene_id)[:80].lstrip(".") or "scene"
    digest = hashlib.sha256(scene_id.encode()).hexdigest()[:10]
    return f"{safe}-{digest}.parquet"


class Manifest:
    """The manifest of one dataset in an :class:`~sim2radar.storage.store.ArtifactStore`.

    Obtain it with ``store.manifest("name")``.

    Parameters
    ----------
    store : FileRoot
        The store (any :class:`~sim2radar.storage._files.FileRoot`: the manifest only needs its
        paths, retried I/O, atomic publish and quarantine); rows go to
        ``<root>/manifests/<dataset>/``.
    dataset : str
        The dataset's name (:func:`check_dataset_name`).
    """

    def __init__(self, store: FileRoot, dataset: str) -> None:
        self.store = store
        self.dataset = check_dataset_name(dataset)
        self._folder = store.join(MANIFESTS, dataset)

    def __repr__(self) -> str:
        return f"Manifest({self.store.root!r}, {self.dataset!r})"

    def _path(self, scene_id: str) -> str:
        return f"{self._folder}/{_row_name(scene_id)}"

    # -- write ------------------------------------------------------------------------------
    def upsert(
        self,
        scene_id: str,
        status: str,
        *,
        error: str = "",
        artifacts: Mapping[str, str] | None = None,
        timings_s: Mapping[str, float] | None = None,
        source: str = "",
        fallbacks: int = 0,
    ) -> dict[str, Any]:
        """Insert or replace the row of ``scene_id``; returns the row as a dict.

        ``attempts`` counts how many runs recorded this scene (incremented here); ``fallbacks``
        the segments whose material fell back in what the scene was made from.
        """
        if status not in STATUSES:
            raise ValueError(f"manifest status must be one of {STATUSES}, got {status!r}")
        if not isinstance(scene_id, str) or not scene_id:
            raise ValueError("manifest scene_id must be a non-empty string")
        with self._row_lock():
            return self._upsert(scene_id, status, error, artifacts, timings_s, source, fallbacks)

    def _row_lock(self):
        """An exclusive lock on this dataset's rows while one is read and written again (a
        local store: ``fcntl`` on ``<folder>/.lock``; two runs recording one scene lost an
        ``attempts`` update); remote stores have none (their writers are not on this host)."""
        import contextlib

        if not getattr(self.store, "is_local", False):
            return contextlib.nullcontext()
        return _file_lock(self.store.join(MANIFESTS, self.dataset, ".lock"))

    def _upsert(self, scene_id, status, error, artifacts, timings_s, source,
                fallbacks) -> dict[str, Any]:
        previous = self.get(scene_id)
        row = {
            "scene_id": scene_id,
            "status": status,
            "error": str(error or ""),
            "artifacts": dict(artifacts or {}),
            "timings_s": {k: float(v) for k, v in (timings_s or {}).items()},
            "source": str(source or ""),
            "attempts": (previous["attempts"] if previous else 0) + 1,
            "updated_utc": datetime.now(UTC),
            "fallbacks": int(fallbacks),
        }
        table = pa.Table.from_pylist(
            [
                {
                    **row,
                    "artifacts": list(row["artifacts"].items()),
                    "timings_s": list(row["timings_s"].items()),
                }
            ],
            schema=MANIFEST.schema,
        )
        table = MANIFEST.validate(table)
        table = table.replace_schema_metadata({b"sim2radar.schema": f"manifest:{MANIFEST.version}".encode()})
        path = self._path(scene_id)
        self.store.retrying(f"manifest upsert {path}", lambda: self.store.publish(path, table))
        return row

    # -- read -------------------------------------------------------------------------------
    def _read_file(self, path: str) -> pa.Table | None:
        """The row file at ``path``; None (the file moved into the store's quarantine, one
        warning) when it does not read — the run that records the scene again rebuilds it from
        the scene's artifacts, which are found cached."""
        try:
            with self.store.fs.open(path, "rb") as fh:
                table = pq.read_table(fh, page_checksum_verification=True)
        except FileNotFoundError:
            return None
        except Exception as exc:
            if not is_corrupt_file_error(exc):
                raise  # an I/O error (worth the store's retries), not a damaged file
            self.store.quarantine(path, f"manifest row not readable: {' '.join(str(exc).split())}")
            return None
        if "fallbacks" not in table.column_names and table.column_names == [
                n for n in MANIFEST.schema.names if n != "fallbacks"]:
            # a v1 row (written before fallbacks were counted): none were recorded
            table = table.append_column(MANIFEST.schema.field("fallbacks"),
                                        pa.array([0] * table.num_rows, pa.int32()))
        MANIFEST.check_file_schema(table.schema, path)
        return table

    def get(self, scene_id: str) -> dict[str, Any] | None:
        """The row of ``scene_id`` as a dict (``artifacts``/``timings_s`` as dicts), or None."""
        path = self._path(scene_id)
        if not self.store.retrying(f"exists {path}", lambda: self.store.fs.exists(path)):
            return None
        table = self.store.retrying(f"read {path}", lambda: self._read_file(path))
        rows = _to_rows(table) if table is not None else []
        return rows[0] if rows else None

    def table(self) -> pa.Table:
        """All rows, sorted by ``scene_id`` (an empty table with the declared schema if none)."""

        def gather() -> pa.Table:
            fs = self.store.fs
            if not fs.exists(self._folder):
                return MANIFEST.schema.empty_table()
            paths = sorted(
                p for p in fs.ls(self._folder, detail=False)
                if p.endswith(".parquet") and not p.rsplit("/", 1)[-1].startswith(".")
            )
            if not paths:
                return MANIFEST.schema.empty_table()
            tables = [t.replace_schema_metadata(None) for t in map(self._read_file, paths)
                      if t is not None]
            if not tables:
                return MANIFEST.schema.empty_table()
            return pa.concat_tables(tables).sort_by("scene_id")

        return self.store.retrying(f"read manifest {self.dataset}", gather)

    def rows(self) -> list[dict[str, Any]]:
        """All rows as dicts, sorted by ``scene_id``."""
        return _to_rows(self.table())

    def counts(self) -> dict[str, int]:
        """``{status: number of scenes}`` for every status."""
        counts = dict.fromkeys(STATUSES, 0)
        for status in self.table().column("status").to_pylist():
            counts[status] += 1
        return counts

    def scene_ids(self, status: str | None = None) -> list[str]:
        """Scene ids, optionally only those with ``status``."""
        return [r["scene_id"] for r in self.rows() if status is None or r["status"] == status]

    def failed(self) -> list[str]:
        """Scene ids whose latest run failed (the ones to retry)."""
        return self.scene_ids("failed")

    def write_csv(self, path: str) -> str:
        """A flat CSV copy for humans (maps as JSON text); returns ``path``."""
        import csv
        import json

        with open(path, "w", newline="") as fh:
            writer = csv.writer(fh)
            cols = MANIFEST.schema.names
            writer.writerow(cols)
            for r in self.rows():
                writer.writerow(
                    [json.dumps(r[c]) if isinstance(r[c], dict) else r[c] for c in cols]
                )
        return path


def _to_rows(table: pa.Table) -> list[dict[str, Any]]:
    rows = table.to_pylist()
    for r in rows:
        r["artifacts"] = dict(r["artifacts"] or [])
        r["timings_s"] = dict(r["timings_s"] or [])
    return rows
