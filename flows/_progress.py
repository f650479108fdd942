"""Progress callbacks from a running flow to its caller (progress bars in the CLI), and the keys
of the artifacts flows publish in Prefect (progress, tables).

Each flow module has its own channel. A flow body reports an outcome with
``notify(channel, outcome)``; a caller listens with ``with listen(channel, fn): ...``. Flows call
these module-level functions rather than touching the registry: a task runner that ships the
flow run context to other processes (Dask) pickles the flow function *by value* with the globals
it names, and a registered callback (a closure over a Rich progress bar, with locks) would not
pickle, while a function of an importable module pickles by reference.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

_LISTENERS: dict[str, list[Callable[[Any], None]]] = {}


@contextmanager
def listen(channel: str, fn: Callable[[Any], None]) -> Iterator[None]:
    """Call ``fn(outcome)`` in this process for every outcome reported on ``channel``."""
    _LISTENERS.setdefault(channel, []).append(fn)
    try:
        yield
    finally:
        _LISTENERS[channel].remove(fn)


def notify(channel: str, outcome: Any) -> None:
    """Report one finished unit of work (a scene, a world) to the listeners of ``channel``."""
    for fn in list(_LISTENERS.get(channel, ())):
        fn(outcome)


def artifact_key(*parts: str) -> str:
    """A Prefect artifact key from ``parts`` (lowercase letters, digits and dashes, at most
    100 characters), e.g. ``artifact_key("sweep", name, "progress")``."""
    import re

    return re.sub(r"[^a-z0-9-]+", "-", "-".join(parts).lower()).strip("-")[:100]
