"""The ``sweep`` job's driver: the paper's experiment grid — pre-train on simulated radar,
fine-tune on real radar, compare with training from scratch over real-data fractions x
trials — as a resumable sweep, on any :class:`~sim2radar.tasks.runner.Runner`.

    from sim2radar.tasks.sweep import SweepRequest, run_sweep
    from sim2radar.tasks.runner import PlainRunner
    summary = run_sweep(SweepRequest(sim="data/sim", real="data/proxy_real", profile="smoke",
                                     name="demo", out="out/sweeps"), PlainRunner())

The flow :func:`sim2radar.flows.run_experiment.run_experiment` runs the same driver with
Prefect (``sim2radar sweep``; the ``sweep-on-demand`` deployment). The driver prepares the
sweep (:func:`sim2radar.tasks.experiment.prepare_sweep`: every input validated, every run
keyed, ``sweep.json`` and ``plan.json`` written) unless the request names a plan already
prepared, then hands the training runs to the runner's task pool as they become ready: the
pre-trainings and the runs from scratch at once, a pre-trained condition's runs when their
pre-training finishes (a failed pre-training fails its runs with its error); the ready job
with the longest chain of optimiser steps ahead goes first (:class:`Dispatch`), so the
full-data runs do not start last and run alone at the end. Every training run is keyed by
content (a finished run is ``skipped`` on a rerun, a run killed half-way resumes from its last
checkpoint: :mod:`sim2radar.tasks.experiment`). As runs finish, the sweep folder's
``runs.parquet``, ``pretrainings.parquet`` and ``progress.json`` are rewritten (the
dashboard's ``--serve`` mode shows them live); at the end the statistics (``stats.json``), the
results table (``results.md``) and the dashboard (``dashboard.html``) are written
(:func:`sim2radar.experiment.finish.finish_sweep`).

The sweep folder (``<out>/<name>/``)::

    sweep.json        profile, conditions, datasets (+ domain, digest), provenance
    plan.json         the prepared plan (run specs, configs, intensity matches)
    runs.parquet      one experiment_runs row per run (sim2radar.experiment.rows)
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

import heapq
import logging
from collections.abc import Callable
from datetime import UTC, datetime
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from sim2radar.experiment.documents import SweepProgress
from sim2radar.experiment.folder import SweepFolder
from sim2radar.experiment.plan import PlannedPretrain, PretrainResult, SweepPlan
from sim2radar.tasks.experiment import (
    failed_pretrain_row,
    failed_row,
    parse_runs_per_gpu,
    prepare_sweep,
    read_plan,
    run_finetuning,
    run_pretraining,
    write_pretrainings_table,
    write_runs_table,
)
from sim2radar.tasks.runner import Runner, RunOptions, TaskPool, dask_installed

__all__ = ["Dispatch", "SweepRequest", "run_sweep", "prepare", "slots", "sweep_options"]

log = logging.getLogger(__name__)


class SweepRequest(BaseModel):
    """One run of the ``sweep`` job.

    Attributes
    ----------
    sim, real : dataset folders (OpenPCDet custom layout) or ``store:NAME[:geometry]`` names
        of factory datasets in ``store`` (exported into the sweep folder first)
    datasets : the other conditions' datasets by role
        (:func:`sim2radar.experiment.profiles.dataset_roles`), e.g. ``{"sim-gt": ...}``
    profile : ``paper``, ``demo``, ``smoke``, a study profile or a profile YAML
    name : the sweep's folder under ``out``
    out : the sweeps' root folder
    store : artifact store root (finished runs are stored there by key)
    ablations : also run the ablation conditions (their datasets in ``datasets``)
    overrides : profile fields to replace (e.g. ``{"trials": 3}``)
    device : torch device (None: the profile's, else automatic)
    force : run ids (``baseline-f0.05-t2``) or keys to redo from scratch
    workers : training runs at once (None: the profile's ``concurrent_runs``); threads, or
        Dask processes with ``dask_address``
    dask_address : None (threads), ``"local"`` or a Dask scheduler address
    runs_per_gpu : concurrent training runs per GPU (a count or ``"auto"``: measured), on a
        CUDA device only (:func:`sweep_options`)
    plan_path : a ``plan.json`` this request was already prepared into (the CLI prepares
        first, to show the plan and start its tracker); None: the driver prepares it
    """

    model_config = ConfigDict(extra="forbid")

    sim: str
    real: str
    datasets: dict[str, str] = {}
    profile: str = "demo"
    name: str = "sweep"
    out: str = "out/sweeps"
    store: str = "out/store"
    ablations: bool = False
    overrides: dict[str, Any] | None = None
    device: str | None = None
    force: list[str] = []
    workers: int | None = Field(None, ge=1)
    dask_address: str | None = None
    runs_per_gpu: int | str | None = None
    plan_path: str | None = None


def prepare(request: SweepRequest) -> SweepPlan:
    """Validate the request's inputs and plan its sweep (writes ``sweep.json`` and
    ``plan.json``; :func:`sim2radar.tasks.experiment.prepare_sweep`)."""
    parse_runs_per_gpu(request.runs_per_gpu)
    return prepare_sweep({**request.datasets, "sim": request.sim, "real": request.real},
                         profile=request.profile, name=request.name, out=request.out,
                         store=request.store, ablations=request.ablations,
                         overrides=request.overrides, device=request.device,
                         force=request.force)


def sweep_options(plan: SweepPlan, request: SweepRequest
                  ) -> tuple[RunOptions, dict[str, int] | None]:
    """How the sweep's training runs are spread, and what each claims on a Dask worker.

    Without ``runs_per_gpu``: ``workers`` (default the profile's ``concurrent_runs``) threads,
    or Dask processes with ``dask_address``. With it (a CUDA device:
    :func:`sim2radar.tasks.experiment.pack_runs` decides and records N): N x GPUs training
    processes — a Dask ``LocalCluster`` when ``dask_address`` is ``local`` or not given and
    prefect-dask is installed (threads otherwise) — or, on a scheduler address, runs that each
    claim one ``GPU_RUNS`` unit, so workers started with ``--resources GPU_RUNS=N`` (one per
    GPU) run N at once.
    """
    if request.runs_per_gpu is None:
        workers = int(request.workers or plan.concurrent_runs)
        return RunOptions(workers=workers, dask_address=request.dask_address), None
    from sim2radar.experiment.packing import GPU_RESOURCE
    from sim2radar.tasks.experiment import pack_runs

    decision, n_gpus = pack_runs(plan, request.runs_per_gpu)
    n = decision.runs * n_gpus
    if request.dask_address and request.dask_address != "local":
        return RunOptions(workers=n, dask_address=request.dask_address), {GPU_RESOURCE: 1}
    return RunOptions(workers=n, dask_address="local" if dask_installed() else None), None


class _Tally:
    """The sweep's rows as they come in, written to the sweep folder after each."""

    def __init__(self, plan: SweepPlan, pool: TaskPool) -> None:
        self.plan, self.pool = plan, pool
        self.folder = SweepFolder(plan.context.sweep_dir)
        self.rows: dict[str, dict] = {}
        self.pretrainings: dict[str, dict] = {}

    def ordered(self) -> list[dict]:
        return sorted(self.rows.values(), key=_order)

    def write_progress(self) -> None:
        failed = sum(r["status"] == "failed" for r in self.rows.values())
        self.folder.write_progress(SweepProgress(
            total_runs=len(self.plan.runs), finished=len(self.rows), failed=failed,
            total_pretrainings=len(self.plan.pretrains),
            pretrainings_finished=len(self.pretrainings),
            updated_at=datetime.now(UTC).isoformat(timespec="seconds")))

    def pretraining(self, row: dict) -> None:
        self.pretrainings[row["pretrain_key"]] = row
        write_pretrainings_table(self.folder.root, list(self.pretrainings.values()))
        self.write_progress()   # the live page shows pre-trainings finishing before any run
        if row["status"] == "failed":
            log.error("%s FAILED: %s", row["pretrain_id"], row["error"])
        else:
            log.info("%s: %s, held-out sim AP %s, zero-shot real AP %s", row["pretrain_id"],
                     row["status"], _ap(row["heldout_ap_3d_r40_iou03"]),
                     _ap(row["zero_shot_ap_3d_r40_iou03"]))

    def run(self, row: dict) -> None:
        self.rows[row["run_key"]] = row
        write_runs_table(self.folder.root, self.ordered())
        self.write_progress()
        self.pool.report(row, len(self.rows), len(self.plan.runs))
        if row["status"] == "failed":
            log.error("%s fraction %.2f trial %d FAILED: %s", row["condition"],
                      row["fraction"], row["trial"], row["error"])
        else:
            log.info("%s fraction %.2f trial %d: %s, 3D AP@0.3 (R40) %.1f", row["condition"],
                     row["fraction"], row["trial"], row["status"], row["ap_3d_r40_iou03"])


def run_sweep(request: SweepRequest, runner: Runner) -> dict[str, Any]:
    """The ``sweep`` job (see the module docstring): prepare (or read) the plan, train every
    run on ``runner``'s task pool, write the tables, statistics, report and dashboard.

    Returns
    -------
    dict — :func:`sim2radar.experiment.finish.finish_sweep`'s summary without its Markdown
    and table rows (published through the runner): ``name``, ``sweep_dir``, ``counts`` (runs
    by status), ``metric``, ``stats``, ``results_md``, ``dashboard``.

    Raises
    ------
    ValueError, FileNotFoundError, DatasetError — a bad input (naming the dataset, profile or
        field), before any training.
    """
    from sim2radar.experiment.cost import chain_steps, plan_jobs  # torch: not at import
    from sim2radar.experiment.finish import finish_sweep

    plan = read_plan(request.plan_path) if request.plan_path else prepare(request)
    ctx = plan.context
    options, resources = sweep_options(plan, request)
    with runner.pool("sweep", plan.name, len(plan.runs), options, resources) as pool:
        tally = _Tally(plan, pool)
        queue = Dispatch(pool, chain_steps(plan_jobs(plan)), slots(options))

        def finetune(run, pretrain: PretrainResult | None) -> None:
            queue.add((run, pretrain), run_finetuning, ctx, run, pretrain,
                      task="finetune-and-test", name=run.id)

        for p in plan.pretrains:
            queue.add((p, None), run_pretraining, ctx, p, task="pretrain-encoder", name=p.id)
        for r in plan.runs:   # the runs from scratch are ready at once
            if r.pretrain_id is None:
                finetune(r, None)
        queue.fill()
        for (job, pretrain), result, error in pool.finished():
            queue.done()
            if not isinstance(job, PlannedPretrain):
                tally.run(result if error is None else failed_row(ctx, job, pretrain, error))
            else:
                tally.pretraining(result.row if error is None and result.row
                                  else failed_pretrain_row(ctx, job, error or "no check"))
                for r in plan.runs_after(job):   # a pre-training's runs are ready when it ends
                    if error is None:
                        finetune(r, result)
                    else:
                        tally.run(failed_row(ctx, r, PretrainResult(key=job.key, checkpoint="",
                                                                    n_frames=0),
                                             f"pre-training {job.id} failed: {error}"))
            queue.fill()
    summary = finish_sweep(plan, tally.ordered(), list(tally.pretrainings.values()))
    runner.publish("sweep", plan.name, "results", table=summary["table_rows"],
                   description=f"sweep {plan.name}: {summary['metric']} per cell")
    runner.publish("sweep", plan.name, "summary", markdown=summary["markdown"],
                   description=f"sweep {plan.name}: results")
    log.info("sweep %s: %s runs; results %s; dashboard %s", plan.name, summary["counts"],
             summary["results_md"], summary["dashboard"])
    return {k: v for k, v in summary.items() if k not in ("markdown", "table_rows")}


def slots(options: RunOptions) -> int | None:
    """Training runs the sweep hands its pool at once: the pool's ``workers`` for threads and
    a local Dask cluster (so a job that becomes ready later can still start before the
    shorter ones ready earlier); None (every ready job at once, ordered by Dask priority) for a
    scheduler address, whose workers decide how many run."""
    return options.workers if options.dask_address in (None, "local") else None


class Dispatch:
    """Ready training jobs handed to a :class:`~sim2radar.tasks.runner.TaskPool` longest chain
    of optimiser steps first (:func:`sim2radar.experiment.cost.chain_steps`; ties in the order
    made ready), at most ``slots`` in flight (None: no limit, the chain as each task's
    priority). :func:`sim2radar.experiment.cost.wall_time` replays this order.

    Call :meth:`add` for each job as it becomes ready, :meth:`fill` to hand jobs over, and
    :meth:`done` when the pool reports one finished.
    """

    def __init__(self, pool: TaskPool, chain: dict[str, int], slots: int | None) -> None:
        self.pool, self.chain, self.slots = pool, chain, slots
        self.ready: list[tuple] = []
        self.seq = self.in_flight = 0

    def add(self, key: Any, fn: Callable[..., Any], *args: Any, task: str, name: str) -> None:
        """``fn(*args)`` is ready to run (the pool's :meth:`~TaskPool.submit` arguments)."""
        heapq.heappush(self.ready, (-self.chain[name], self.seq, key, fn, args, task, name))
        self.seq += 1

    def fill(self) -> None:
        """Hand the longest ready jobs to the pool while it has a free slot."""
        while self.ready and (self.slots is None or self.in_flight < self.slots):
            neg, _, key, fn, args, task, name = heapq.heappop(self.ready)
            self.pool.submit(key, fn, *args, task=task, name=name, priority=-neg)
            self.in_flight += 1

    def done(self) -> None:
        """One handed-over job finished."""
        self.in_flight -= 1


def _ap(v: float | None) -> str:
    return "-" if v is None else f"{v:.1f}"


def _order(row: dict) -> tuple:
    return (str(row["condition"]), float(row["fraction"]), int(row["trial"]))

