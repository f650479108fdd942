"""How a job's units of work run: the one seam between the factory's jobs and an engine.

Every job of the factory (simulate scene files, generate worlds, reconstruct images, generate
a dataset, a capture folder, the reference dataset) is one *driver* in :mod:`sim2radar.tasks`
— ``generate_dataset(request, runner)`` — that validates its typed request, hands its units of
work (worlds, scenes, images) to a :class:`Runner` and summarises what came back. The runner
decides how the units run:

* :class:`PlainRunner` (here): one after another in this process, no Prefect import
  (``sim2radar simulate --no-prefect``, notebooks, tests);
* :class:`sim2radar.flows.engine.PrefectRunner`: each unit a Prefect task on a thread pool or
  a Dask cluster, each of its steps a nested task that ends **Cached** when its artifact
  existed, progress and table artifacts in the UI. Each flow in :mod:`sim2radar.flows` is
  ``@flow def job(request)`` calling the driver with it.

Either way a unit that raises is recorded as ``failed`` in the dataset manifest and the others
finish; outcomes come back in the order of the units.

    units = Units(job="simulate", what="scene", task="simulate-scene", items=paths,
                  work=functools.partial(simulate_one, radar="ti-mmwcas", store=root),
                  failed=failed_outcome, name=scene_task_name, store=root, dataset="demo")
    outcomes = PlainRunner().run(units)

A unit's ``work(item, run)`` gets a *step runner* ``run(stage, fn, *args, label="")``: it
calls ``fn(*args)``, directly here, as the step's Prefect task (named
``<unit>-<stage>[-<label>]``) under :class:`~sim2radar.flows.engine.PrefectRunner`.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import logging
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager
from typing import Any, Protocol

from pydantic import BaseModel, ConfigDict, Field

from sim2radar.tasks.common import Outcome, open_store, record

__all__ = ["StepRun", "call_step", "Units", "Runner", "TaskPool", "PlainRunner", "PlainPool",
           "RunOptions", "dask_installed", "error_text"]

log = logging.getLogger(__name__)

#: A step runner: ``run(stage, fn, *args, label="") -> fn(*args)``.
StepRun = Callable[..., Any]


def call_step(stage: str, fn: Callable, *args: Any, label: str = "") -> Any:
    """The plain step runner: call ``fn(*args)`` (``stage`` and ``label`` only name it)."""
    return fn(*args)


@dataclasses.dataclass(frozen=True)
class Units:
    """A job's units of work, as a :class:`Runner` runs them.

    Attributes
    ----------
    job : str — the job's name: its progress channel and the key of the artifacts it
        publishes (``generate``, ``simulate``, ``captures``, ...)
    what : str — what one unit is, for logs (``world``, ``scene``, ``frame``)
    task : str — the Prefect task name of one unit (``generate-world-dataset``)
    items : tuple — the units' identities (seeds, scene paths, image jobs, capture scenes)
    work : callable — ``work(item, run) -> Outcome``; a module-level function or a
        :func:`functools.partial` of one, so it pickles by reference to a Dask worker
    failed : callable — ``failed(item, error) -> Outcome`` for a unit that raised
    name : callable — ``name(item) -> str``, the unit's id (its manifest row, e.g.
        ``world_000003``): its task-run name and its steps' prefix
    store : str — artifact store root (path or URI) whose manifest records each outcome
    dataset : str — the manifest's name
    """

    job: str
    what: str
    task: str
    items: tuple
    work: Callable[[Any, StepRun], Outcome]
    failed: Callable[[Any, BaseException | str], Outcome]
    name: Callable[[Any], str]
    store: str
    dataset: str


class Runner(Protocol):
    """What a driver needs from an engine."""

    def run(self, units: Units) -> list[Outcome]:
        """Run every unit; record each outcome in ``units.dataset``'s manifest as it finishes
        (a unit that raised as ``units.failed(item, error)``); return the outcomes in the
        order of ``units.items``."""

    def pool(self, job: str, name: str, total: int, options: RunOptions | None = None,
             resources: dict[str, int] | None = None) -> AbstractContextManager[TaskPool]:
        """A :class:`TaskPool` for a job whose tasks depend on each other (the sweep: a
        pre-training's fine-tunings start when it finishes): ``total`` tasks expected,
        ``options`` (default the runner's) how many at once and where, ``resources`` what
        each task claims on a Dask worker (``{"GPU_RUNS": 1}``)."""

    def publish(self, job: str, name: str, what: str, *, description: str,
                table: list[dict[str, Any]] | None = None,
                markdown: str | None = None) -> None:
        """Show a table (one row per unit: seconds per step, points per frame) or a Markdown
        report where the engine shows them (Prefect artifacts keyed ``<job>-<name>-<what>``);
        a plain run has nowhere to show them and drops them."""


class TaskPool(Protocol):
    """Tasks submitted one by one and collected as they finish (:meth:`Runner.pool`)."""

    def submit(self, key: Any, fn: Callable[..., Any], *args: Any, task: str,
               name: str, priority: int = 0) -> None:
        """Run ``fn(*args)`` as a task (Prefect task name ``task``, run name ``name``);
        ``fn`` is module-level and ``args`` pickle (Dask). On Dask a waiting task of higher
        ``priority`` starts first."""

    def finished(self) -> Iterator[tuple[Any, Any, str | None]]:
        """``(key, result, error)`` of each task as it finishes (``error``: None, or
        ``"Type: message"``), including tasks submitted while iterating; ends when none is
        left."""

    def report(self, item: Any, done: int, total: int) -> None:
        """One more unit finished: the engine's progress display and the job's listeners."""


class RunOptions(BaseModel):
    """How many units run at once and where (:class:`sim2radar.flows.engine.PrefectRunner`;
    a :class:`PlainRunner` runs one at a time).

    Attributes
    ----------
    workers : int — units at once: threads, or LocalCluster processes with ``dask_address =
        "local"``
    dask_address : str or None — None (threads), ``"local"`` or a Dask scheduler address
        (``tcp://host:8786``)
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    workers: int = Field(1, ge=1)
    dask_address: str | None = None


class PlainRunner:
    """Units one after another in this process, each recorded in the manifest as it finishes
    (no Prefect import). ``on_outcome(outcome)`` is called after each (progress bars)."""

    def __init__(self, on_outcome: Callable[[Outcome], None] | None = None) -> None:
        self.on_outcome = on_outcome

    def run(self, units: Units) -> list[Outcome]:
        store = open_store(units.store)
        store.manifest(units.dataset)  # validates the name before any work
        outcomes = []
        for item in units.items:
            try:
                outcome = units.work(item, call_step)
            except Exception as exc:  # noqa: BLE001 - one broken unit must not stop the others
                # info: the outcome carries the error and the caller reports it (once)
                log.info("%s %s failed: %s: %s", units.what, units.name(item),
                         type(exc).__name__, exc)
                outcome = units.failed(item, exc)
            record(store, units.dataset, outcome)
            outcomes.append(outcome)
            if self.on_outcome is not None:
                self.on_outcome(outcome)
        return outcomes

    def pool(self, job: str, name: str, total: int, options: RunOptions | None = None,
             resources: dict[str, int] | None = None) -> AbstractContextManager[TaskPool]:
        return contextlib.nullcontext(PlainPool(self.on_outcome))

    def publish(self, job: str, name: str, what: str, *, description: str,
                table: list[dict[str, Any]] | None = None,
                markdown: str | None = None) -> None:
        return None


class PlainPool:
    """:class:`TaskPool` of a :class:`PlainRunner`: each task runs when :meth:`finished`
    reaches it, in the order submitted, in this process."""

    def __init__(self, on_outcome: Callable[[Any], None] | None = None) -> None:
        self.queue: collections.deque = collections.deque()
        self.on_outcome = on_outcome

    def submit(self, key: Any, fn: Callable[..., Any], *args: Any, task: str,
               name: str, priority: int = 0) -> None:
        self.queue.append((key, fn, args, name))

    def finished(self) -> Iterator[tuple[Any, Any, str | None]]:
        while self.queue:
            key, fn, args, name = self.queue.popleft()
            try:
                yield key, fn(*args), None
            except Exception as exc:  # noqa: BLE001 - one failed task must not stop the others
                log.info("%s failed: %s: %s", name, type(exc).__name__, exc)
                yield key, None, error_text(exc)

    def report(self, item: Any, done: int, total: int) -> None:
        if self.on_outcome is not None:
            self.on_outcome(item)


def dask_installed() -> bool:
    """True when ``prefect-dask`` and ``distributed`` are installed (``sim2radar[dask]``);
    nothing is imported."""
    import importlib.util

    return all(importlib.util.find_spec(m) is not None for m in ("distributed", "prefect_dask"))


def error_text(error: Any) -> str:
    """``"Type: message"`` of an exception; anything else as text."""
    return f"{type(error).__name__}: {error}" if isinstance(error, BaseException) else str(error)

