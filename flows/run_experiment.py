"""Flow: the paper's experiment grid as a resumable sweep (:mod:`sim2radar.tasks.sweep`), run
with :class:`~sim2radar.flows.engine.PrefectRunner`.

    from sim2radar.flows._states import run_flow
    from sim2radar.flows.run_experiment import run_experiment
    from sim2radar.tasks.sweep import SweepRequest
    summary = run_flow(run_experiment, request=SweepRequest(
        sim="data/sim", real="data/proxy_real", profile="demo", name="demo", out="out/sweeps"))

Every training run is its own Prefect task (``pretrain-encoder``, ``finetune-and-test``,
named by the run's id) on the task runner the request asks for (threads, a local Dask
cluster or a scheduler address; runs packed onto GPUs with ``runs_per_gpu``); a progress
artifact moves as runs finish, and the results table and report are published as a table and
a Markdown artifact. The run ends **Failed** in Prefect when any run or pre-training failed;
the summary rides on the state (:func:`~sim2radar.flows._states.run_flow` returns it). It is
also the ``sweep-on-demand`` deployment's entrypoint.
"""

from __future__ import annotations

from typing import Any

from prefect import flow

from sim2radar.flows._states import finish
from sim2radar.flows.engine import PrefectRunner
from sim2radar.tasks.sweep import SweepRequest, run_sweep

__all__ = ["run_experiment", "SweepRequest"]


@flow(name="run-experiment", log_prints=False)
def run_experiment(request: SweepRequest) -> dict[str, Any]:
    """Prepare (unless ``request.plan_path`` names a prepared plan) and run a sweep
    (:func:`sim2radar.tasks.sweep.run_sweep`); ends Failed when a run failed."""
    summary = run_sweep(request, PrefectRunner())
    counts = summary["counts"]
    return finish(summary, failed=counts["failed"], total=sum(counts.values()), unit="runs",
                  detail=f" (sweep {summary['name']})")
