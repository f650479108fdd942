"""The files under a store root: paths, retried I/O, atomic Parquet publish, quarantine.

:class:`FileRoot` is the low-level layer that both the artifact store
(:class:`~sim2radar.storage.store.ArtifactStore`, a subclass) and the per-dataset manifests
(:class:`~sim2radar.storage.manifest.Manifest`, which receives a ``FileRoot``) write through.
It knows nothing of stages, keys or manifests; the layout of the root is theirs.

Atomic publish: a file is written under a hidden temporary name (``.tmp-…``) in the same folder
and then renamed to its final name (``os.replace`` after ``fsync`` on local disks; on object
stores the final object appears whole when its upload/copy completes). A reader never sees half
a file, and a killed run leaves only ``.tmp-*`` files.

Remote I/O can flake: on non-local file systems :meth:`FileRoot.retrying` retries an operation
``io_retries`` times with exponential backoff (transient errors only, see
:func:`is_transient_io_error`). Local I/O is not retried.
"""

from __future__ import annotations

import errno
import logging
import os
import time
import uuid
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import fsspec
import pyarrow as pa
import pyarrow.parquet as pq

__all__ = ["FileRoot", "QUARANTINE", "TMP_PREFIX", "is_transient_io_error"]

log = logging.getLogger(__name__)

#: name prefix of in-flight writes (never read; see ArtifactStore.clean_partial)
TMP_PREFIX = ".tmp-"
#: folder of the store root that receives files which did not verify
QUARANTINE = "quarantine"
T = TypeVar("T")

#: OSError subclasses that say the same thing on every attempt (retrying cannot help).
_PERMANENT_OS_ERRORS = (FileNotFoundError, PermissionError, NotADirectoryError,
                        IsADirectoryError, FileExistsError)
#: errno values with the same meaning: no permission, read-only file system, disk/quota full,
#: name too long.
_PERMANENT_ERRNOS = frozenset({errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOSPC,
                               errno.EDQUOT, errno.ENAMETOOLONG, errno.ENOTDIR, errno.EISDIR})
#: errno values of a full disk or quota
_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})


def is_transient_io_error(exc: BaseException) -> bool:
    """True if ``exc`` is an I/O error that may succeed when tried again (a timeout, a dropped
    connection, a remote store's 5xx as ``OSError``); False for everything else, including
    local file-system errors that repeat on every attempt (permission denied, read-only file
    system, disk full, a file where a folder should be, a missing file) and non-I/O errors
    (schema, value, type errors).

    The one rule behind both :meth:`FileRoot.retrying` and the Prefect task retries of storage
    I/O (:mod:`sim2radar.tasks.common`).
    """
    if not isinstance(exc, OSError) or isinstance(exc, _PERMANENT_OS_ERRORS):
        return False
    return exc.errno not in _PERMANENT_ERRNOS


class FileRoot:
    """A folder on a local or fsspec file system, written through retried, atomic operations.

    Parameters
    ----------
    root : str or Path
        Local folder (created on first write) or URI such as ``s3://bucket/prefix`` or
        ``memory://store``.
    io_retries : int, optional
        Retries of a failed remote I/O operation (default 3 for remote file systems, 0 local).
    retry_backoff_s : float
        First backoff delay [s]; doubles on each retry.
    compression : str
        Parquet codec of :meth:`publish` (``zstd`` by default).
    storage_options : mapping, optional
        Passed to fsspec (credentials, endpoint URLs, ...).
    """

    def __init__(
        self,
        root: str | os.PathLike,
        *,
        io_retries: int | None = None,
        retry_backoff_s: float = 0.5,
        compression: str = "zstd",
        storage_options: Mapping[str, Any] | None = None,
    ) -> None:
        self.root_uri = os.fspath(root)
        self.storage_options = dict(storage_options or {})
        self.fs, base = fsspec.core.url_to_fs(self.root_uri, **self.storage_options)
        self._base = base.rstrip("/") or "/"
        self.is_local = "file" in _protocols(self.fs)
        if self.is_local:
            self._base = str(Path(self._base).resolve())
        self.io_retries = (0 if self.is_local else 3) if io_retries is None else int(io_retries)
        self.retry_backoff_s = float(retry_backoff_s)
        self.compression = compression

    # -- paths --------------------------------------------------------------------------------
    @property
    def root(self) -> str:
        """The root as a path (local) or URI."""
        if self.is_local:
            return self._base
        return self.root_uri

    def join(self, *parts: str) -> str:
        """Path of ``root/part/part/...`` inside the file system (``/``-separated)."""
        return "/".join([self._base.rstrip("/"), *parts]) if self._base != "/" else "/" + "/".join(parts)

    def location(self, path: str) -> str:
        """Human-readable location of ``path`` (local path, or ``protocol://path``)."""
        if self.is_local:
            return path
        proto = _protocols(self.fs)[0]
        return f"{proto}://{path.lstrip('/')}" if proto != "memory" else f"memory://{path}"

    # -- retries ------------------------------------------------------------------------------
    def retrying(self, what: str, fn: Callable[[], T]) -> T:
        """``fn()``, tried again ``io_retries`` times with exponential backoff when it raises a
        transient I/O error (:func:`is_transient_io_error`); ``what`` names the operation in
        the warning of each retry."""
        delay = self.retry_backoff_s
        for attempt in range(self.io_retries + 1):
            try:
                return fn()
            except (OSError, TimeoutError, ConnectionError) as exc:
                if attempt == self.io_retries or not is_transient_io_error(exc):
                    raise
                log.warning(
                    "storage: %s failed (%s); retry %d/%d in %.1f s",
                    what, exc, attempt + 1, self.io_retries, delay,
                )
                time.sleep(delay)
                delay *= 2
        raise AssertionError("unreachable")  # pragma: no cover

    # -- write --------------------------------------------------------------------------------
    def publish(self, final: str, table: pa.Table) -> None:
        """Write ``table`` as Parquet (page checksums on) to a temporary sibling of ``final``,
        then rename it into place. Not retried by itself: wrap it in :meth:`retrying`.

        Raises
        ------
        OSError
            On a full disk or quota, with a message that names ``final`` and what to do.
        """
        folder, name = final.rsplit("/", 1)
        tmp = f"{folder}/{TMP_PREFIX}{name[: -len('.parquet')]}-{uuid.uuid4().hex[:12]}.parquet"
        try:
            if self.is_local:
                os.makedirs(folder, exist_ok=True)
                with open(tmp, "wb") as fh:
                    pq.write_table(table, fh, compression=self.compression,
                                   write_page_checksum=True)
                    fh.flush()
                    os.fsync(fh.fileno())
                os.replace(tmp, final)  # atomic on POSIX within one file system
            else:
                self.fs.makedirs(folder, exist_ok=True)
                with self.fs.open(tmp, "wb") as fh:
                    pq.write_table(table, fh, compression=self.compression,
                                   write_page_checksum=True)
                self.fs.mv(tmp, final)
        except BaseException as exc:
            try:
                if self.fs.exists(tmp):
                    self.fs.rm(tmp)
            except Exception:  # noqa: BLE001 - best effort; the tmp name is ignored anyway
                log.warning("storage: could not remove partial file %s", tmp)
            if isinstance(exc, OSError) and exc.errno in _FULL_ERRNOS and final not in str(exc):
                # Arrow's own message for a full disk names no file
                raise type(exc)(exc.errno, f"{exc.strerror or exc} while writing {final}: free "
                                "space on that disk (or raise the quota), or choose another "
                                "store folder; rerun and the finished work is kept",
                                final) from exc
            raise

    # -- quarantine ---------------------------------------------------------------------------
    def quarantine(self, path: str, reason: str) -> str | None:
        """Move the file at ``path`` (inside the root) to ``quarantine/<same relative path>.<UTC
        time>`` with a ``.why.txt`` beside it; returns the new location (None when another
        process moved or replaced it first). Nothing is deleted."""
        rel = path[len(self._base):].lstrip("/") if path.startswith(self._base) else \
            path.rsplit("/", 1)[-1]
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
        dest = self.join(QUARANTINE, f"{rel}.{stamp}-{uuid.uuid4().hex[:6]}")
        try:
            self.fs.makedirs(dest.rsplit("/", 1)[0], exist_ok=True)
            self.fs.mv(path, dest)
        except FileNotFoundError:
            return None
        with self.fs.open(f"{dest}.why.txt", "wb") as fh:
            fh.write(f"{path}\n{reason}\n".encode())
        log.warning("storage: %s does not verify (%s); moved to %s; it is recomputed when next needed",
                    path, reason, dest)
        return dest

    def quarantined(self) -> list[str]:
        """Files moved aside by :meth:`quarantine` (their ``.why.txt`` notes not listed)."""
        folder = self.join(QUARANTINE)
        if not self.fs.exists(folder):
            return []
        return sorted(p for p in self.fs.find(folder) if not p.endswith(".why.txt"))


def _protocols(fs) -> tuple[str, ...]:
    proto = fs.protocol
    return (proto,) if isinstance(proto, str) else tuple(proto)
