"""The artifact store: one Parquet file per (stage, key), published atomically.

Layout under the root (a local folder or any fsspec URI: ``s3://bucket/x``, ``gs://…``,
``memory://…``)::

    <root>/<stage>/<key>.parquet              published artifacts (complete by construction)
    <root>/<stage>/.tmp-<key>-<uuid>.parquet  in-flight writes (never read; see clean_partial)
    <root>/manifests/<dataset>/<scene>.parquet  one manifest row per scene (see manifest.py)
    <root>/quarantine/<path>.<UTC time>         files that did not verify, moved aside (kept)

Atomic publish: a file is written under a hidden temporary name in the same folder and then
renamed to its final name (``os.replace`` after ``fsync`` on local disks; on object stores the
final object appears whole when its upload/copy completes). A reader never sees half a file, and
a killed run leaves only ``.tmp-*`` files, which ``exists``/``keys``/``read`` ignore. The
mechanics (paths, retries, atomic publish, quarantine) are :class:`~sim2radar.storage._files.FileRoot`'s,
which the store extends and the manifests (:mod:`sim2radar.storage.manifest`) write through.

Self-healing: a published file that does not verify (truncated, overwritten, not Parquet — its
footer does not parse or its row groups do not add up to its row count) is never served. The
cache check :meth:`ArtifactStore.exists` verifies the footer, moves a file that fails into
``quarantine/`` (nothing is deleted) with one warning naming it, and answers False, so the run
that asked recomputes it; :meth:`ArtifactStore.read` does the same for a body that does not
decode (:class:`CorruptArtifactError`). :meth:`ArtifactStore.verify_all` reads every file
(``sim2radar store verify``).

Remote I/O can flake: on non-local file systems every operation is retried ``io_retries`` times
with exponential backoff (transient ``OSError``/``TimeoutError``/``ConnectionError`` only, see
:func:`is_transient_io_error`; a missing file, a permission error, a full or read-only disk or
a schema error is never retried). Local I/O is not retried. :func:`check_writable` tells up
front whether a local store root can be written.
"""

from __future__ import annotations

import json
import os
import re
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from sim2radar.storage._files import QUARANTINE, TMP_PREFIX, FileRoot, is_transient_io_error
from sim2radar.storage.integrity import SCHEMA_KEY, file_problem, is_corrupt_file_error
from sim2radar.storage.manifest import MANIFESTS, Manifest
from sim2radar.storage.provenance import PROVENANCE_KEY, build_provenance
from sim2radar.storage.schemas import SchemaError, get_schema

__all__ = [
    "ArtifactStore",
    "ArtifactNotFoundError",
    "CorruptArtifactError",
    "QUARANTINE",
    "SCHEMA_KEY",
    "check_writable",
    "is_transient_io_error",
]

_KEY_RE = re.compile(r"[0-9a-f]{8,64}")  # content keys (sim2radar.storage.keys.KEY_LENGTH) or digests


class ArtifactNotFoundError(FileNotFoundError):
    """No published artifact for (stage, key); the message names the path."""


class CorruptArtifactError(SchemaError):
    """A published file that does not read as the Parquet it should be (truncated, damaged).
    It has been moved into the store's ``quarantine/``; the next run recomputes it."""


def check_writable(root: str | os.PathLike) -> None:
    """Check that a local store root can be written, before any work starts.

    The root need not exist yet: its nearest existing ancestor must be a folder in which a file
    can be created (the probe file is removed again; nothing else is created). Remote URIs
    (``s3://``, ``gs://``, ``memory://``, ...) are not checked: that would need credentials and
    network I/O; their errors surface on the first write.

    Raises
    ------
    ValueError
        If a file stands where the store (or one of its parent folders) should be.
    PermissionError
        If the folder cannot be written (permissions, read-only file system, ...); the message
        names the path and what to do.
    """
    text = os.fspath(root)
    if "://" in text and not text.startswith("file://"):
        return
    path = Path(text.removeprefix("file://")).absolute()
    probe = path
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if not probe.is_dir():
        raise ValueError(f"store {path}: {probe} is a file, not a folder; choose a store path "
                         "whose parents are folders")
    try:
        fd, tmp = tempfile.mkstemp(prefix=".write-check-", dir=probe)
        os.close(fd)
        os.unlink(tmp)
    except OSError as exc:
        where = "" if probe == path else f" (its nearest existing parent {probe})"
        raise PermissionError(
            f"store {path}{where} is not writable: {exc.strerror or exc}; choose a writable "
            "folder or fix its permissions"
        ) from None


class ArtifactStore(FileRoot):
    """Parquet artifacts keyed by content, under a local path or fsspec URI.

    Parameters
    ----------
    root, io_retries, retry_backoff_s, compression, storage_options
        As for :class:`~sim2radar.storage._files.FileRoot` (the root folder or fsspec URI,
        retries of remote I/O, first backoff [s], Parquet codec, fsspec options), whose paths,
        retried I/O, atomic publish and quarantine the store builds on.

    Examples
    --------
    >>> store = ArtifactStore("out/store")
    >>> key = content_key(stage="radar_points", stage_version=1, inputs={"scene": skey},
    ...                   config=radar.to_dict())
    >>> if not store.exists("radar_points", key):
    ...     store.write("radar_points", key, table, provenance={"config": radar.to_dict()})
    >>> table = store.read("radar_points", key)
    """

    # -- pickling (Prefect / Dask workers rebuild the file system from the URI) ---------------
    def __reduce__(self):
        return (
            _rebuild_store,
            (self.root_uri, self.io_retries, self.retry_backoff_s, self.compression, self.storage_options),
        )

    def __repr__(self) -> str:
        return f"ArtifactStore({self.root_uri!r})"

    # -- paths --------------------------------------------------------------------------------

    def path(self, stage: str, key: str) -> str:
        """Path of an artifact inside the store's file system."""
        _check_stage_key(stage, key)
        return self.join(stage, f"{key}.parquet")

    def uri(self, stage: str, key: str) -> str:
        """Human-readable location of an artifact (local path, or ``protocol://path``)."""
        return self.location(self.path(stage, key))

    # -- queries ------------------------------------------------------------------------------
    def exists(self, stage: str, key: str) -> bool:
        """True if a complete artifact (stage, key) is published and its footer verifies.

        A published file that does not verify is moved into ``quarantine/`` (one warning names
        it) and the answer is False: the caller recomputes it, as if it had never been written.
        """
        path = self.path(stage, key)
        if not self.retrying(f"exists {path}", lambda: self.fs.exists(path)):
            return False
        problem = self.retrying(f"verify {path}", lambda: file_problem(self.fs, path))
        if problem is None:
            return True
        self.quarantine(path, problem)
        return False

    def all_exist(self, keys: Mapping[str, str]) -> bool:
        """``exists`` for every ``stage -> key`` (each one checked: every file that does not
        verify is quarantined, not only the first)."""
        return all([self.exists(stage, key) for stage, key in keys.items()])

    def provisional(self, stage: str, key: str) -> dict[str, Any] | None:
        """The ``provisional`` record of an artifact written from a fallback (``{"fallbacks":
        n, "reason": ...}``, see :meth:`write`), or None for a result (and for an artifact
        that is not there)."""
        if not self.exists(stage, key):
            return None
        return self.read_provenance(stage, key).get("provisional") or None

    def cached(self, stage: str, key: str) -> bool:
        """Whether a step may skip computing ``(stage, key)``: the artifact exists, verifies and
        is a result, not a provisional stand-in written from a fallback (a VLM outage's
        ``unknown`` materials and everything simulated from them are computed again)."""
        return self.exists(stage, key) and not (
            self.read_provenance(stage, key).get("provisional"))

    def all_cached(self, keys: Mapping[str, str]) -> bool:
        """``cached`` for every ``stage -> key`` (each one checked, like :meth:`all_exist`)."""
        return all([self.cached(stage, key) for stage, key in keys.items()])

    def verify(self, stage: str, key: str, *, deep: bool = True) -> str | None:
        """What is wrong with a published artifact (None when it reads; ``deep`` decodes every
        page, otherwise only the footer is checked). Moves nothing."""
        path = self.path(stage, key)
        return self.retrying(f"verify {path}", lambda: file_problem(self.fs, path, deep=deep))

    def verify_all(self, *, repair: bool = False) -> list[dict[str, str]]:
        """Read every published artifact and manifest row file in full; returns one
        ``{"path", "problem", "moved_to"}`` per file that does not verify (``moved_to`` only
        with ``repair``, which quarantines them so the next run recomputes them)."""
        from sim2radar.storage.schemas import schema_names

        found = []
        targets = [(stage, self.join(stage)) for stage in schema_names() if stage != "manifest"]
        targets += [("manifest", self.join(MANIFESTS, name)) for name in self.manifests()]
        for stage, folder in targets:
            if not self.fs.exists(folder):
                continue
            for path in sorted(self.fs.ls(folder, detail=False)):
                name = path.rsplit("/", 1)[-1]
                if not name.endswith(".parquet") or name.startswith("."):
                    continue
                if stage != "manifest" and not _KEY_RE.fullmatch(name[: -len(".parquet")]):
                    continue
                problem = self.retrying(f"verify {path}", lambda p=path, s=stage: file_problem(
                    self.fs, p, deep=True, expected_schema=s))
                if problem is None:
                    continue
                row = {"path": path, "problem": problem}
                if repair:
                    row["moved_to"] = self.quarantine(path, problem) or ""
                found.append(row)
        return found

    def keys(self, stage: str) -> list[str]:
        """Published keys of ``stage``, sorted (in-flight ``.tmp-*`` files are not listed)."""
        get_schema(stage)
        folder = self.join(stage)

        def ls() -> list[str]:
            if not self.fs.exists(folder):
                return []
            return [p.rsplit("/", 1)[-1] for p in self.fs.ls(folder, detail=False)]

        names = self.retrying(f"list {folder}", ls)
        stems = (n[: -len(".parquet")] for n in names if n.endswith(".parquet"))
        return sorted(s for s in stems if _KEY_RE.fullmatch(s))

    # -- write --------------------------------------------------------------------------------
    def write(
        self,
        stage: str,
        key: str,
        table: pa.Table,
        *,
        provenance: Mapping[str, Any] | None = None,
        stage_version: int | None = None,
        provisional: Mapping[str, Any] | None = None,
    ) -> str:
        """Validate ``table`` against the stage's declared schema and publish it atomically.

        Parameters
        ----------
        stage, key : str
            Stage name (declared in ``storage/schemas.py``) and content key
            (:func:`storage.content_key`).
        table : pyarrow.Table
            The artifact; converted losslessly to the declared column order and types.
        provenance : mapping, optional
            ``inputs``, ``config``, ``seed``, ``timings_s``, ``model_files``, ``extra`` (see
            :func:`sim2radar.storage.provenance.build_provenance`); package versions, time and host are
            added here.
        stage_version : int, optional
            The stage version that went into ``key`` (recorded for humans).
        provisional : mapping, optional
            ``{"fallbacks": n, "reason": str}`` when the artifact stands in for a result this
            run could not get (a fallback, e.g. ``on_error: unknown`` materials) or was made
            from one: it is stored (this run goes on with it) but :meth:`cached` says False, so
            the next run computes it again instead of keeping the fallback for good.

        Returns
        -------
        str
            The artifact's location (:meth:`uri`).
        """
        schema = get_schema(stage)
        table = schema.validate(table)
        doc = build_provenance(
            stage=stage,
            stage_version=stage_version if stage_version is not None else -1,
            schema_version=schema.version,
            key=key,
            provenance=provenance,
        )
        if provisional:
            doc["provisional"] = {"fallbacks": int(provisional.get("fallbacks", 0)),
                                  "reason": str(provisional.get("reason", ""))}
        meta = dict(table.schema.metadata or {})
        meta[PROVENANCE_KEY] = json.dumps(doc, sort_keys=True).encode()
        meta[SCHEMA_KEY] = f"{stage}:{schema.version}".encode()
        table = table.replace_schema_metadata(meta)
        final = self.path(stage, key)
        self.retrying(f"write {final}", lambda: self.publish(final, table))
        return self.uri(stage, key)

    # -- read ---------------------------------------------------------------------------------
    def _open_checked(self, stage: str, key: str) -> tuple[str, pq.ParquetFile, Any]:
        schema = get_schema(stage)
        path = self.path(stage, key)
        try:
            fh = self.fs.open(path, "rb")
        except FileNotFoundError:
            raise ArtifactNotFoundError(
                f"no artifact {stage}/{key} in store {self.root}: {path} does not exist"
            ) from None
        try:
            pf = pq.ParquetFile(fh, page_checksum_verification=True)
        except Exception as exc:
            fh.close()
            if not is_corrupt_file_error(exc):
                raise
            self.quarantine(path, f"not a readable Parquet file: {exc}")
            raise CorruptArtifactError(
                f"{path}: not a readable Parquet file ({exc}); moved to the store's "
                f"{QUARANTINE}/, the next run recomputes it") from exc
        recorded = (pf.schema_arrow.metadata or {}).get(SCHEMA_KEY, b"").decode()
        expected = f"{stage}:{schema.version}"
        if recorded != expected:
            fh.close()
            raise SchemaError(
                f"{path}: recorded schema {recorded or '(none)'!r} differs from declared "
                f"{expected!r}; it was written by another code version — bump the stage version "
                "to recompute, or read it with the code that wrote it"
            )
        schema.check_file_schema(pf.schema_arrow, path)
        return path, pf, fh

    def read(self, stage: str, key: str, *, columns: list[str] | None = None) -> pa.Table:
        """Read a published artifact, validated against its declared schema.

        Raises
        ------
        ArtifactNotFoundError
            If the artifact is not published.
        SchemaError
            If the file's recorded schema differs from the declared one.
        """

        def go() -> pa.Table:
            path, pf, fh = self._open_checked(stage, key)
            with fh:
                try:
                    return pf.read(columns=columns)
                except Exception as exc:
                    if not is_corrupt_file_error(exc):
                        raise
                    problem = f"a page does not decode: {' '.join(str(exc).split())}"
            self.quarantine(path, problem)
            raise CorruptArtifactError(f"{path}: {problem}; moved to the store's {QUARANTINE}/, "
                                       "the next run recomputes it")

        return self.retrying(f"read {stage}/{key}", go)

    def read_provenance(self, stage: str, key: str) -> dict[str, Any]:
        """The provenance document stored with an artifact (see :mod:`sim2radar.storage.provenance`)."""

        def go() -> dict[str, Any]:
            _, pf, fh = self._open_checked(stage, key)
            with fh:
                raw = (pf.schema_arrow.metadata or {}).get(PROVENANCE_KEY)
            return json.loads(raw) if raw else {}

        return self.retrying(f"read provenance {stage}/{key}", go)

    # -- maintenance --------------------------------------------------------------------------
    def delete(self, stage: str, key: str) -> bool:
        """Remove an artifact; True if it existed."""
        path = self.path(stage, key)
        if not self.exists(stage, key):
            return False
        self.retrying(f"delete {path}", lambda: self.fs.rm(path))
        return True

    def partial_files(self) -> list[str]:
        """In-flight or abandoned ``.tmp-*`` files (left by killed runs), all stages."""
        if not self.fs.exists(self._base):
            return []
        found = self.fs.find(self._base)
        return sorted(p for p in found if p.rsplit("/", 1)[-1].startswith(TMP_PREFIX))

    def clean_partial(self, older_than_s: float = 3600.0) -> list[str]:
        """Delete ``.tmp-*`` files older than ``older_than_s`` [s]; returns their paths.

        Keep the age margin above the longest write, so a concurrent writer is not disturbed.
        """
        removed = []
        now = time.time()
        for p in self.partial_files():
            try:
                modified = self.fs.modified(p).timestamp()
            except (NotImplementedError, AttributeError, OSError):
                modified = 0.0
            if now - modified >= older_than_s:
                self.fs.rm(p)
                removed.append(p)
        return removed

    # -- manifests ----------------------------------------------------------------------------
    def manifest(self, dataset: str) -> Manifest:
        """The :class:`~sim2radar.storage.manifest.Manifest` of ``dataset`` in this store.

        Raises
        ------
        ValueError
            If ``dataset`` is not a valid dataset name (letters, digits, ``_ . -``).
        """
        return Manifest(self, dataset)

    def manifests(self) -> list[str]:
        """Names of the datasets that have a manifest in this store."""
        folder = self.join(MANIFESTS)
        if not self.fs.exists(folder):
            return []
        return sorted(p.rstrip("/").rsplit("/", 1)[-1] for p in self.fs.ls(folder, detail=False))


def _check_stage_key(stage: str, key: str) -> None:
    get_schema(stage)
    if not isinstance(key, str) or not _KEY_RE.fullmatch(key):
        raise ValueError(
            f"artifact key must be lowercase hex (from storage.content_key), got {key!r}"
        )


def _rebuild_store(root, io_retries, retry_backoff_s, compression, storage_options):
    return ArtifactStore(
        root,
        io_retries=io_retries,
        retry_backoff_s=retry_backoff_s,
        compression=compression,
        storage_options=storage_options,
    )
