"""The prepared GPU benchmark (issue #31): what one accelerator does for the paper grid.

    python -m benchmarks gpu          # on a GPU: <= 8 minutes; on a CPU: small sizes, ~2 min

Figures, each measured here:

1. **Training step** per profile (``paper``, ``study``) and precision (float32, the device's
   mixed dtype): median seconds per optimiser step of the profile's fine-tuning model
   (:func:`sim2radar.detect.precision.probe_step_seconds`: batch of synthetic corridors at
   IFR's density, augmentation, collation, forward, loss, backward, AdamW), and what ``amp:
   auto`` would choose from them (:data:`~sim2radar.detect.precision.MIN_GAIN` rule).
2. **Runs per GPU**: N training processes started together on the one device (1/2/4/8 on a
   GPU, 1/2 on a CPU at one thread each), each running the same steps of the paper model in
   the chosen precision; aggregate optimiser steps per second = N x steps / wall time.
3. **The paper grid's planned wall time**: its jobs (``paper`` profile: 5 fractions x 5
   trials, baseline + sim-pretrain, 371 real training frames, 270 sim frames; optimiser steps
   from :func:`sim2radar.experiment.cost.sweep_jobs`) replayed on each measured N
   (:func:`~sim2radar.experiment.cost.wall_time`: longest chain first, as the sweep
   dispatches; each run's step at the measured speed of the runs sharing the device at that
   moment).
4. **The radar on the device**: a ray-traced ``ti-mmwcas`` frame of a 20k-triangle corridor
   (a rig at rest, and walking at 1 m/s as the factory's frames are taken) with the Mitsuba
   variant in use (``cuda_ad_rgb`` on a GPU) against bare ``ray_intersect``
   of the same rays, its detection where :func:`sim2radar.radar.frame.detection_device` puts
   it (torch on the GPU under ``cuda_ad_rgb``: the sums stay there,
   :mod:`sim2radar.radar.detection_torch`) and, for comparison, the same frame detected on the
   host in NumPy and through the torch chain on the device torch picks; and a reference-radar
   frame (signal synthesis + TI chain, torch on the device, receiver noise drawn there) from
   20,000 synthetic paths. Each frame's time is also split into its stages: the ray-traced
   frame's own timers (``stats['seconds']``: rays, trace, readback, beamform, detect), and the
   reference frame's synthesis and processing, each ended by a device synchronisation.

Run on a GPU machine without internet: see the README's "A GPU machine" for the wheels to
carry. Record the figures in BENCHMARKS.md with the card's name.
"""

from __future__ import annotations

import statistics
import time

#: paper grid sizes (arXiv 2602.13314, Table 1): real training frames, sim frames
PAPER_REAL_TRAIN = 371
PAPER_SIM_FRAMES = 270

def _gpu() -> bool:
    import torch

    return torch.cuda.is_available()


def step_times(device: str, profiles: tuple[str, ...], steps: int) -> dict:
    """Median s/step per profile and precision, and what ``amp: auto`` would choose."""
    import torch

    from sim2radar.detect.precision import prefers_mixed, probe_step_seconds
    from sim2radar.experiment import load_profile
    from sim2radar.hardware import autocast_dtype

    mixed = autocast_dtype(device, True)
    mixed_name = str(mixed).removeprefix("torch.")
    out = {}
    for profile in profiles:
        cfg = load_profile(profile).detector_config("finetune")
        fp32 = probe_step_seconds(cfg, device, None, steps=steps)
        amp_s = probe_step_seconds(cfg, device, mixed, steps=steps)
        choice = mixed_name if prefers_mixed(fp32, amp_s) else "float32"
        out[profile] = {"float32": round(fp32, 4), mixed_name: round(amp_s, 4),
                        "auto_chooses": choice}
        print(f"{profile:6s} step: float32 {fp32:.4f} s, {mixed_name} {amp_s:.4f} s "
              f"-> amp auto: {choice}")
        if device.startswith("cuda"):
            torch.cuda.empty_cache()
    return out


def runs_per_device(device: str, profile: str, dtype: str, counts: tuple[int, ...] | None,
                    steps: int, threads: int) -> dict:
    """Aggregate optimiser steps/s of N concurrent training processes on the device
    (:func:`sim2radar.experiment.packing.aggregate_throughput`) for ``counts`` — None: the
    counts ``--runs-per-gpu auto`` probes (:func:`~sim2radar.experiment.packing.probe_runs`:
    1/2/4/8, then doubling while it pays) — and what ``auto`` would choose from them."""
    from sim2radar.experiment import load_profile
    from sim2radar.experiment.packing import aggregate_throughput, choose_runs, probe_runs

    cfg = load_profile(profile).detector_config("finetune").with_updates(
        runtime={"amp": dtype != "float32", "num_threads": threads})
    t0 = time.perf_counter()
    if counts is None:
        per_n, note = probe_runs(cfg, device, steps=steps)
        if note:
            print(f"the probe stopped: {note}")
    else:
        per_n = aggregate_throughput(cfg, device, counts, steps=steps)
    out = {n: {"steps_per_s": v} for n, v in per_n.items()}
    for n, v in per_n.items():
        print(f"{n} run(s) on {device}: {v:.1f} steps/s in aggregate ({n / v:.4f} s per step "
              "each)")
    choice = choose_runs(per_n)
    print(f"--runs-per-gpu auto would choose {choice.runs} ({time.perf_counter() - t0:.0f} s)")
    return out


def paper_grid(per_n: dict, measured: str) -> dict:
    """The paper grid's jobs and planned wall time on the best number of runs per device, at
    the ``measured`` profile's throughput (the paper model's on a GPU; on a CPU the small
    demo model stands in, and the figure says so)."""
    from sim2radar.experiment import load_profile
    from sim2radar.experiment.cost import sweep_jobs, wall_time
    from sim2radar.experiment.plan import plan_sweep

    profile = load_profile("paper")
    ids = [f"{i:06d}" for i in range(PAPER_REAL_TRAIN)]
    pretrains, runs = plan_sweep(profile, ids, ("baseline", "sim-pretrain"))
    jobs = sweep_jobs(pretrains, runs, {"sim": PAPER_SIM_FRAMES}, profile.batch_size)
    total = sum(j.steps for j in jobs)
    plans = {}
    agg = {n: fig["steps_per_s"] for n, fig in per_n.items()}
    for n, v in agg.items():
        s = n / v                           # one run's step while n share the device
        plans[n] = round(wall_time(jobs, {"pretrain": s, "finetune": s}, workers=n,
                                   throughput=agg) / 60, 1)
    best = min(plans, key=plans.get)
    print(f"paper grid: {len(jobs)} jobs, {total} optimiser steps; planned "
          + ", ".join(f"{n} per device {m:.1f} min" for n, m in plans.items())
          + f" (best: {best}; at the {measured} model's measured throughput)")
    return {"jobs": len(jobs), "steps": total, "planned_minutes": plans, "best_runs": best,
            "throughput_of": measured}


def radar_frames() -> dict:
    """Ray-traced frame vs bare intersection, and a reference-radar frame, on this machine."""
    import numpy as np

    from benchmarks._scenes import corridor
    from benchmarks.bench_signal import synthetic_paths
    from sim2radar.hardware import torch_device
    from sim2radar.radar import RadarScene, load_radar_config
    from sim2radar.radar.frame import simulate_scene_frame
    from sim2radar.radar.signal import simulate_signal_frame

    radar = load_radar_config("ti-mmwcas")
    scene = RadarScene(corridor(20_000))
    pose = np.eye(4)
    pose[:3, 3] = [0.0, 0.0, 1.0]
    torch_dev = str(torch_device())
    # "auto": where detection_device puts it; None: NumPy on the host; the torch chain on the
    # device torch picks (the GPU, or the CPU where there is none)
    # and "walking": "auto" with the rig walking at 1 m/s, as the factory's frames are taken
    # (its returns fill ~20 Doppler bins, each detected as a slab)
    modes = {"auto": "auto", "host": None, "torch": torch_dev, "walking": "auto"}
    walk = {"walking": np.array([1.0, 0.0, 0.0])}
    for key, mode in modes.items():
        simulate_scene_frame(scene, radar, pose, seed=0, device=mode,
                             velocity_mps=walk.get(key))
    scene.intersect_only(radar, pose, seed=0)
    times: dict[str, list[float]] = {k: [] for k in modes}
    stages: dict[str, list[float]] = {}
    walk_stages: dict[str, list[float]] = {}
    bare_s, where = [], ""
    for i in range(5):
        for key, mode in modes.items():  # interleaved: each sees the same machine load
            t0 = time.perf_counter()
            f = simulate_scene_frame(scene, radar, pose, seed=i + 1, device=mode,
                                     velocity_mps=walk.get(key))
            times[key].append(time.perf_counter() - t0)
            if key in ("auto", "walking"):
                where = f.stats["detection_device"]
                for stage, seconds in f.stats["seconds"].items():
                    (stages if key == "auto" else walk_stages).setdefault(
                        stage, []).append(seconds)
        bare_s.append(scene.intersect_only(radar, pose, seed=i + 1)["seconds"])
    frame, bare = statistics.median(times["auto"]), statistics.median(bare_s)
    ref = load_radar_config("ti-mmwcas-reference")
    paths = synthetic_paths(20_000, seed=0)
    simulate_signal_frame(paths, ref, seed=0, heatmap=False)
    ref_s, ref_parts = [], {"synthesis": [], "processing": []}
    for i in range(3):  # points only, as the factory runs it (no range-azimuth heatmap)
        t0 = time.perf_counter()
        out = simulate_signal_frame(paths, ref, seed=i + 1, heatmap=False)
        ref_s.append(time.perf_counter() - t0)
        for part, seconds in reference_split(paths, ref, seed=i + 1).items():
            ref_parts[part].append(seconds)
    host_s, torch_s = statistics.median(times["host"]), statistics.median(times["torch"])
    split = {k: round(statistics.median(v) * 1000, 2) for k, v in stages.items()}
    walk_split = {k: round(statistics.median(v) * 1000, 2) for k, v in walk_stages.items()}
    walking_s = statistics.median(times["walking"])
    ref_split = {k: round(statistics.median(v) * 1000, 1) for k, v in ref_parts.items()}
    res = {"variant": scene.variant, "frame_s": round(frame, 4), "bare_s": round(bare, 4),
           "ratio": round(frame / bare, 2), "detection_device": where,
           "frame_stages_ms": split, "walking_frame_s": round(walking_s, 4),
           "walking_ratio": round(walking_s / bare, 2), "walking_frame_stages_ms": walk_split,
           "frame_host_detection_s": round(host_s, 4),
           "frame_torch_detection_s": round(torch_s, 4), "torch_device": torch_dev,
           "reference_frame_s": round(statistics.median(ref_s), 3),
           "reference_stages_ms": ref_split,
           "reference_device": out.stats["device"]}
    print(f"ray-traced frame ({scene.variant}, detection on {where}): {frame * 1000:.1f} ms vs "
          f"bare ray_intersect {bare * 1000:.1f} ms ({frame / bare:.2f}x); detected on the host "
          f"{host_s * 1000:.1f} ms, by torch on {torch_dev} {torch_s * 1000:.1f} ms; "
          f"reference frame (20k paths, {out.stats['device']}): "
          f"{res['reference_frame_s']:.3f} s")
    print(f"  the rig walking at 1 m/s: {walking_s * 1000:.1f} ms ({walking_s / bare:.2f}x; "
          + ", ".join(f"{k} {v:.2f}" for k, v in walk_split.items()) + " ms)")
    print("  ray-traced frame's stages [ms]: "
          + ", ".join(f"{k} {v:.2f}" for k, v in split.items())
          + "; reference frame's [ms, each ended by a device sync]: "
          + ", ".join(f"{k} {v:.1f}" for k, v in ref_split.items()))
    return res


def reference_split(paths, radar, seed: int) -> dict[str, float]:
    """Seconds of a reference frame's two halves, IF synthesis (:func:`~sim2radar.radar.fmcw.
    synthesize_if`) and the TI chain (:func:`~sim2radar.radar.processing.process_if`), each
    ended by a device synchronisation: the frame's own timers do not wait for the GPU, so they
    put the synthesis's queued kernels in the processing's time."""
    from benchmarks.bench_training import _sync
    from sim2radar.hardware import torch_device
    from sim2radar.radar.fmcw import synthesize_if
    from sim2radar.radar.processing import process_if

    device = torch_device()
    t0 = time.perf_counter()
    cube = synthesize_if(paths, radar, seed=seed, device=device)
    _sync(device)
    t1 = time.perf_counter()
    process_if(cube, radar, heatmap=False)
    _sync(device)
    return {"synthesis": t1 - t0, "processing": time.perf_counter() - t1}


def main() -> dict:
    import torch

    gpu = _gpu()
    device = "cuda" if gpu else "cpu"
    name = torch.cuda.get_device_name() if gpu else "CPU (no CUDA: small sizes)"
    print(f"device: {name}, torch {torch.__version__}")
    t0 = time.perf_counter()
    res: dict = {"device": name}
    res["step"] = step_times(device, ("paper", "study") if gpu else ("demo",),
                             steps=20 if gpu else 2)
    best = res["step"]["paper" if gpu else "demo"]["auto_chooses"]
    res["runs_per_device"] = runs_per_device(
        device, "paper" if gpu else "demo", best, None if gpu else (1, 2),
        steps=30 if gpu else 3, threads=2 if gpu else 1)
    res["paper_grid"] = paper_grid(res["runs_per_device"], "paper" if gpu else "demo")
    res["radar"] = radar_frames()
    res["seconds"] = round(time.perf_counter() - t0, 1)
    print(f"benchmark took {res['seconds']:.0f} s")
    return res


if __name__ == "__main__":
    main()
