"""Where a training step's time goes: target assignment, augmentation, collation, the model.

    python -m benchmarks training                      # paper + demo models (2 cores: ~2 min
                                                       # with bfloat16, ~6 min in float32)
    SIM2RADAR_BENCH_STEPS=20 SIM2RADAR_BENCH_ROUNDS=3 python -m benchmarks training
    SIM2RADAR_BENCH_PROFILES=demo SIM2RADAR_BENCH_STEPS=2 SIM2RADAR_BENCH_ROUNDS=1 \
        python -m benchmarks training                  # CI-sized (tests/test_benchmark_training.py)

The step is :func:`sim2radar.detect.train.train`'s loop body at batch 8 on synthetic corridors
at IFR's density (2,000 points per frame), with GT sampling on: augmentation (GT sampling,
flip, rotation, scaling) and collation run on the host; target assignment
(:func:`sim2radar.detect.anchors.assign_targets`, inside the loss) runs on the model's device;
"model" is the rest (voxelisation, forward, loss, backward, clipping, AdamW). Each part is timed
with ``time.perf_counter`` around it (CUDA synchronised on a GPU), median over the steps after
two warm-up steps. Host-side work on the critical path is augmentation + collation (and, on a
GPU, whatever of the assignment waits for the host); the issue #31 goal is <= 5 ms per step on
the GPU machine's CPU.

How far the step could go on this device: the step's floating-point work (``gflop``: the
forward and backward of one step as ``torch.utils.flop_counter`` counts it, nearly all of it
in the convolutions), the rate the timed step achieves (``gflops``), and this device's float32
matrix-product rate at the run's thread count (``matmul_gflops``, a square ``torch.mm``): the
step cannot run faster than ``floor_ms = gflop / matmul_gflops`` in float32 here, so a goal
below that floor needs faster hardware or lower precision, not better code.

Then the same step inside :func:`sim2radar.detect.train.train` (the profile's precision as
``amp: auto`` resolves here) with ``runtime.loader_workers`` 0 (each batch made in this process
just before its step), 1 and 2 (DataLoader worker processes make the batches during the steps;
:mod:`sim2radar.detect.batches`; the same batches bit for bit): median seconds per step over
the epochs after the first (``SIM2RADAR_BENCH_STEPS`` steps each), and the host-side time on
the critical path — how long the training loop waits for its next batch (augmentation +
collation in-process, or an unfinished worker's batch), mean per step [ms]; the worker counts
take turns over ``SIM2RADAR_BENCH_ROUNDS`` rounds (default 2), medians reported. On a CPU
with two or more cores, last, the demo model on one thread with 0 and 1 workers: the worker
then has a core of its own, as on a GPU machine, and the wait left is the hand-over's.
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


def matmul_gflops(device: torch.device, n: int | None = None, repeats: int = 5) -> float:
    """Float32 ``torch.mm`` of two ``n x n`` matrices on ``device`` at torch's thread count:
    GFLOP/s (``2 n^3`` per product), over ``repeats`` products after a warm-up."""
    n = n or (2048 if device.type == "cpu" else 8192)
    gen = torch.Generator(device=device).manual_seed(0)
    a = torch.randn(n, n, device=device, generator=gen)
    b = torch.randn(n, n, device=device, generator=gen)
    torch.mm(a, b)
    _sync(device)
    t0 = time.perf_counter()
    for _ in range(repeats):
        torch.mm(a, b)
    _sync(device)
    return 2.0 * n**3 * repeats / (time.perf_counter() - t0) / 1e9


def step_flops(model, pts: torch.Tensor, gt: torch.Tensor, batch: int) -> float:
    """Floating-point operations of one training step's forward and backward (``torch.utils.
    flop_counter``: matrix products and convolutions; the optimiser's elementwise update is
    not counted). The gradients it leaves are cleared."""
    from torch.utils.flop_counter import FlopCounterMode

    counter = FlopCounterMode(display=False)
    with counter:
        loss, _ = model.loss(model(pts, batch), gt)
        loss.backward()
    model.zero_grad(set_to_none=True)
    return float(counter.get_total_flops())


def step_breakdown(profile: str, device: torch.device, n_steps: int) -> dict[str, float]:
    """Median milliseconds per training step of ``profile``'s fine-tuning model, by part, and
    its floating-point work per step (``gflop``) and rate (``gflops``)."""
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
    opt = torch.optim.AdamW(model.parameters(), lr=1e-3, foreach=True)  # as train() asks
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
    out = {k: round(1000 * statistics.median(v), 1) for k, v in parts.items()}
    flop = step_flops(model, pts, gt, BATCH)
    out["gflop"] = round(flop / 1e9, 3)
    out["gflops"] = round(flop / 1e9 / (out["step"] / 1000), 1)
    return out


LOADER_WORKERS = (0, 1, 2)


@contextlib.contextmanager
def _timed_batch_waits(waits: list[tuple[int, float]]):
    """Record ``(epoch, seconds)`` for every wait of ``train()``'s loop for its next batch."""
    import sim2radar.detect.train as train_mod

    real = train_mod.TrainingBatches

    class Timed(real):
        def epoch(self, epoch):
            it = super().epoch(epoch)
            while True:
                t0 = time.perf_counter()
                try:
                    item = next(it)
                except StopIteration:
                    return
                waits.append((epoch, time.perf_counter() - t0))
                yield item

    train_mod.TrainingBatches = Timed
    try:
        yield
    finally:
        train_mod.TrainingBatches = real


def loader_step_seconds(profile: str, device: torch.device, n_steps: int,
                        rounds: int = 2, threads: int | None = None,
                        workers: tuple[int, ...] = LOADER_WORKERS) -> dict[str, float]:
    """``train()`` with 0, 1 and 2 DataLoader workers (same batches: only time differs),
    interleaved over ``rounds`` rounds so a neighbour's load hits every count alike: median
    s/step (``workers_<n>``) and median of the loop's mean wait for a batch per step [ms]
    (``wait_ms_<n>``), each over the epochs after the first. ``threads``: the model's torch
    threads (``runtime.num_threads``; None: the machine's)."""
    from sim2radar.datasets import make_door_frames
    from sim2radar.detect.precision import measure_step_seconds
    from sim2radar.experiment import load_profile

    cfg = load_profile(profile).detector_config("finetune")
    frames = make_door_frames(n_steps * BATCH, seed=0, points_per_frame=POINTS_PER_FRAME)
    step: dict[int, list[float]] = {w: [] for w in workers}
    wait: dict[int, list[float]] = {w: [] for w in workers}
    for _ in range(rounds):
        for w in workers:
            waits: list[tuple[int, float]] = []
            with _timed_batch_waits(waits):
                step[w].append(measure_step_seconds(
                    cfg.with_updates(runtime={"loader_workers": w, "num_threads": threads}),
                    frames,
                    steps_per_epoch=n_steps, epochs=3, device=device))
            wait[w].append(statistics.fmean(t for e, t in waits if e > 0))
    out: dict[str, float] = {}
    for w in workers:
        out[f"workers_{w}"] = round(statistics.median(step[w]), 4)
        out[f"wait_ms_{w}"] = round(1000 * statistics.median(wait[w]), 1)
    return out


def main() -> dict:
    from sim2radar.hardware import torch_device

    device = torch_device()
    n_steps = int(os.environ.get("SIM2RADAR_BENCH_STEPS", "6" if device.type == "cpu" else "30"))
    print(f"device {device}, torch {torch.__version__}, {torch.get_num_threads()} threads, "
          f"batch {BATCH}, {POINTS_PER_FRAME} points per frame, median of {n_steps} steps")
    profiles = tuple(p for p in os.environ.get("SIM2RADAR_BENCH_PROFILES", ",".join(PROFILES))
                     .split(",") if p)
    res: dict = {"device": str(device), "steps": n_steps}
    print(f"{'profile':8s} {'augment':>9s} {'collate':>9s} {'assign':>9s} {'model':>9s} "
          f"{'step':>9s} {'host':>9s}  [ms per step]")
    for profile in profiles:
        ms = step_breakdown(profile, device, n_steps)
        ms["host"] = round(ms["augment"] + ms["collate"], 1)
        res[profile] = ms
        print(f"{profile:8s} {ms['augment']:9.1f} {ms['collate']:9.1f} {ms['assign']:9.1f} "
              f"{ms['model']:9.1f} {ms['step']:9.1f} {ms['host']:9.1f}")
    peak = res["matmul_gflops"] = round(matmul_gflops(device), 1)
    print(f"float32 matrix product here: {peak:.1f} GFLOP/s ({torch.get_num_threads()} threads)")
    for profile in profiles:
        ms = res[profile]
        ms["floor_ms"] = round(1000 * ms["gflop"] / peak, 1)
        print(f"{profile:8s} {ms['gflop']:9.3f} GFLOP per step (forward + backward), "
              f"{ms['gflops']:.1f} GFLOP/s in the timed step ({100 * ms['gflops'] / peak:.0f} % "
              f"of the matrix product's); float32 floor {ms['floor_ms']:.1f} ms per step")
    print(f"{'profile':8s} " + " ".join(f"{f'{w} workers':>17s}" for w in LOADER_WORKERS)
          + "  [train() s/step | loop's wait for a batch, ms/step]")
    for profile in profiles:
        s = loader_step_seconds(profile, device, n_steps,
                                int(os.environ.get("SIM2RADAR_BENCH_ROUNDS", "2")))
        res[profile].update(s)
        print(f"{profile:8s} " + " ".join(
            f"{s[f'workers_{w}']:8.4f} |{s[f'wait_ms_{w}']:6.1f}  " for w in LOADER_WORKERS))
    if device.type == "cpu" and (os.cpu_count() or 1) >= 2:
        # The GPU machine's case on this CPU: the model on one thread, a core left for the
        # worker, so the wait left is the data path's own (hand-over), not core contention.
        threads = torch.get_num_threads()
        try:
            s = loader_step_seconds("demo", device, n_steps,
                                    int(os.environ.get("SIM2RADAR_BENCH_ROUNDS", "2")),
                                    threads=1, workers=(0, 1))
        finally:  # a training run sets torch's thread count and leaves it
            torch.set_num_threads(threads)
        res["demo_1_thread"] = s
        print(f"{'demo, 1 model thread (a core spare for the worker)':8s}: " + " ".join(
            f"{w} workers {s[f'workers_{w}']:.4f} s | {s[f'wait_ms_{w}']:.1f} ms"
            for w in (0, 1)))
    return res


if __name__ == "__main__":
    main()
