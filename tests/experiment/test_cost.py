"""A sweep's cost before it runs: steps per job, the FIFO wall-time replay of the flow's
dispatch, and the measured seconds per step."""

from __future__ import annotations

import math

import pytest

from sim2radar.experiment.cost import Job, measure_step_seconds, sweep_jobs, wall_time
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


def test_wall_time_replays_fifo_dispatch():
    """Hand-checked: 2 workers; P (10 s) and B1 start, B2 after B1 (5-10 s), the two runs
    waiting for P start at 10 s and end at 13 s."""
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
