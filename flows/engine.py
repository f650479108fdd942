"""The Prefect side of the seam :mod:`sim2radar.tasks.runner`: :class:`PrefectRunner` runs a
job's units of work as Prefect tasks and each unit's steps (render, depth, segments,
materials, scene, poses, simulate) as nested tasks that end **Cached** when their artifact
already existed, so the UI shows per unit which step ran, was cached, retried or failed.

    @flow(name="simulate-dataset")
    def simulate_dataset(request: SimulateRequest) -> dict:
        return finish_run(simulate_scenes(request, PrefectRunner(request.run)), "scenes")

The units run on the task runner of :func:`sim2radar.flows.runners.task_runner` (a thread
pool, or a Dask cluster) that :meth:`PrefectRunner.run` opens for them; they are gathered as
they finish: each outcome recorded in the manifest (:func:`record_task`, retried on transient
storage errors only), logged, counted on a progress artifact and reported on the job's
progress channel (:mod:`sim2radar.flows._progress`). Steps run inside their unit's task
(nested task runs, in that worker), so their arguments never leave the process. Only
``materials`` is retried (backoff 2 s, 8 s) and only on network errors (the VLM server);
deterministic and local-I/O failures fail at once.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import Any

from prefect import get_run_logger, task
from prefect.cache_policies import NO_CACHE
from prefect.futures import as_completed
from prefect.states import Completed, State

from sim2radar.flows import _progress
from sim2radar.tasks.common import (
    REMOTE_IO_RETRIES,
    REMOTE_IO_RETRY_DELAYS_S,
    Outcome,
    open_store,
    record,
    retry_transient_io,
)
from sim2radar.tasks.runner import RunOptions, Units, error_text

__all__ = ["STEP_NAMES", "PrefectRunner", "PrefectPool", "run_as_tasks", "record_task",
           "call_task"]

#: Every step's task name (the Prefect UI's task names).
STEP_NAMES = ("render", "depth", "segments", "materials", "scene", "poses", "simulate")


def _network_error(task, task_run, state) -> bool:
    """Retry condition of the materials step: only errors of talking to a server (the VLM)."""
    import urllib.error

    try:
        state.result()
    except (ConnectionError, TimeoutError, urllib.error.URLError):
        return True
    except Exception:  # noqa: BLE001 - anything else is deterministic: do not retry
        return False
    return False


def _as_state(result):
    """A step's return value as a Prefect state: ``Cached`` when its artifact existed (a result
    with ``status == "skipped"``)."""
    if getattr(result, "status", None) == "skipped":
        what = getattr(result, "stage", "") or type(result).__name__
        return Completed(name="Cached", message=f"{what}: artifact exists", data=result)
    return result


def _step_task(stage: str, **options):
    def step(fn: Callable, args: tuple):
        return _as_state(fn(*args))

    step.__name__ = f"{stage}_step"
    return task(name=stage, cache_policy=NO_CACHE, persist_result=False, **options)(step)


_TASKS = {stage: _step_task(stage) for stage in STEP_NAMES if stage != "materials"}
_TASKS["materials"] = _step_task("materials", retries=2, retry_delay_seconds=[2.0, 8.0],
                                 retry_condition_fn=_network_error)


def run_as_tasks(prefix: str):
    """A step runner ``run(stage, fn, *args, label="")`` (:data:`sim2radar.tasks.runner.StepRun`)
    that calls ``fn(*args)`` as the step's Prefect task, named ``<prefix>-<stage>[-<label>]``;
    a failed step raises its error, a cached one returns its result."""

    def run(stage: str, fn: Callable, *args, label: str = "") -> Any:
        suffix = f"-{label}" if label else ""
        state = _TASKS[stage].with_options(task_run_name=f"{prefix}-{stage}{suffix}")(
            fn, args, return_state=True)
        result = state.result()  # raises the step's error when it failed
        return result.result() if isinstance(result, State) else result  # a Cached state

    return run


@task(name="record-manifest", cache_policy=NO_CACHE, retries=REMOTE_IO_RETRIES,
      retry_delay_seconds=REMOTE_IO_RETRY_DELAYS_S, retry_condition_fn=retry_transient_io,
      persist_result=False)
def record_task(store: str, dataset: str, outcome: Outcome) -> list[dict]:
    """Prefect task around :func:`~sim2radar.tasks.common.record` (retried, but only on
    transient storage errors: the work itself is deterministic and never retried)."""
    return record(store, dataset, outcome)


def _run_unit(work: Callable[[Any, Callable], Outcome], item: Any, prefix: str) -> Outcome:
    """One unit of a job, in its task: ``work(item, run_as_tasks(prefix))``, its steps nested
    tasks named ``<prefix>-<stage>[-<label>]``."""
    return work(item, run_as_tasks(prefix))


def _log_outcome(what: str, outcome: Outcome) -> None:
    logger = get_run_logger()
    name = f"{what} {outcome.id}".strip()
    if outcome.status == "failed":
        logger.error("%s FAILED: %s", name, outcome.error)
    elif outcome.parts:
        logger.info("%s: %s, %d frames", name, outcome.status, len(outcome.parts))
    else:
        logger.info("%s: %s", name, outcome.status)


class PrefectRunner:
    """:class:`sim2radar.tasks.runner.Runner` for a flow body: the units as Prefect tasks on
    ``options``' task runner (:class:`~sim2radar.tasks.runner.RunOptions`: threads, or Dask),
    gathered as they finish with a progress artifact; tables as table artifacts."""

    def __init__(self, options: RunOptions | None = None) -> None:
        self.options = options or RunOptions()

    def run(self, units: Units) -> list[Outcome]:
        """Each unit a task on a :class:`PrefectPool` (no retries: the work is deterministic,
        and a failing step already says which step failed); as each finishes its outcome (a
        unit that raised: ``units.failed``) is recorded in the manifest (:func:`record_task`),
        logged and reported."""
        open_store(units.store).manifest(units.dataset)  # validates the name before any work
        total, done = len(units.items), {}
        with self.pool(units.job, units.dataset, total) as pool:
            for i, item in enumerate(units.items):
                name = units.name(item)
                pool.submit(i, _run_unit, units.work, item, name, task=units.task, name=name)
            for i, result, error in pool.finished():
                outcome = result if error is None and isinstance(result, Outcome) else (
                    units.failed(units.items[i], error or repr(result)))
                record_task(units.store, units.dataset, outcome)
                _log_outcome(units.what, outcome)
                done[i] = outcome
                pool.report(outcome, len(done), total)
        return [done[i] for i in range(total)]

    def pool(self, job: str, name: str, total: int, options: RunOptions | None = None,
             resources: dict[str, int] | None = None):
        """A :class:`PrefectPool` on ``options``' task runner (default the runner's)."""
        return PrefectPool(job, name, total, options or self.options, resources)

    def publish(self, job: str, name: str, what: str, *, description: str,
                table: list[dict[str, Any]] | None = None,
                markdown: str | None = None) -> None:
        from prefect.artifacts import create_markdown_artifact, create_table_artifact

        key = _progress.artifact_key(job, name, what)
        if table is not None:
            create_table_artifact(table=table, key=key, description=description)
        if markdown is not None:
            create_markdown_artifact(markdown=markdown, key=key, description=description)


@task(cache_policy=NO_CACHE, retries=0, persist_result=False)
def call_task(fn: Callable[..., Any], args: tuple) -> Any:
    """One task of a :class:`PrefectPool` (named after the pool's ``task``): ``fn(*args)``."""
    return fn(*args)


class PrefectPool:
    """:class:`sim2radar.tasks.runner.TaskPool` in a flow: tasks on the task runner of
    ``options`` (threads or Dask), each claiming ``resources`` of a Dask worker; a progress
    artifact ``<job>-<name>-progress`` moves as :meth:`report` is called and the job's progress
    channel hears each finished unit."""

    def __init__(self, job: str, name: str, total: int, options: RunOptions,
                 resources: dict[str, int] | None) -> None:
        self.job, self.name, self.total = job, name, total
        self.options, self.resources = options, resources
        self.pending: dict[Any, Any] = {}

    def __enter__(self) -> PrefectPool:
        from prefect.artifacts import create_progress_artifact

        from sim2radar.flows.runners import task_runner

        self.progress_id = create_progress_artifact(
            progress=0.0, key=_progress.artifact_key(self.job, self.name, "progress"),
            description=f"{self.job} {self.name}: finished of {self.total}")
        self._engine = task_runner(self.options.workers, self.options.dask_address)
        self.engine = self._engine.__enter__()
        return self

    def __exit__(self, *exc_info) -> None:
        self._engine.__exit__(*exc_info)

    def submit(self, key: Any, fn: Callable[..., Any], *args: Any, task: str,
               name: str, priority: int = 0) -> None:
        one = call_task.with_options(name=task, task_run_name=name)
        with self._claim(priority):
            fut = self.engine.submit(one, {"fn": fn, "args": args})
        self.pending[fut] = key

    def _claim(self, priority: int):
        """Dask annotations of a task: the worker resources it claims, its priority."""
        notes = {"resources": dict(self.resources)} if self.resources else {}
        if self.options.dask_address and priority:
            notes["priority"] = int(priority)
        if not notes:
            return contextlib.nullcontext()
        import dask

        return dask.annotate(**notes)

    def finished(self):
        while self.pending:
            fut = next(iter(as_completed(list(self.pending))))
            key = self.pending.pop(fut)
            result = fut.result(raise_on_failure=False)
            if isinstance(result, BaseException):
                yield key, None, error_text(result)
            elif not fut.state.is_completed():
                yield key, None, fut.state.message or repr(result)
            else:
                yield key, result, None

    def report(self, item: Any, done: int, total: int) -> None:
        from prefect.artifacts import update_progress_artifact

        update_progress_artifact(self.progress_id, 100.0 * done / max(total, 1))
        _progress.notify(self.job, item)
