"""What a sweep will cost before it runs (``sim2radar sweep --plan``): optimiser steps per run,
measured seconds per step, and the wall time on N workers. :func:`sweep_cost` does it all for a
prepared sweep (:func:`sim2radar.experiment.prepare.setup_sweep` and its opened datasets).

    jobs = sweep_jobs(pretrains, runs, n_sim_frames={"sim": 270}, batch_size=8)
    s = {"pretrain": measure_step_seconds(pre_cfg, sim_frames),
         "finetune": measure_step_seconds(ft_cfg, real_frames)}
    hours = wall_time(jobs, s, workers=8) / 3600

:func:`wall_time` replays the sweep's dispatch (:func:`sim2radar.tasks.sweep.run_sweep`): every
pre-training and every from-scratch run is ready at the start, a pre-trained run is ready
when its pre-training finishes, and each free worker takes the ready job with the longest
chain of optimiser steps still ahead of it (:func:`chain_steps`: its own steps plus those of
its longest waiting run; ties in plan order). Longest-first keeps the grid's long runs (the
full-data fraction's) from starting last and running alone at the end. Jobs last ``steps x
seconds per step`` plus an optional fixed overhead (validation and the test); with the
device's measured throughput by concurrent runs (``throughput=``) a job's steps go faster
while fewer runs share the device. The estimate has no start-up, data loading or scheduling
cost, so a real sweep takes somewhat longer.
"""

from __future__ import annotations

import dataclasses
import heapq
import math
from collections.abc import Collection, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from sim2radar.detect.precision import measure_step_seconds
from sim2radar.experiment.plan import PretrainSpec, RunSpec, plan_sweep

if TYPE_CHECKING:
    from sim2radar.experiment.plan import SweepPlan
    from sim2radar.experiment.prepare import SweepSetup

__all__ = ["Job", "chain_steps", "measure_step_seconds", "plan_jobs", "sim_frame_counts",
           "sweep_cost", "sweep_jobs", "wall_time"]


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


def plan_jobs(plan: SweepPlan) -> list[Job]:
    """The jobs of a prepared sweep (:class:`~sim2radar.experiment.plan.SweepPlan`), with the
    optimiser steps :func:`sweep_jobs` gives them: the sim frames each pre-training trains on
    are its dataset's planned ids less its held-out split."""
    specs = [p.spec for p in plan.pretrains]
    return sweep_jobs(specs, [r.spec for r in plan.runs],
                      sim_frame_counts(specs, plan.context.datasets),
                      plan.context.finetune_config.optimization.batch_size)


def sim_frame_counts(pretrains: Sequence[PretrainSpec], datasets: Mapping[str, Any]
                     ) -> dict[str, int]:
    """Sim role -> frames its pre-trainings train on: the dataset's ids (``datasets[role]
    .ids(splits)``: an opened dataset or a plan's reference) less the held-out split."""
    n_sim = {}
    for p in pretrains:
        sim, held = datasets[p.sim_role], p.holdout_split
        out = set(sim.ids([held])) if held else set()
        n_sim[p.sim_role] = sum(i not in out for i in sim.ids())
    return n_sim


def chain_steps(jobs: Sequence[Job]) -> dict[str, int]:
    """Each job's optimiser steps plus the longest chain of steps among the jobs that wait for
    it: the sweep's dispatch priority (the longest chain starts first).

    Raises
    ------
    ValueError — a job waits for a job that is not among ``jobs``, or for itself in a cycle.
    """
    by_name = {j.name: j for j in jobs}
    after: dict[str, list[str]] = {}
    for j in jobs:
        if j.after is not None:
            if j.after not in by_name:
                raise ValueError(f"{j.name} waits for {j.after!r}, which is not planned")
            after.setdefault(j.after, []).append(j.name)
    out: dict[str, int] = {}

    def chain(name: str, seen: frozenset[str]) -> int:
        if name in seen:
            raise ValueError(f"{name} waits for itself (a cycle of pre-trainings)")
        if name not in out:
            out[name] = by_name[name].steps + max(
                (chain(n, seen | {name}) for n in after.get(name, ())), default=0)
        return out[name]

    for j in jobs:
        chain(j.name, frozenset())
    return out


def wall_time(jobs: Sequence[Job], seconds_per_step: Mapping[str, float], workers: int,
              overhead_s: Mapping[str, float] | None = None, *,
              throughput: Mapping[int, float] | None = None, devices: int = 1) -> float:
    """Seconds from the first job's start to the last job's end on ``workers`` workers, each
    running one job at a time (module docstring: the longest chain first).

    Parameters
    ----------
    jobs : the sweep's jobs (:func:`sweep_jobs`, :func:`plan_jobs`), in plan order.
    seconds_per_step : kind -> one job's seconds per optimiser step while ``workers`` jobs run.
    workers : jobs at once.
    overhead_s : kind -> fixed seconds per job (validation, the test).
    throughput : runs sharing one device -> aggregate optimiser steps per second, as measured
        (:func:`sim2radar.experiment.packing.aggregate_throughput`). When given, while k jobs
        run on ``devices`` devices each goes at ``a(m) / m`` steps per second with ``m = k /
        devices``, relative to its speed at ``m = workers / devices`` (``a`` linear between
        the measured counts, ``a(0) = 0``, flat past the largest): the last runs of a packed
        GPU go faster than the full ones. None: every job at ``seconds_per_step``.
    devices : the devices the workers share (with ``throughput``).

    Raises
    ------
    ValueError — bad ``workers``/``devices``, or a job waits for one that is not planned.
    """
    if workers < 1 or devices < 1:
        raise ValueError(f"workers and devices must be >= 1, got {workers}, {devices}")
    overhead = dict(overhead_s or {})
    chain = chain_steps(jobs)
    speed = _sharing_speed(throughput, workers / devices, devices)

    def duration(j: Job) -> float:
        return j.steps * float(seconds_per_step[j.kind]) + float(overhead.get(j.kind, 0.0))

    order = {j.name: i for i, j in enumerate(jobs)}
    ready = [(-chain[j.name], order[j.name], j) for j in jobs if j.after is None]
    heapq.heapify(ready)
    waiting: dict[str, list[Job]] = {}
    for j in jobs:
        if j.after is not None:
            waiting.setdefault(j.after, []).append(j)
    running: dict[str, float] = {}      # name -> work left, in seconds at full occupancy
    now = 0.0
    while ready or running:
        while ready and len(running) < workers:
            job = heapq.heappop(ready)[2]
            running[job.name] = duration(job)
        step = min(running.values())
        now += step / speed(len(running))
        for name in list(running):
            running[name] -= step
            if running[name] <= 1e-9 * max(step, 1e-9):
                del running[name]
                for j in waiting.pop(name, []):
                    heapq.heappush(ready, (-chain[j.name], order[j.name], j))
    return now


def _sharing_speed(throughput: Mapping[int, float] | None, full: float, devices: int):
    """k running jobs -> their step speed relative to ``full`` jobs per device
    (:func:`wall_time`'s ``throughput``)."""
    if not throughput:
        return lambda k: 1.0
    counts = sorted((float(n), float(v)) for n, v in throughput.items())
    if any(n < 1 or v <= 0 for n, v in counts):
        raise ValueError(f"throughput must map run counts >= 1 to steps/s > 0, got "
                         f"{dict(throughput)}")
    xs, ys = [0.0, *(n for n, _ in counts)], [0.0, *(v for _, v in counts)]

    def per_run(m: float) -> float:
        m = max(m, 1e-9)
        return float(np.interp(m, xs, ys)) / m

    base = per_run(full)
    return lambda k: per_run(k / devices) / base


def sweep_cost(setup: SweepSetup, domains: Mapping[str, Any], *,
               workers: Collection[int] = (1, 8),
               step_seconds: Mapping[str, float] | None = None,
               throughput: Mapping[int, float] | None = None, devices: int = 1
               ) -> dict[str, Any]:
    """What a sweep would cost: its jobs, their optimiser steps, seconds per step measured here
    on the sweep's own frames with its resolved configs (or ``step_seconds`` =
    ``{"pretrain": s, "finetune": s}``, e.g. a GPU's figures), and the expected wall time on
    each of ``workers`` worker counts (:func:`sim2radar.experiment.cost.wall_time`; with the
    measured ``throughput`` of runs sharing each of ``devices`` GPUs).

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
    jobs = sweep_jobs(pretrains, runs, sim_frame_counts(pretrains, domains), profile.batch_size)
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
            "wall_hours": {int(n): wall_time(jobs, sec, int(n), throughput=throughput,
                                             devices=devices) / 3600 for n in workers}}
