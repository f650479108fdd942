"""Flow: the paper's experiment grid — pre-train on simulated radar, fine-tune on real radar,
compare with training from scratch over real-data fractions × trials — as a resumable sweep.

    from sim2radar.flows.run_experiment import run_experiment
    summary = run_experiment("data/sim", "data/proxy_real", profile="demo", name="demo",
                             out="out/sweeps")

Every training run is its own Prefect task (:func:`pretrain_task`, :func:`finetune_task`
around :mod:`sim2radar.tasks.experiment`'s plain functions) keyed by content: a
finished run is ``skipped`` on a rerun, a run killed half-way resumes from its last checkpoint,
and a pre-training shared by several cells runs once (per trial seed with the profile's
``pretrain_per_trial``). Baseline runs start at once; a pre-trained condition's runs start when
their pre-training finishes. Runs fan out over the factory's task runners (threads, Dask local
or a scheduler address). As runs finish, the sweep folder's ``runs.parquet`` and
``progress.json`` are rewritten (the dashboard's ``--serve`` mode shows them live) and a Prefect
progress artifact moves; at the end the statistics (``stats.json``), the results table
(``results.md``, a Prefect table + markdown artifact) and the dashboard (``dashboard.html``)
are written.

The sweep folder (``<out>/<name>/``)::

    sweep.json        profile, conditions, datasets (+ domain, digest), provenance
    plan.json         the prepared plan the flow runs (run specs, configs, intensity matches)
    runs.parquet      one experiment_runs row per run (storage/schemas.py)
    pretrainings.parquet  one experiment_pretrain row per pre-training: its check (held-out
                      sim AP, zero-shot real AP, AP on its training frames) and loss curve
    preregistration.md    the study's pre-registration, when its profile declares one
    progress.json     total / finished / failed runs
    stats.json        paired statistics (sim2radar.experiment.stats)
    results.md        Table-1-style results with confidence intervals
    dashboard.html    the offline dashboard
    pretrain/<key>/   pre-training checkpoints;  runs/<key>/   fine-tuning checkpoints
"""

from __future__ import annotations

import contextlib
import importlib
import os
from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from prefect import flow, get_run_logger, task
from prefect.cache_policies import NO_CACHE
from prefect.futures import as_completed

from sim2radar.experiment.folder import SweepFolder
from sim2radar.experiment.plan import PlannedPretrain, PlannedRun, PretrainResult, SweepContext
from sim2radar.fileio import write_json
from sim2radar.flows import _progress
from sim2radar.flows._states import finish, relay, run_flow
from sim2radar.flows.runners import task_runner
from sim2radar.tasks.experiment import (
    failed_pretrain_row,
    failed_row,
    run_finetuning,
    run_pretraining,
    write_pretrainings_table,
    write_runs_table,
)

__all__ = ["run_experiment_flow", "run_experiment", "run_experiment_job", "progress_callback",
           "pretrain_task", "finetune_task"]


# --- Prefect tasks: no retries (deterministic training); caching by content key inside.
@task(name="pretrain-encoder", cache_policy=NO_CACHE, retries=0, persist_result=False)
def pretrain_task(ctx: SweepContext, job: PlannedPretrain) -> PretrainResult:
    """Prefect task around :func:`sim2radar.tasks.experiment.run_pretraining`."""
    return run_pretraining(ctx, job)


@task(name="finetune-and-test", cache_policy=NO_CACHE, retries=0, persist_result=False)
def finetune_task(ctx: SweepContext, job: PlannedRun,
                  pretrain: PretrainResult | None) -> dict[str, Any]:
    """Prefect task around :func:`sim2radar.tasks.experiment.run_finetuning`."""
    return run_finetuning(ctx, job, pretrain)


def progress_callback(fn: Callable[[dict], None]):
    """Context manager: call ``fn(row)`` in this process after each training run finishes."""
    return _progress.listen("run_experiment", fn)


@flow(name="run-experiment", log_prints=False)
def run_experiment_flow(plan_path: str, gpu_slots: bool = False) -> dict[str, Any]:
    """Run a prepared sweep — the ``plan.json`` :func:`sim2radar.tasks.experiment.prepare_sweep`
    wrote (its ``plan_path``; a paper-sized plan is over Prefect's 512 KiB limit on a flow run's
    parameters, its path is not): every pre-training and fine-tuning task, the tables,
    statistics, artifacts and dashboard. It ends Failed in Prefect when any run or
    pre-training failed (the summary rides on the state: :func:`~sim2radar.flows._states.
    run_flow` returns it).

    ``gpu_slots``: on a Dask cluster, every training task asks for one unit of the worker
    resource :data:`~sim2radar.experiment.packing.GPU_RESOURCE`; a GPU worker started with
    ``--resources GPU_RUNS=N`` then runs at most N of them at once (``--runs-per-gpu``)."""
    from prefect.artifacts import (
        create_markdown_artifact,
        create_progress_artifact,
        create_table_artifact,
        update_progress_artifact,
    )

    from sim2radar.experiment.finish import finish_sweep
    from sim2radar.tasks.experiment import read_plan

    plan = read_plan(plan_path)
    logger = get_run_logger()
    ctx, name, sweep_dir = plan.context, plan.name, Path(plan.context.sweep_dir)
    total = len(plan.runs)
    progress_id = create_progress_artifact(
        progress=0.0, key=_progress.artifact_key("sweep", name, "progress"),
        description=f"sweep {name}: finished training runs of {total}")
    rows: dict[str, dict] = {}
    pretrainings: dict[str, dict] = {}

    def write_progress() -> None:
        failed = sum(r["status"] == "failed" for r in rows.values())
        write_json(SweepFolder(sweep_dir).progress_json, {
            "total_runs": total, "finished": len(rows), "failed": failed,
            "total_pretrainings": len(plan.pretrains),
            "pretrainings_finished": len(pretrainings),
            "updated_at": datetime.now(UTC).isoformat(timespec="seconds")})

    def record_pretraining(row: dict) -> None:
        pretrainings[row["pretrain_key"]] = row
        write_pretrainings_table(sweep_dir, list(pretrainings.values()))
        write_progress()   # the live page shows pre-trainings finishing before any run
        if row["status"] == "failed":
            logger.error("%s FAILED: %s", row["pretrain_id"], row["error"])
        else:
            logger.info("%s: %s, held-out sim AP %s, zero-shot real AP %s", row["pretrain_id"],
                        row["status"], _ap(row["heldout_ap_3d_r40_iou03"]),
                        _ap(row["zero_shot_ap_3d_r40_iou03"]))

    def record(row: dict) -> None:
        rows[row["run_key"]] = row
        ordered = sorted(rows.values(), key=_order)
        write_runs_table(sweep_dir, ordered)
        write_progress()
        update_progress_artifact(progress_id, 100.0 * len(ordered) / max(total, 1))
        _progress.notify("run_experiment", row)
        if row["status"] == "failed":
            logger.error("%s fraction %.2f trial %d FAILED: %s", row["condition"],
                         row["fraction"], row["trial"], row["error"])
        else:
            logger.info("%s fraction %.2f trial %d: %s, 3D AP@0.3 (R40) %.1f",
                        row["condition"], row["fraction"], row["trial"], row["status"],
                        row["ap_3d_r40_iou03"])

    # a pre-training's runs start when it finishes; the runs from scratch start at once
    pending: dict[Any, tuple[Any, PretrainResult | None]] = {}

    def slot():
        if not gpu_slots:
            return contextlib.nullcontext()
        import dask

        from sim2radar.experiment.packing import GPU_RESOURCE

        return dask.annotate(resources={GPU_RESOURCE: 1})

    def finetune(run, pretrain: PretrainResult | None) -> None:
        with slot():
            fut = finetune_task.with_options(task_run_name=run.id).submit(ctx, run, pretrain)
        pending[fut] = (run, pretrain)

    for p in plan.pretrains:
        with slot():
            fut = pretrain_task.with_options(task_run_name=p.id).submit(ctx, p)
        pending[fut] = (p, None)
    for r in plan.runs:
        if r.pretrain_id is None:
            finetune(r, None)
    while pending:
        fut = next(iter(as_completed(list(pending))))
        job, pretrain = pending.pop(fut)
        result = fut.result(raise_on_failure=False)
        error = result if isinstance(result, BaseException) else (
            None if fut.state.is_completed() else (fut.state.message or repr(result)))
        if isinstance(job, PlannedPretrain):
            record_pretraining(result.row if error is None and result.row
                               else failed_pretrain_row(ctx, job, _text(error or "no check")))
            for r in plan.runs_after(job):
                if error is None:
                    finetune(r, result)
                else:
                    record(failed_row(ctx, r, PretrainResult(key=job.key, checkpoint="", n_frames=0),
                                      f"pre-training {job.id} failed: {_text(error)}"))
        else:
            record(result if error is None else failed_row(ctx, job, pretrain, _text(error)))

    summary = finish_sweep(plan, sorted(rows.values(), key=_order), list(pretrainings.values()))
    create_table_artifact(table=summary["table_rows"],
                          key=_progress.artifact_key("sweep", name, "results"),
                          description=f"sweep {name}: {summary['metric']} per cell")
    create_markdown_artifact(markdown=summary["markdown"],
                             key=_progress.artifact_key("sweep", name, "summary"),
                             description=f"sweep {name}: results")
    logger.info("sweep %s: %s runs; results %s; dashboard %s", name, summary["counts"],
                summary["results_md"], summary["dashboard"])
    out = {k: v for k, v in summary.items() if k not in ("markdown", "table_rows")}
    n_runs = sum(summary["counts"].values())
    return finish(out, failed=summary["counts"]["failed"], total=n_runs, unit="runs",
                  detail=f" (sweep {name})")


def _ap(v: float | None) -> str:
    return "-" if v is None else f"{v:.1f}"


def _text(error: Any) -> str:
    return f"{type(error).__name__}: {error}" if isinstance(error, BaseException) else str(error)


def _order(row: dict) -> tuple:
    return (str(row["condition"]), float(row["fraction"]), int(row["trial"]))


def run_experiment(
    sim: str | os.PathLike,
    real: str | os.PathLike,
    *,
    profile: str | os.PathLike = "demo",
    name: str = "sweep",
    out: str | os.PathLike = "out/sweeps",
    store: str | os.PathLike = "out/store",
    datasets: Mapping[str, str | os.PathLike | None] | None = None,
    ablations: bool = False,
    overrides: dict[str, Any] | None = None,
    workers: int | None = None,
    dask_address: str | None = None,
    device: str | None = None,
    force: list[str] | None = None,
    runs_per_gpu: int | str | None = None,
) -> dict[str, Any]:
    """Prepare and run a sweep (see the module docstring); configs and datasets are validated
    before the flow starts, so a bad input fails fast with the file and field named.

    Parameters
    ----------
    sim, real : dataset folders (OpenPCDet custom layout) or ``store:NAME[:geometry]`` names of
        factory datasets in ``store`` (exported into the sweep folder first).
    profile : ``paper``, ``demo``, ``smoke`` or a profile YAML.
    datasets : the other conditions' datasets by role
        (:data:`sim2radar.experiment.profiles.ROLES`), e.g. ``{"sim-gt": ...,
        "sim-one-material": ...}`` for the ablations (with ``ablations``).
    overrides : profile fields to replace (e.g. ``{"trials": 3}``).
    workers : concurrent runs (default: the profile's ``concurrent_runs``); with
        ``dask_address`` (``"local"`` or ``tcp://...``) the runs go to Dask instead of threads.
    force : run ids (``baseline-f0.05-t2``) or keys to redo from scratch (their stored rows and
        checkpoints are moved aside, not deleted).
    runs_per_gpu : concurrent training runs per GPU (a count, or ``"auto"``: measured), on a
        CUDA device only (:func:`packed_runner`).
    """
    from sim2radar.tasks.experiment import prepare_sweep

    plan = prepare_sweep({**(datasets or {}), "sim": sim, "real": real}, profile=profile,
                         name=name, out=out, store=store, ablations=ablations,
                         overrides=overrides, device=device, force=force or ())
    runner, gpu_slots = packed_runner(plan, workers, dask_address, runs_per_gpu)
    return run_flow(run_experiment_flow.with_options(task_runner=runner),
                    plan_path=plan.plan_path, gpu_slots=gpu_slots)


def packed_runner(plan, workers: int | None, dask_address: str | None,
                  runs_per_gpu: int | str | None) -> tuple[Any, bool]:
    """The sweep's task runner and whether its training tasks claim GPU slots.

    Without ``runs_per_gpu``: ``workers`` (default the profile's ``concurrent_runs``) threads,
    or Dask processes with ``dask_address``. With it (a CUDA device:
    :func:`sim2radar.tasks.experiment.pack_runs` decides and records N):
    N x GPUs training processes — a Dask ``LocalCluster`` when ``dask_address`` is ``local``
    or not given and prefect-dask is installed (threads otherwise) — or, on a scheduler
    address, tasks that each claim one ``GPU_RUNS`` unit, so workers started with
    ``--resources GPU_RUNS=N`` (one per GPU) run N at once.
    """
    if runs_per_gpu is None:
        return task_runner(int(workers or plan.concurrent_runs), dask_address), False
    from sim2radar.flows.runners import dask_available
    from sim2radar.tasks.experiment import pack_runs

    decision, n_gpus = pack_runs(plan, runs_per_gpu)
    n = decision.runs * n_gpus
    if dask_address and dask_address != "local":
        return task_runner(n, dask_address), True
    return task_runner(n, "local" if dask_available() else None), False


@flow(name="run-experiment-job", log_prints=False)
def run_experiment_job(
    sim: str,
    real: str,
    profile: str = "demo",
    name: str = "sweep",
    out: str = "out/sweeps",
    store: str = "out/store",
    datasets: dict[str, str] | None = None,
    ablations: bool = False,
    workers: int | None = None,
    dask_address: str | None = None,
    runs_per_gpu: int | str | None = None,
) -> dict[str, Any]:
    """Deployment entry point (``sim2radar deploy``): :func:`run_experiment` as a subflow
    (the package's copy, so Dask workers can import it); ``datasets``: the ablations' datasets
    by role (``{"sim-gt": ..., "sim-one-material": ...}``); ``runs_per_gpu``: a count or
    ``"auto"`` on a GPU pool."""
    package = importlib.import_module("sim2radar.flows.run_experiment")
    return relay(package.run_experiment(sim, real, profile=profile, name=name, out=out,
                                        store=store, datasets=datasets, ablations=ablations,
                                        workers=workers, dask_address=dask_address,
                                        runs_per_gpu=runs_per_gpu), "runs")
