"""What a sweep will cost before it runs: optimiser steps per run, measured seconds per step, and
the wall time on N workers.

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
from collections.abc import Mapping, Sequence

from sim2radar.detect.precision import measure_step_seconds
from sim2radar.experiment.plan import PretrainSpec, RunSpec

__all__ = ["Job", "measure_step_seconds", "sweep_jobs", "wall_time"]


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
