"""Task runners for the factory's flows: one thread pool, or a Dask cluster.

    from sim2radar.flows.runners import task_runner
    runner = task_runner(workers=2, dask_address="local")      # LocalCluster, 2 processes
    runner = task_runner(workers=1, dask_address="tcp://10.0.0.5:8786")   # existing scheduler
    runner = task_runner(workers=1)                              # thread pool (default)
    summary = some_flow.with_options(task_runner=runner)(...)

Choice of runner
----------------
* ``dask_address=None`` -> :class:`ThreadRunner` (Prefect's thread pool that does not wait for
  running tasks when the flow is interrupted by SIGTERM or Ctrl-C) with ``workers`` threads.
  Mitsuba/Dr.Jit already spreads one frame over every core, so ``workers=1`` is the default on
  one machine.
* ``dask_address="local"`` -> ``prefect_dask.DaskTaskRunner`` on a temporary
  ``distributed.LocalCluster`` with ``workers`` worker *processes* of one thread each, bound to
  127.0.0.1 (no dashboard). Each process imports Mitsuba and picks its variant itself
  (:func:`sim2radar.hardware.mitsuba_variant` runs lazily inside the radar/world/reconstruction
  code), so no Dr.Jit state crosses a process boundary.
* ``dask_address="tcp://host:8786"`` (any Dask scheduler address) -> ``DaskTaskRunner``
  connected to that scheduler; the cluster's workers must run in an environment where the same
  sim2radar is installed (they import ``sim2radar.tasks`` and ``sim2radar.storage``) and reach
  the artifact store (a shared folder or an object-store URI).

What crosses to a Dask worker is pickled: the tasks receive plain values and specs only (scene
paths, store paths/URIs, a DatasetSpec, seeds) and return small :class:`Outcome` records;
arrays travel through the artifact store, never through Dask.

For an external scheduler :func:`check_dask_workers` probes every worker first and says how to
start them. (Dask's spill folder on a worker is called ``storage``; when the store package was
the top-level ``storage`` that folder could hide it. As ``sim2radar.storage`` it cannot.)

``prefect-dask`` and ``distributed`` are optional (``pip install 'sim2radar[dask]'``); asking
for Dask without them raises :class:`ImportError` saying what to install.
"""

from __future__ import annotations

from typing import Any

from prefect.task_runners import ThreadPoolTaskRunner

__all__ = ["task_runner", "ThreadRunner", "local_cluster_kwargs",
           "check_dask_workers", "LOCAL"]

#: The ``dask_address`` value that starts a temporary local cluster.
LOCAL = "local"

_INSTALL_HINT = (
    "pip install 'sim2radar[dask]' (prefect-dask==0.3.7 and distributed), or run with the "
    "thread runner (no dask_address / no --dask)"
)


class ThreadRunner(ThreadPoolTaskRunner):
    """Prefect's thread pool, except that a flow interrupted from outside (SIGTERM, which
    Prefect raises as ``TerminationSignal`` in the main thread, or Ctrl-C) does not wait for
    the tasks still running before it reports the flow run ``Crashed`` and the process
    exits.

    Prefect's pool waits for every running task when the flow ends, also when it ends on
    SIGTERM: a world or capture scene then ran to its end (seconds to minutes) before the
    process went, past a scheduler's grace period (Kubernetes: 30 s, then SIGKILL). Now the
    process goes within about a second. Nothing is lost by not waiting: every artifact is
    published atomically and a rerun recomputes only what is missing. A flow that ends
    normally, or on an ordinary exception, still waits for its tasks.

    It reaches into the pool's ``_executor`` and ``_cancel_events`` (Prefect 3.8.8, pinned in
    pyproject.toml); ``tests/cli/test_server.py`` fails if a Prefect upgrade changes them.
    """

    def __exit__(self, exc_type, exc_value, traceback) -> None:
        if exc_type is not None and not issubclass(exc_type, Exception):
            for event in self._cancel_events.values():
                event.set()  # tasks not yet started end Cancelled
            if self._executor is not None:
                self._executor.shutdown(wait=False, cancel_futures=True)
                self._executor = None
        super().__exit__(exc_type, exc_value, traceback)


def local_cluster_kwargs(workers: int) -> dict[str, Any]:
    """Keyword arguments for the temporary ``distributed.LocalCluster`` behind ``"local"``.

    ``workers`` processes with one thread each (a Mitsuba frame is already multi-threaded,
    and one task per process keeps each Dr.Jit/pymeshlab state private), on loopback only,
    without the Bokeh dashboard, and without a memory limit: a worker's memory is Mitsuba's,
    Dr.Jit's and PyTorch's, which Dask cannot spill, and its tasks return small records.
    """
    return {
        "n_workers": max(1, int(workers)),
        "threads_per_worker": 1,
        "processes": True,
        "host": "127.0.0.1",
        "dashboard_address": None,
        "memory_limit": 0,
    }


_PACKAGES = ("sim2radar", "sim2radar.tasks", "sim2radar.storage")


def _probe_packages() -> dict[str, str]:
    """Where each package of the project is imported from, or the import error (runs on a
    Dask worker)."""
    import importlib

    out = {}
    for name in _PACKAGES:
        try:
            mod = importlib.import_module(name)
            out[name] = getattr(mod, "__file__", None) or "namespace " + str(list(mod.__path__))
        except Exception as exc:  # noqa: BLE001 - reported back to the caller
            out[name] = f"ImportError: {type(exc).__name__}: {exc}"
    return out


def _worker_problems(address: str, probes: dict[str, dict[str, str]]) -> list[str]:
    """Human-readable problems in ``{worker: _probe_packages()}``; empty when all is well."""
    problems = []
    for worker, found in sorted(probes.items()):
        for name in _PACKAGES:
            where = found.get(name, "missing")
            if not where.endswith("__init__.py"):
                problems.append(f"{worker}: cannot import {name} ({where}): start the workers "
                                f"in an environment with sim2radar installed (`pip install "
                                f"-e .` or the wheel), e.g. `dask worker {address}` from the "
                                "flow's virtual environment")
    return problems


def check_dask_workers(address: str, timeout_s: float = 10.0) -> dict[str, dict[str, str]]:
    """Connect to the scheduler at ``address`` and check each worker imports the project.

    Returns
    -------
    dict — worker address -> {package: file it was imported from}

    Raises
    ------
    ConnectionError
        No scheduler answers at ``address`` within ``timeout_s`` [s].
    RuntimeError
        A worker cannot import a package of the project (the message says how to start the
        workers).
    """
    import distributed

    try:
        client = distributed.Client(address, timeout=timeout_s, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise ConnectionError(
            f"no Dask scheduler at {address} ({exc}); start one with `dask scheduler --host "
            "127.0.0.1` and workers with `dask worker ADDRESS` from the virtual environment "
            "sim2radar is installed in"
        ) from exc
    with client:
        try:
            probes = client.run(_probe_packages) if client.scheduler_info()["workers"] else {}
        except Exception as exc:  # noqa: BLE001 - e.g. the workers cannot import sim2radar
            raise RuntimeError(
                f"Dask workers at {address} cannot run sim2radar code ({type(exc).__name__}: "
                f"{exc}); start them from the virtual environment sim2radar is installed in: "
                f"`dask worker {address}`") from exc
    problems = _worker_problems(address, probes)
    if problems:
        raise RuntimeError("Dask workers cannot run sim2radar tasks:\n" + "\n".join(problems))
    return probes


def _check_address(dask_address: str) -> str:
    address = str(dask_address).strip()
    if address == LOCAL:
        return address
    if "://" not in address and ":" not in address:
        raise ValueError(
            f"dask_address={dask_address!r} is neither 'local' nor a scheduler address; give "
            "e.g. 'tcp://127.0.0.1:8786' (printed by `dask scheduler`) or 'local'"
        )
    return address


def task_runner(workers: int = 1, dask_address: str | None = None, *, check: bool = True):
    """The Prefect task runner for ``workers`` and ``dask_address`` (see the module docstring).

    Parameters
    ----------
    workers : tasks run concurrently: threads (no Dask) or LocalCluster worker processes
        (``dask_address="local"``); ignored for an external scheduler (its workers decide).
    dask_address : None (thread pool), ``"local"`` or a Dask scheduler address
        (``tcp://host:8786``).
    check : for a scheduler address, probe its workers first (:func:`check_dask_workers`).

    Returns
    -------
    prefect.task_runners.ThreadPoolTaskRunner or prefect_dask.DaskTaskRunner

    Raises
    ------
    ValueError
        ``workers < 1`` or an address that is not an address.
    ImportError
        Dask asked for but ``prefect-dask``/``distributed`` are not installed.
    ConnectionError, RuntimeError
        See :func:`check_dask_workers`.
    """
    if int(workers) < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if not dask_address:
        return ThreadRunner(max_workers=int(workers))
    address = _check_address(dask_address)
    try:
        import distributed  # noqa: F401
        from prefect_dask import DaskTaskRunner
    except ImportError as exc:
        raise ImportError(
            f"dask_address={dask_address!r} needs the Dask task runner: {_INSTALL_HINT} "
            f"(import failed: {exc})"
        ) from exc
    if address == LOCAL:
        return DaskTaskRunner(cluster_class="distributed.LocalCluster",
                              cluster_kwargs=local_cluster_kwargs(workers))
    if check:
        check_dask_workers(address)
    return DaskTaskRunner(address=address)
