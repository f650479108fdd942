"""One way for every command to run a job: build its typed request, pick the runner.

    summary = run_job("sim2radar.flows.simulate:simulate_dataset", simulate_scenes, request,
                      job="simulate", use_prefect=True, on_outcome=bar_update)

With Prefect the job's flow runs (each unit a task, the run visible in the UI, Failed when
work failed) and ``on_outcome`` hears each finished unit on the job's progress channel;
without (``--no-prefect``) the driver runs with a :class:`~sim2radar.tasks.runner.PlainRunner`
and Prefect is never imported. Either way the job's summary comes back.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

__all__ = ["run_job"]


def run_job(flow: str, driver: Callable[..., dict[str, Any]], request: Any, *, job: str,
            use_prefect: bool = True,
            on_outcome: Callable[[Any], None] | None = None) -> dict[str, Any]:
    """Run ``request`` through the flow ``flow`` (``"module:name"``) or, without Prefect,
    through ``driver(request, PlainRunner(on_outcome))``; return the job's summary.

    ``job`` is the driver's job name (:attr:`sim2radar.tasks.runner.Units.job`): the progress
    channel ``on_outcome`` listens on under Prefect."""
    if not use_prefect:
        from sim2radar.tasks.runner import PlainRunner

        return driver(request, PlainRunner(on_outcome))
    from sim2radar.flows import _progress
    from sim2radar.flows._states import run_flow

    module, name = flow.split(":")
    with _progress.listen(job, on_outcome or (lambda _o: None)):
        return run_flow(getattr(importlib.import_module(module), name), request=request)
