"""Where a training step's time goes: target assignment, augmentation, collation, the model.

    python -m benchmarks training                      # paper + demo models (~1-2 min, 2 cores)
    SIM2RADAR_BENCH_STEPS=20 python -m benchmarks training

The step is :func:`sim2radar.detect.train.train`'s loop body at batch 8 on synthetic corridors
at IFR's density (2,000 points per frame), with GT sampling on: augmentation (GT sampling,
flip, rotation, scaling) and collation run on the host; target assignment
(:func:`sim2radar.detect.anchors.assign_targets`, inside the loss) runs on the model's device;
"model" is the rest (voxelisation, forward, loss, backward, clipping, AdamW). Each part is timed
with ``time.perf_counter`` around it (CUDA synchronised on a GPU), median over the steps after
two warm-up steps. Host-side work on the critical path is augmentation + collation (and, on a
GPU, whatever of the assignment waits for the host); the issue #31 goal is <= 5 ms per step on
the GPU machine's CPU.

Then the same step inside :func:`sim2radar.detect.train.train` (the profile's precision as
``amp: auto`` resolves here) with ``runtime.prefetch_batches`` 0 (each batch made just before
its step) and 1 (a background thread makes the next batch during the step;
:mod:`sim2radar.detect.batches`): median seconds per step over the epochs after the first.
"""

from __future__ import annotations

import contextlib
import os
import statistics
import time

import numpy as np
import torch

BATCH = 8
POINTS_PER_FRAME = 2000
PROFILES = ("paper", "demo")


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize()


@contextlib.contextmanager
def _timed_assignment(device: torch.device, spent: list[float]):
    """Time every call of the model's ``assign_targets`` into ``spent`` (seconds)."""
    import sim2radar.detect.model as model_mod

    real = model_mod.assign_targets

    def timed(*args, **kwargs):
        _sync(device)
        t0 = time.perf_counter()
        out = real(*args, **kwargs)
        _sync(device)
        spent.append(time.perf_counter() - t0)
        return out

    model_mod.assign_targets = timed
    try:
        yield
    finally:
        model_mod.assign_targets = real


def step_breakdown(profile: str, device: torch.device, n_steps: int) -> dict[str, float]:
    """Median milliseconds per training step of ``profile``'s fine-tuning model, by part."""
    from sim2radar.datasets import make_door_frames
    from sim2radar.detect import PointPillars
    from sim2radar.detect.augment import augment_frame, build_gt_database
    from sim2radar.detect.train import collate
    from sim2radar.experiment import load_profile

    cfg = load_profile(profile).detector_config("finetune")
    mcfg = cfg.model
    frames = make_door_frames(4 * BATCH, seed=0, points_per_frame=POINTS_PER_FRAME)
    db = build_gt_database(frames, mcfg.class_names, cfg.augmentation.min_points_in_gt)
    torch.manual_seed(0)
    model = PointPillars(mcfg).to(device).train()
    opt = torch.optim.AdamW(model.parameters(), lr=1e-3)
    rng = np.random.default_rng(0)
    parts: dict[str, list[float]] = {"augment": [], "collate": [], "assign": [], "model": [],
                                     "step": []}
    assign: list[float] = []
    with _timed_assignment(device, assign):
        for i in range(n_steps + 2):
            batch = [frames[(i * BATCH + k) % len(frames)] for k in range(BATCH)]
            _sync(device)
            t0 = time.perf_counter()
            aug = [augment_frame(f, cfg.augmentation, rng, mcfg.point_cloud_range_m, db)
                   for f in batch]
            t1 = time.perf_counter()
            pts, gt = collate([a[0] for a in aug], [a[1] for a in aug], [a[2] for a in aug],
                              mcfg.class_names, device)
            _sync(device)
            t2 = time.perf_counter()
            n_before = len(assign)
            loss, _ = model.loss(model(pts, BATCH), gt)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), 10.0)
            opt.step()
            _sync(device)
            t3 = time.perf_counter()
            if i < 2:
                continue
            a = sum(assign[n_before:])
            parts["augment"].append(t1 - t0)
            parts["collate"].append(t2 - t1)
            parts["assign"].append(a)
            parts["model"].append(t3 - t2 - a)
            parts["step"].append(t3 - t0)
    return {k: round(1000 * statistics.median(v), 1) for k, v in parts.items()}


def prefetch_step_seconds(profile: str, device: torch.device) -> dict[str, float]:
    """Median s/step of ``train()`` with prefetch 0 and 1 (same batches: only time differs)."""
    from sim2radar.datasets import make_door_frames
    from sim2radar.experiment import load_profile
    from sim2radar.experiment.cost import measure_step_seconds

    cfg = load_profile(profile).detector_config("finetune")
    frames = make_door_frames(4 * BATCH, seed=0, points_per_frame=POINTS_PER_FRAME)
    return {f"prefetch_{n}": round(measure_step_seconds(
        cfg.with_updates(runtime={"prefetch_batches": n}), frames, device=device), 4)
        for n in (0, 1)}


def main() -> dict:
    from sim2radar.hardware import torch_device

    device = torch_device()
    n_steps = int(os.environ.get("SIM2RADAR_BENCH_STEPS", "6" if device.type == "cpu" else "30"))
    print(f"device {device}, torch {torch.__version__}, {torch.get_num_threads()} threads, "
          f"batch {BATCH}, {POINTS_PER_FRAME} points per frame, median of {n_steps} steps")
    res: dict = {"device": str(device), "steps": n_steps}
    print(f"{'profile':8s} {'augment':>9s} {'collate':>9s} {'assign':>9s} {'model':>9s} "
          f"{'step':>9s} {'host':>9s}  [ms per step]")
    for profile in PROFILES:
        ms = step_breakdown(profile, device, n_steps)
        ms["host"] = round(ms["augment"] + ms["collate"], 1)
        res[profile] = ms
        print(f"{profile:8s} {ms['augment']:9.1f} {ms['collate']:9.1f} {ms['assign']:9.1f} "
              f"{ms['model']:9.1f} {ms['step']:9.1f} {ms['host']:9.1f}")
    for profile in PROFILES:
        s = prefetch_step_seconds(profile, device)
        res[profile].update(s)
        print(f"{profile:8s} train() step, amp auto: prefetch 0 {s['prefetch_0']:.4f} s, "
              f"prefetch 1 {s['prefetch_1']:.4f} s")
    return res


if __name__ == "__main__":
    main()
