"""Task runners for the factory's flows: one thread pool, or a Dask cluster.

    from tasks.runners import task_runner
    runner = task_runner(workers=2, dask_address="local")      # LocalCluster, 2 processes
    runner = task_runner(workers=1, dask_address="tcp://10.0.0.5:8786")   # existing scheduler
    runner = task_runner(workers=1)                              # thread pool (default)
    summary = some_flow.with_options(task_runner=runner)(...)

Choice of runner
----------------
* ``dask_address=None`` -> :class:`prefect.task_runners.ThreadPoolTaskRunner` with ``workers``
  threads. Mitsuba/Dr.Jit already spreads one frame over every core, so ``workers=1`` is the
  default on one machine.
* ``dask_address="local"`` -> ``prefect_dask.DaskTaskRunner`` on a temporary
  ``distributed.LocalCluster`` with ``workers`` worker *processes* of one thread each, bound to
  127.0.0.1 (no dashboard). Each process imports Mitsuba and picks its variant itself
  (:func:`sim2radar.hardware.mitsuba_variant` runs lazily inside the radar/world/reconstruction
  code), so no Dr.Jit state crosses a process boundary.
* ``dask_address="tcp://host:8786"`` (any Dask scheduler address) -> ``DaskTaskRunner``
  connected to that scheduler; the cluster's workers must run the same checkout/venv (they
  import ``tasks``, ``storage`` and ``sim2radar``) and reach the artifact store (a shared folder
  or an object-store URI).

What crosses to a Dask worker is pickled: the tasks receive plain values only (scene paths,
store paths/URIs, specs as dicts, seeds) and return small dataclasses; arrays travel through
the artifact store, never through Dask.

``prefect-dask`` and ``distributed`` are optional (``pip install 'sim2radar[dask]'``); asking
for Dask without them raises :class:`ImportError` saying what to install.
"""

from __future__ import annotations

from typing import Any

__all__ = ["task_runner", "dask_available", "local_cluster_kwargs", "LOCAL"]

#: The ``dask_address`` value that starts a temporary local cluster.
LOCAL = "local"

_INSTALL_HINT = (
    "pip install 'sim2radar[dask]' (prefect-dask==0.3.7 and distributed), or run with the "
    "thread runner (no dask_address / no --dask)"
)


def dask_available() -> bool:
    """True when ``prefect_dask`` and ``distributed`` import."""
    try:
        import distributed  # noqa: F401
        import prefect_dask  # noqa: F401
    except ImportError:
        return False
    return True


def local_cluster_kwargs(workers: int) -> dict[str, Any]:
    """Keyword arguments for the temporary ``distributed.LocalCluster`` behind ``"local"``.

    ``workers`` processes with one thread each (a Mitsuba frame is already multi-threaded,
    and one task per process keeps each Dr.Jit/pymeshlab state private), on loopback only,
    without the Bokeh dashboard.
    """
    return {
        "n_workers": max(1, int(workers)),
        "threads_per_worker": 1,
        "processes": True,
        "host": "127.0.0.1",
        "dashboard_address": None,
    }


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


def task_runner(workers: int = 1, dask_address: str | None = None):
    """The Prefect task runner for ``workers`` and ``dask_address`` (see the module docstring).

    Parameters
    ----------
    workers : tasks run concurrently: threads (no Dask) or LocalCluster worker processes
        (``dask_address="local"``); ignored for an external scheduler (its workers decide).
    dask_address : None (thread pool), ``"local"`` or a Dask scheduler address
        (``tcp://host:8786``).

    Returns
    -------
    prefect.task_runners.ThreadPoolTaskRunner or prefect_dask.DaskTaskRunner

    Raises
    ------
    ValueError
        ``workers < 1`` or an address that is not an address.
    ImportError
        Dask asked for but ``prefect-dask``/``distributed`` are not installed.
    """
    if int(workers) < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if not dask_address:
        from prefect.task_runners import ThreadPoolTaskRunner

        return ThreadPoolTaskRunner(max_workers=int(workers))
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
    return DaskTaskRunner(address=address)
