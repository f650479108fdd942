"""What a sweep will cost before it runs (``sim2radar sweep --plan``): optimiser steps per run,
measured seconds per step, and the wall time on N workers. :func:`sweep_cost` does it all for a
prepared sweep (:func:`sim2radar.experiment.prepare.setup_sweep` and its opened datasets).

    jobs = sweep_jobs(pretrains, runs, n_sim_frames={"sim": 270}, batch_size=8)
    s = {"pretrain": measure_step_seconds(pre_cfg, sim_frames),
         "finetune": measure_step_seconds(ft_cfg, real_frames)}
    hours = wall_time(jobs, s, workers=8) / 3600

:func:`wall_time` replays the sweep flow's dispatch (:mod:`sim2radar.flows.run_experiment`): every
pre-training and every from-scratch run is queued at the start in plan order, a pre-trained
run is queued when its pre-training finishes, and each free worker takes the oldest queued
job (Dask and the thread pool both run tasks roughly first-in, first-out). Jobs last ``steps x
seconds per step`` plus an optional fixed overhead (validation and the test); the estimate
has no start-up, data loading or scheduling cost, so a real sweep takes somewhat longer.
"""

from __future__ import annotations

import dataclasses
import heapq
import math
from collections.abc import Collection, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from sim2radar.detect.precision import measure_step_seconds
from sim2radar.experiment.plan import PretrainSpec, RunSpec, plan_sweep

if TYPE_CHECKING:
    from sim2radar.experiment.prepare import SweepSetup

__all__ = ["Job", "measure_step_seconds", "sweep_cost", "sweep_jobs", "wall_time"]


@dataclasses.dataclass(frozen=True)
class Job:
    """One training job of a sweep.

    Attributes
    ----------
    name : str — the run's or pre-training's name.
    kind : str — ``"pretrain"`` or ``"finetune"``.
    steps : int — optimiser steps (epochs x ``ceil(frames / batch)``).
    after : str or None — the pre-training it waits for.
    """

    name: str
    kind: str
    steps: int
    after: str | None = None


def sweep_jobs(pretrains: Sequence[PretrainSpec], runs: Sequence[RunSpec],
               n_sim_frames: Mapping[str, int], batch_size: int) -> list[Job]:
    """The jobs of a planned sweep (:func:`~sim2radar.experiment.plan.plan_sweep`), in the
    order the flow submits them: pre-trainings, then runs.

    ``n_sim_frames``: frames of each sim dataset role that a pre-training trains on.
    """
    jobs = []
    for p in pretrains:
        if p.sim_role not in n_sim_frames:
            raise ValueError(f"{p.name}: no frame count for the {p.sim_role!r} dataset")
        jobs.append(Job(p.name, "pretrain",
                        int(p.epochs) * math.ceil(int(n_sim_frames[p.sim_role]) / batch_size)))
    for r in runs:
        jobs.append(Job(r.name, "finetune", int(r.epochs) * math.ceil(int(r.n_real) /
                                                                       batch_size),
                        r.pretrain.name if r.pretrain else None))
    return jobs


def wall_time(jobs: Sequence[Job], seconds_per_step: Mapping[str, float], workers: int,
              overhead_s: Mapping[str, float] | None = None) -> float:
    """Seconds from the first job's start to the last job's end on ``workers`` workers, each
    running one job at a time (module docstring: the flow's FIFO dispatch).

    Raises
    ------
    ValueError — a job waits for a pre-training that is not among ``jobs``.
    """
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    overhead = dict(overhead_s or {})
    names = {j.name for j in jobs}
    for j in jobs:
        if j.after is not None and j.after not in names:
            raise ValueError(f"{j.name} waits for {j.after!r}, which is not planned")

    def duration(j: Job) -> float:
        return j.steps * float(seconds_per_step[j.kind]) + float(overhead.get(j.kind, 0.0))

    queue = [j for j in jobs if j.after is None]             # FIFO of ready jobs
    waiting: dict[str, list[Job]] = {}
    for j in jobs:
        if j.after is not None:
            waiting.setdefault(j.after, []).append(j)
    free = [0.0] * workers                                    # heap of worker free times
    running: list[tuple[float, int, Job]] = []                # heap of (end, seq, job)
    now, seq, end = 0.0, 0, 0.0
    while queue or running:
        while queue and free and free[0] <= now:
            heapq.heappop(free)
            job = queue.pop(0)
            seq += 1
            heapq.heappush(running, (now + duration(job), seq, job))
        t, _, job = heapq.heappop(running)
        now = end = max(end, t)
        heapq.heappush(free, t)
        queue.extend(waiting.pop(job.name, []))
        while running and running[0][0] <= now:               # simultaneous finishes
            t2, _, j2 = heapq.heappop(running)
            heapq.heappush(free, t2)
            queue.extend(waiting.pop(j2.name, []))
    return end


def sweep_cost(setup: SweepSetup, domains: Mapping[str, Any], *,
               workers: Collection[int] = (1, 8),
               step_seconds: Mapping[str, float] | None = None) -> dict[str, Any]:
    """What a sweep would cost: its jobs, their optimiser steps, seconds per step measured here
    on the sweep's own frames with its resolved configs (or ``step_seconds`` =
    ``{"pretrain": s, "finetune": s}``, e.g. a GPU's figures), and the expected wall time on
    each of ``workers`` worker counts (:func:`sim2radar.experiment.cost.wall_time`).

    Returns ``profile``, ``device``, ``precision`` (amp per stage), ``threads_per_run``,
    ``jobs`` (kind -> count, steps), ``step_seconds``, ``measured`` (whether timed here),
    ``compute_hours`` and ``wall_hours`` (workers -> hours).
    """
    profile, device, (pre_cfg, ft_cfg) = setup.profile, setup.device, setup.configs
    domains = {role: domains[role] for role in setup.roles}
    real = domains["real"]
    train_ids = real.splits.get(profile.train_split) or []
    if not train_ids:
        raise ValueError(f"{real.root}/ImageSets/{profile.train_split}.txt lists no frame")
    pretrains, runs = plan_sweep(profile, train_ids, setup.conditions)
    held = profile.pretrain_holdout_split     # held out of every pre-training
    n_sim = {role: len(set(ds.ids()) - set(ds.ids([held]) if held else ()))
             for role, ds in domains.items() if role != "real"}
    jobs = sweep_jobs(pretrains, runs, n_sim, profile.batch_size)
    measured = step_seconds is None
    if measured:
        n = 3 * profile.batch_size
        nfeat, classes = ft_cfg.model.num_point_features, ft_cfg.model.class_names
        sec = {"finetune": measure_step_seconds(
            ft_cfg, real.frames(train_ids[:n], nfeat, classes), device=device)}
        if pretrains:
            sim = domains[pretrains[0].sim_role]
            sec["pretrain"] = measure_step_seconds(
                pre_cfg, sim.frames(sim.ids()[:n], nfeat, classes), device=device)
    else:
        sec = {k: float(v) for k, v in step_seconds.items()}
        missing = {j.kind for j in jobs} - set(sec)
        if missing:
            raise ValueError(f"step_seconds lacks {sorted(missing)} (give pretrain and "
                             "finetune seconds per step)")
    by_kind = {k: {"jobs": sum(j.kind == k for j in jobs),
                   "steps": sum(j.steps for j in jobs if j.kind == k)}
               for k in ("pretrain", "finetune")}
    compute_s = sum(j.steps * sec[j.kind] for j in jobs)
    return {"profile": profile.name, "device": device or str(ft_cfg.runtime.device or "auto"),
            "precision": {"pretrain": pre_cfg.runtime.amp, "finetune": ft_cfg.runtime.amp},
            "threads_per_run": profile.threads_per_run, "jobs": by_kind, "step_seconds": sec,
            "measured": measured, "compute_hours": compute_s / 3600,
            "wall_hours": {int(n): wall_time(jobs, sec, int(n)) / 3600 for n in workers}}
