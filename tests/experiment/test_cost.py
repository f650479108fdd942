"""A sweep's cost before it runs: steps per job, the wall-time replay of the sweep's
longest-chain-first dispatch, and the measured seconds per step."""

from __future__ import annotations

import math

import pytest

from sim2radar.experiment.cost import (
    Job,
    chain_steps,
    measure_step_seconds,
    sweep_jobs,
    wall_time,
)
from sim2radar.experiment.plan import plan_sweep
from sim2radar.experiment.profiles import load_profile

IDS = [f"world_{w:06d}_f{k:03d}" for w in range(38) for k in range(10)][:371]


def test_paper_grid_steps():
    """The paper grid on its 371 real train frames and 270 sim frames: 25 pre-trainings of
    20 x 34 steps (one per trial and fraction: intensity matching per subset) and 50 runs of
    200 epochs x ceil(n / 8)."""
    prof = load_profile("paper")
    pretrains, runs = plan_sweep(prof, IDS)
    jobs = sweep_jobs(pretrains, runs, {"sim": 270}, prof.batch_size)
    pre = [j for j in jobs if j.kind == "pretrain"]
    assert len(pre) == 25 and {j.steps for j in pre} == {20 * 34}
    ft = {(r.fraction, r.condition): j.steps for r, j in zip(runs, jobs[len(pre):],
                                                             strict=True)}
    for fraction, n in ((0.05, 18), (0.1, 37), (0.25, 92), (0.5, 185), (1.0, 371)):
        assert ft[(fraction, "baseline")] == ft[(fraction, "sim-pretrain")] == \
            200 * math.ceil(n / 8)
    assert all(j.after is None for j in jobs if j.name.startswith("baseline"))
    assert all(j.after and j.after.startswith("pretrain-") for j in jobs
               if j.name.startswith("sim-pretrain"))


def test_wall_time_replays_the_dispatch():
    """Hand-checked: 2 workers; P (10 s, chain 13) and B1 start, B2 after B1 (5-10 s), the two
    runs waiting for P start at 10 s and end at 13 s."""
    jobs = [Job("P", "pretrain", 10), Job("B1", "finetune", 5), Job("B2", "finetune", 5),
            Job("R1", "finetune", 3, "P"), Job("R2", "finetune", 3, "P")]
    s = {"pretrain": 1.0, "finetune": 1.0}
    assert wall_time(jobs, s, 2) == pytest.approx(13.0)
    assert wall_time(jobs, s, 1) == pytest.approx(26.0)          # one worker: the sum
    assert wall_time(jobs, s, 10) == pytest.approx(13.0)         # the critical path P -> R
    # 1 s overhead per run: B1 0-6, B2 6-12, R1 on P's worker 10-14, R2 12-16
    assert wall_time(jobs, s, 2, overhead_s={"finetune": 1.0}) == pytest.approx(16.0)
    with pytest.raises(ValueError, match="not planned"):
        wall_time([Job("R", "finetune", 1, "nope")], s, 1)


def test_the_longest_chain_starts_first():
    """2 workers, jobs in plan order A (1 s), B (1 s), C (4 s): first-in first-out would end
    at 5 s (A, B, then C alone); longest first runs C beside A then B and ends at 4 s. A
    pre-trained run that becomes ready later still overtakes the shorter runs from scratch."""
    s = {"pretrain": 1.0, "finetune": 1.0}
    assert wall_time([Job("A", "finetune", 1), Job("B", "finetune", 1),
                      Job("C", "finetune", 4)], s, 2) == pytest.approx(4.0)
    # 1 worker each for P -> R (1 + 6) and the short runs S1..S3 (2 each): P first (chain 7);
    # R ready at 1 s goes before S1..S3, so the grid ends at 7 + 6 = 13 s on one worker and
    # at 7 s on two (R on P's worker, S1..S3 on the other: 6 s)
    jobs = [Job("P", "pretrain", 1), Job("S1", "finetune", 2), Job("S2", "finetune", 2),
            Job("S3", "finetune", 2), Job("R", "finetune", 6, "P")]
    assert chain_steps(jobs) == {"P": 7, "S1": 2, "S2": 2, "S3": 2, "R": 6}
    assert wall_time(jobs, s, 2) == pytest.approx(7.0)
    assert wall_time(jobs, s, 1) == pytest.approx(13.0)
    with pytest.raises(ValueError, match="itself"):
        chain_steps([Job("X", "pretrain", 1, "Y"), Job("Y", "pretrain", 1, "X")])


def test_runs_go_faster_while_fewer_share_the_device():
    """Measured: 1 run 10 steps/s, 2 runs 15 steps/s in aggregate. Two runs of 15 and 30 steps
    on 2 slots: both at 7.5 steps/s until the short one ends at 2 s, then the long one alone
    at 10 steps/s for its last 15 steps (1.5 s): 3.5 s, against 4 s at the shared speed
    throughout. With 2 devices the two never share one, so each runs at 10 steps/s."""
    jobs = [Job("a", "finetune", 15), Job("b", "finetune", 30)]
    s = {"finetune": 2 / 15}                       # one run's step while 2 share the device
    curve = {1: 10.0, 2: 15.0}
    assert wall_time(jobs, s, 2) == pytest.approx(4.0)
    assert wall_time(jobs, s, 2, throughput=curve) == pytest.approx(3.5)
    assert wall_time(jobs, {"finetune": 0.1}, 2, throughput=curve,
                     devices=2) == pytest.approx(3.0)
    # one run alone goes at the 1-run figure: 10 steps in 1 s
    assert wall_time([Job("a", "finetune", 10)], s, 2, throughput=curve) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="throughput"):
        wall_time(jobs, s, 2, throughput={0: 1.0})


def test_the_sweeps_dispatch_is_what_the_plan_replays():
    """The sweep's :class:`Dispatch` on a pool that runs each job for its steps in seconds
    (one job per slot) ends the paper grid when :func:`wall_time` says, for 1, 3 and 8
    slots; and hands the jobs over longest chain first."""
    from tasks.sweep import Dispatch

    prof = load_profile("paper")
    jobs = sweep_jobs(*plan_sweep(prof, IDS), {"sim": 270}, prof.batch_size)
    after = {}
    for j in jobs:
        if j.after:
            after.setdefault(j.after, []).append(j)

    class ClockPool:
        """Runs a submitted job from now until now + its steps; finishes the earliest."""

        def __init__(self):
            self.now, self.running, self.started = 0.0, [], []

        def submit(self, key, fn, *args, task, name, priority=0):
            self.started.append((name, priority))
            self.running.append((self.now + key.steps, len(self.started), key))

        def finished(self):
            while self.running:
                self.running.sort(key=lambda r: r[:2])
                end, _, job = self.running.pop(0)
                self.now = end
                yield job, None, None

    for slots in (1, 3, 8):
        pool = ClockPool()
        queue = Dispatch(pool, chain_steps(jobs), slots)
        for j in jobs:
            if j.after is None:
                queue.add(j, print, task="t", name=j.name)
        queue.fill()
        for job, _, _ in pool.finished():
            queue.done()
            for r in after.get(job.name, []):
                queue.add(r, print, task="t", name=r.name)
            queue.fill()
        assert len(pool.started) == len(jobs)
        assert pool.now == pytest.approx(wall_time(jobs, {"pretrain": 1, "finetune": 1}, slots))
        # at the start: the 5 full-data pre-trainings (chain 680 + 9400), then the full-data
        # runs from scratch (9400), in falling chain order
        start = [p for _, p in pool.started[:slots]]
        assert start == sorted(start, reverse=True)
        assert start[:5] == [680 + 9400] * min(5, slots)


def test_wall_time_bounds_on_the_paper_grid():
    prof = load_profile("paper")
    jobs = sweep_jobs(*plan_sweep(prof, IDS), {"sim": 270}, prof.batch_size)
    s = {"pretrain": 0.8, "finetune": 0.8}
    total = sum(j.steps for j in jobs) * 0.8
    longest = max(j.steps for j in jobs) * 0.8
    one, eight = wall_time(jobs, s, 1), wall_time(jobs, s, 8)
    assert one == pytest.approx(total)
    assert total / 8 <= eight <= total / 8 + 2 * longest           # list scheduling bound


def test_step_seconds_are_measured_on_the_given_frames():
    from sim2radar.datasets import make_door_frames

    cfg = load_profile("smoke").detector_config("finetune")
    frames = make_door_frames(12, seed=0, points_per_frame=200)
    sec = measure_step_seconds(cfg, frames, steps_per_epoch=2, epochs=2)
    assert 0 < sec < 30
