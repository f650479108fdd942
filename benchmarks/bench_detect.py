"""PointPillars (paper config) speed: training step, inference, KITTI-protocol evaluation.

    python -m benchmarks detect                       # eager CPU figures (~1-2 min on 2 cores)
    SIM2RADAR_BENCH_COMPILE=1 python -m benchmarks detect   # also torch.compile (minutes)

Frames are synthetic corridors with doors at IFR's density (2,000 points per frame). A training
step is the full loop body at batch 8: augmentation (GT sampling, flip, rotation, scaling),
collation, voxelisation, forward, target assignment + loss, backward, gradient clipping, AdamW
and scheduler step. On CUDA the benchmark also reports training frames/s and extrapolates one
200-epoch run on 371 frames (the paper's largest real split).
"""

from __future__ import annotations

import math
import os
import statistics
import time

import numpy as np
import torch

from sim2radar.datasets import make_door_frames
from sim2radar.detect import DetectConfig, PointPillars
from sim2radar.detect.augment import augment_frame, build_gt_database
from sim2radar.detect.train import collate, predict_frames
from sim2radar.evaluate import evaluate_detections
from sim2radar.hardware import torch_device

BATCH = 8
POINTS_PER_FRAME = 2000


def _train_step_times(device: torch.device, n_steps: int, compile_model: bool) -> dict:
    cfg = DetectConfig()
    mcfg = cfg.model
    frames = make_door_frames(4 * BATCH, seed=0, points_per_frame=POINTS_PER_FRAME)
    db = build_gt_database(frames, mcfg.class_names)
    torch.manual_seed(0)
    model = PointPillars(mcfg).to(device).train()
    if compile_model:
        model.compile_dense()
    opt = torch.optim.AdamW(model.parameters(), lr=3e-3, betas=(0.9, 0.99), weight_decay=0.01)
    rng = np.random.default_rng(0)

    def step(i: int) -> float:
        t0 = time.perf_counter()
        batch = [frames[(i * BATCH + k) % len(frames)] for k in range(BATCH)]
        aug = [augment_frame(f, cfg.augmentation, rng, mcfg.point_cloud_range_m, db) for f in batch]
        pts, gt = collate([a[0] for a in aug], [a[1] for a in aug], [a[2] for a in aug],
                          mcfg.class_names, device)
        loss, _ = model.loss(model(pts, BATCH), gt)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 10.0)
        opt.step()
        if device.type == "cuda":
            torch.cuda.synchronize()
        return time.perf_counter() - t0

    warm = [step(i) for i in range(2)]
    times = [step(i) for i in range(2, 2 + n_steps)]
    return {"first_step_s": warm[0], "median_step_s": statistics.median(times),
            "min_step_s": min(times)}


def _inference_ms_per_frame(device: torch.device, batch: int, n_frames: int) -> float:
    frames = make_door_frames(n_frames, seed=1, points_per_frame=POINTS_PER_FRAME)
    torch.manual_seed(0)
    model = PointPillars().to(device).eval()
    predict_frames(model, frames[:batch], batch)  # warm-up
    t0 = time.perf_counter()
    predict_frames(model, frames, batch)
    if device.type == "cuda":
        torch.cuda.synchronize()
    return 1000.0 * (time.perf_counter() - t0) / n_frames


def _evaluation_s(n_frames: int = 155) -> float:
    """All 8 AP figures (3D/BEV x IoU 0.3/0.5 x R11/R40) on 155 frames of realistic output:
    every door detected with noise, plus 8 scored false positives per frame."""
    rng = np.random.default_rng(2)
    frames = make_door_frames(n_frames, seed=2, points_per_frame=200)
    gts = [f.boxes for f in frames]
    preds, scores = [], []
    for g in gts:
        noisy = g + rng.normal(0, [0.05, 0.05, 0.03, 0.03, 0.02, 0.03, 0.05], g.shape)
        fp = np.column_stack([rng.uniform(0, 5, 8), rng.uniform(-4, 4, 8), np.zeros(8),
                              np.full(8, 0.95), np.full(8, 0.2), np.full(8, 2.05),
                              rng.uniform(-3, 3, 8)])
        preds.append(np.vstack([noisy, fp]))
        scores.append(np.concatenate([rng.uniform(0.3, 1.0, len(g)), rng.uniform(0.1, 0.6, 8)]))
    t0 = time.perf_counter()
    evaluate_detections(gts, preds, scores)
    return time.perf_counter() - t0


def _load() -> float:
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")


def main() -> dict:
    device = torch_device()
    cores = os.cpu_count() or 1
    print(f"device {device}, torch {torch.__version__}, {cores} cores, "
          f"load average {_load():.1f} at start")
    res: dict = {"device": str(device)}

    # CPU: one and all cores. On a machine shared with other jobs, one OpenMP thread is often
    # faster than two (threads wait on each other when a core is taken).
    thread_counts = sorted({1, cores}) if device.type == "cpu" else [torch.get_num_threads()]
    for n in thread_counts:
        torch.set_num_threads(n)
        eager = _train_step_times(device, n_steps=5 if device.type == "cpu" else 30,
                                  compile_model=False)
        res[f"train_step_eager_s_{n}t"] = round(eager["median_step_s"], 3)
        res[f"train_step_eager_min_s_{n}t"] = round(eager["min_step_s"], 3)
        print(f"train step, batch {BATCH}, eager, {n} thread(s): median "
              f"{eager['median_step_s']:.3f} s (min {eager['min_step_s']:.3f} s; "
              f"load {_load():.1f})")
    res["train_step_eager_s"] = min(res[f"train_step_eager_s_{n}t"] for n in thread_counts)
    if device.type == "cuda":
        fps = BATCH / eager["median_step_s"]
        run_s = math.ceil(371 / BATCH) * 200 * eager["median_step_s"]
        res["train_frames_per_s"] = round(fps, 1)
        res["run_200ep_371fr_min"] = round(run_s / 60, 1)
        print(f"training {fps:.0f} frames/s; 200 epochs x 371 frames ~ {run_s / 60:.1f} min")
    else:
        print("GPU figures not measured (no CUDA device)")

    if device.type == "cpu":  # the rest with the faster thread count
        best = min(thread_counts, key=lambda n: res[f"train_step_eager_s_{n}t"])
        torch.set_num_threads(best)
        res["threads"] = best
    if os.environ.get("SIM2RADAR_BENCH_COMPILE"):
        t0 = time.perf_counter()
        comp = _train_step_times(device, n_steps=5, compile_model=True)
        res["train_step_compiled_s"] = round(comp["median_step_s"], 3)
        res["compile_first_step_s"] = round(comp["first_step_s"], 1)
        print(f"train step, batch {BATCH}, torch.compile: median {comp['median_step_s']:.3f} s "
              f"(first step incl. compilation {comp['first_step_s']:.0f} s; "
              f"total {time.perf_counter() - t0:.0f} s)")

    for b in (1, BATCH):
        ms = _inference_ms_per_frame(device, b, n_frames=16)
        res[f"inference_ms_per_frame_b{b}"] = round(ms, 1)
        print(f"inference (voxelise + network + NMS), batch {b}: {ms:.1f} ms/frame")
    ev = _evaluation_s()
    res["evaluation_155_frames_s"] = round(ev, 3)
    print(f"KITTI evaluation, 155 frames, 8 AP figures: {ev:.2f} s")
    return res


if __name__ == "__main__":
    main()
