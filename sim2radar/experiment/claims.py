"""Claims: one training run is trained by one process at a time, however many sweep processes or
Dask workers share the sweep folder.

Before a process trains a run it creates ``<sweep>/claims/<key>.json`` with ``O_CREAT |
O_EXCL`` (atomic on a local disk and on NFSv3+), holding who claimed it (host, pid, time). While
it trains, a daemon thread touches the file every ``heartbeat_s`` seconds. A second process that
finds the claim waits for the run's result instead of training it. A claim is **stale** — its
process is gone — when its pid no longer exists on this host, or (another host) when its
heartbeat is older than ``stale_after_s``; a stale claim is taken over by renaming it aside
first (only one contender's rename can succeed) and creating a fresh one. The taker resumes the
run from its last checkpoint, so a run whose worker died is finished once, not trained twice.

Every claim, takeover and release is appended to ``<sweep>/claims/events.jsonl`` (one JSON
object per line; appends of one short line are atomic on a local disk), the audit trail that
says which process trained which run.

This is the pattern of `filelock`'s SoftFileLock with a liveness check; a plain
``fcntl.flock`` would not do, because Dask workers on other hosts share the folder over NFS
where advisory locks are unreliable and a killed worker's lock must be recognisable as dead.
"""

from __future__ import annotations

import errno
import json
import os
import socket
import threading
import time
import uuid
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

__all__ = ["Claim", "ClaimTimeout", "claim_run", "read_events", "wait_and_claim"]

#: seconds between heartbeats of a held claim
HEARTBEAT_S = 5.0
#: a claim from another host without a heartbeat for this long is stale
STALE_AFTER_S = 120.0
EVENTS = "events.jsonl"


class ClaimTimeout(TimeoutError):
    """Waited longer than allowed for another process's run to finish."""


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _log(folder: Path, event: str, key: str, **extra: Any) -> None:
    line = json.dumps({"event": event, "key": key, "host": socket.gethostname(),
                       "pid": os.getpid(), "time": _now(), **extra}) + "\n"
    with open(folder / EVENTS, "a", encoding="utf-8") as fh:
        fh.write(line)


def read_events(folder: str | os.PathLike) -> list[dict[str, Any]]:
    """The claims folder's events, oldest first (a torn last line is skipped)."""
    path = Path(folder) / EVENTS
    if not path.is_file():
        return []
    out = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            out.append(json.loads(line))
        except ValueError:
            continue
    return out


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:       # exists, owned by someone else
        return True
    return True


class Claim:
    """A held claim: heartbeats until :meth:`release` (or the ``with`` block ends)."""

    def __init__(self, path: Path, key: str, token: str, heartbeat_s: float):
        self.path, self.key, self.token = path, key, token
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._beat, args=(heartbeat_s,),
                                        name=f"claim-{key[:8]}", daemon=True)
        self._thread.start()

    def _beat(self, every: float) -> None:
        while not self._stop.wait(every):
            try:
                os.utime(self.path)
            except OSError:
                return

    def release(self, outcome: str = "released") -> None:
        """Stop the heartbeat and delete the claim file (if it is still ours)."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=1.0)
        holder = _read(self.path)
        if holder is not None and holder.get("token") == self.token:
            try:
                self.path.unlink()
            except FileNotFoundError:
                pass
        _log(self.path.parent, outcome, self.key)

    def __enter__(self) -> Claim:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.release("released" if exc is None else "failed")


def _read(path: Path) -> dict[str, Any] | None:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except ValueError:            # being written: treat as held and fresh
        return {}


def _stale(path: Path, holder: dict[str, Any], stale_after_s: float) -> str | None:
    """Why the claim at ``path`` is stale, or None while its holder may be alive."""
    if holder.get("host") == socket.gethostname() and isinstance(holder.get("pid"), int):
        if not _pid_alive(holder["pid"]):
            return f"pid {holder['pid']} on {holder['host']} is gone"
        return None
    try:
        age = time.time() - path.stat().st_mtime
    except FileNotFoundError:
        return "released"
    if age > stale_after_s:
        return f"no heartbeat from {holder.get('host')} for {age:.0f} s"
    return None


def claim_run(folder: str | os.PathLike, key: str, *, stale_after_s: float = STALE_AFTER_S,
              heartbeat_s: float = HEARTBEAT_S, note: dict[str, Any] | None = None
              ) -> Claim | None:
    """Try once to claim run ``key`` in ``folder``; a :class:`Claim` or None when a live
    process holds it. A stale claim is taken over (its holder is logged)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{key}.json"
    token = uuid.uuid4().hex
    doc = {"key": key, "host": socket.gethostname(), "pid": os.getpid(), "token": token,
           "claimed_at": _now(), **(note or {})}
    for _attempt in range(3):
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            holder = _read(path)
            if holder is None:
                continue                         # released meanwhile: try again
            why = _stale(path, holder, stale_after_s)
            if why is None:
                return None
            aside = path.with_name(f"{path.name}.stale-{token}")
            try:
                os.rename(path, aside)           # only one contender wins this
            except FileNotFoundError:
                continue
            aside.unlink(missing_ok=True)
            _log(folder, "takeover", key, reason=why, previous={
                k: holder.get(k) for k in ("host", "pid", "claimed_at")})
            continue
        except OSError as exc:                   # pragma: no cover - exotic filesystems
            if exc.errno == errno.EEXIST:
                return None
            raise
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(doc, fh)
        _log(folder, "claimed", key, **(note or {}))
        return Claim(path, key, token, heartbeat_s)
    return None


def wait_and_claim(folder: str | os.PathLike, key: str, done: Callable[[], bool], *,
                   poll_s: float = 2.0, timeout_s: float | None = None,
                   stale_after_s: float = STALE_AFTER_S, heartbeat_s: float = HEARTBEAT_S,
                   note: Callable[[], dict[str, Any]] | None = None,
                   on_wait: Callable[[dict[str, Any]], None] | None = None) -> Claim | None:
    """Claim run ``key`` unless it is finished: returns None as soon as ``done()`` is true
    (before or after waiting for another process's claim), else a held :class:`Claim`, which
    the caller trains under and releases. ``done()`` is checked again after claiming, so a run
    that finished between the check and the claim is not trained twice.

    ``on_wait(holder)`` is called once when the run is found claimed by a live process.

    Raises
    ------
    ClaimTimeout — after ``timeout_s`` seconds of waiting for a live holder.
    """
    start, told = time.monotonic(), False
    while True:
        if done():
            return None
        claim = claim_run(folder, key, stale_after_s=stale_after_s, heartbeat_s=heartbeat_s,
                          note=note() if note else None)
        if claim is not None:
            if done():
                claim.release("released-finished")
                return None
            return claim
        if not told and on_wait is not None:
            on_wait(_read(Path(folder) / f"{key}.json") or {})
            told = True
        if timeout_s is not None and time.monotonic() - start > timeout_s:
            raise ClaimTimeout(f"run {key} in {folder}: still claimed by another process after "
                               f"{timeout_s:.0f} s")
        time.sleep(poll_s)
