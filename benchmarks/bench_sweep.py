"""The experiment sweep's cost: seconds per training step of every profile, the demo's wall
time, and (on a GPU) the paper's full grid.

    python -m benchmarks sweep                          # step times (~1 min on 2 cores)
    SIM2RADAR_BENCH_DEMO=1 python -m benchmarks sweep   # + `sim2radar demo` from scratch (~15 min)
    SIM2RADAR_BENCH_PAPER_GRID=1 python -m benchmarks sweep   # + the paper grid (GPU: ~1 h goal)
    SIM2RADAR_BENCH_PAPER_SLICE=1 python -m benchmarks sweep  # + one paper cell (~25 min, CPU)

The paper grid's plan (always): ``sim2radar sweep --plan``'s estimate on synthetic datasets of
the paper's size (270 sim; 371 / 92 / 155 real), seconds per step measured here in the
profile's resolved precision, wall time on 1 and 8 workers. The slice: one fraction (5 %) x
one trial of the paper profile, both conditions (one pre-training, two fine-tuning runs, no
validation), run one after another and timed, next to the plan's prediction for it.

Step times: each profile's resolved fine-tuning detector config, batch size and threads, on
synthetic corridors at IFR's density (2,000 points per frame), median seconds per optimiser
step over the epochs after the first. The demo: a fresh output folder and Prefect home, the
whole main job (simulated and proxy-real datasets, gap report, demo sweep, dashboard) timed
from outside, then the cached rerun. The paper grid: synthetic frames sized like the paper (270
sim, 371 / 92 / 155 real), the ``paper`` profile (200 + 20 epochs, 5 fractions x 5 trials, 50
fine-tuning runs + 5 pre-trainings) with ``concurrent_runs`` runs sharing the device.
"""

from __future__ import annotations

import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
POINTS_PER_FRAME = 2000


def _step_time(profile_name: str, n_frames: int = 24, epochs: int = 4) -> dict:
    import torch

    from sim2radar.datasets import make_door_frames
    from sim2radar.detect.train import train
    from sim2radar.experiment import load_profile

    profile = load_profile(profile_name)
    cfg = profile.detector_config("finetune")
    torch.set_num_threads(profile.threads_per_run or os.cpu_count() or 1)
    frames = make_door_frames(n_frames, seed=0, points_per_frame=POINTS_PER_FRAME)
    with tempfile.TemporaryDirectory() as tmp:
        res = train(cfg, out_dir=tmp, frames=frames, epochs=epochs, seed=0)
    steps_per_epoch = res.steps // res.epochs
    per_step = [h["seconds"] / steps_per_epoch for h in res.history[1:]]
    from sim2radar.hardware import autocast_dtype, torch_device

    dtype = autocast_dtype(torch_device(cfg.runtime.device), cfg.runtime.amp)
    return {"profile": profile_name, "batch_size": cfg.optimization.batch_size,
            "threads": torch.get_num_threads(),
            "precision": "float32" if dtype is None else str(dtype).removeprefix("torch."),
            "device": str(cfg.runtime.device or "auto"),
            "s_per_step_median": statistics.median(per_step), "steps_timed": len(per_step)
            * steps_per_epoch}


def _demo_wall_time() -> dict:
    out = Path(tempfile.mkdtemp(prefix="sim2radar-bench-demo-"))
    env = {**os.environ, "PREFECT_HOME": str(out / ".prefect")}
    cmd = [sys.executable, "-c", "from sim2radar.cli import main; main()", "demo", "--out",
           str(out / "out")]
    times = []
    try:
        for _ in range(2):  # from scratch, then cached
            t0 = time.perf_counter()
            res = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True)
            times.append(time.perf_counter() - t0)
            if res.returncode != 0:
                return {"error": res.stdout[-2000:] + res.stderr[-2000:], "seconds": times}
        return {"demo_first_s": times[0], "demo_cached_s": times[1],
                "tail": res.stdout[-1500:]}
    finally:
        shutil.rmtree(out, ignore_errors=True)


def _paper_grid() -> dict:
    from sim2radar.hardware import torch_device

    device = torch_device()
    if device.type != "cuda":
        return {"skipped": "no CUDA device: the paper grid is for a GPU or a cluster"}
    root = Path(tempfile.mkdtemp(prefix="sim2radar-bench-grid-"))
    try:
        sim, real = _paper_data(root)
        from sim2radar.flows._states import run_flow
        from sim2radar.flows.run_experiment import run_experiment
        from sim2radar.tasks.sweep import SweepRequest

        concurrent = int(os.environ.get("SIM2RADAR_BENCH_CONCURRENT", "4"))
        t0 = time.perf_counter()
        summary = run_flow(run_experiment, request=SweepRequest(
            sim=str(sim), real=str(real), profile="paper", name="grid",
            out=str(root / "sweeps"), store=str(root / "store"), workers=concurrent,
            overrides={"concurrent_runs": concurrent, "val_every": 0}))
        return {"paper_grid_s": time.perf_counter() - t0, "concurrent_runs": concurrent,
                "counts": summary["counts"], "device": str(device)}
    finally:
        shutil.rmtree(root, ignore_errors=True)


def _paper_data(root: Path) -> tuple[Path, Path]:
    """Synthetic datasets of the paper's size: 270 sim frames, 371 / 92 / 155 real."""
    from sim2radar.datasets import make_door_frames, write_dataset, write_metadata

    sim = make_door_frames(270, seed=1, points_per_frame=POINTS_PER_FRAME)
    write_dataset(root / "sim", sim, {"train": [f.frame_id for f in sim]})
    real = make_door_frames(618, seed=2, points_per_frame=POINTS_PER_FRAME, first_id=1000)
    ids = [f.frame_id for f in real]
    write_dataset(root / "real", real, {"train": ids[:371], "val": ids[371:463],
                                        "test": ids[463:]})
    write_metadata(root / "real", {"domain": "synthetic benchmark frames"})
    return root / "sim", root / "real"


def _paper_plan(root: Path) -> dict:
    from sim2radar.tasks.experiment import plan_cost

    sim, real = _paper_data(root)
    return plan_cost({"sim": sim, "real": real}, profile="paper", store=root / "store",
                     workers=(1, 8))


def _paper_slice(root: Path) -> dict:
    from sim2radar.tasks.experiment import plan_cost
    from sim2radar.tasks.runner import PlainRunner
    from sim2radar.tasks.sweep import SweepRequest, run_sweep

    sim, real = (root / "sim", root / "real") if (root / "real").is_dir() else _paper_data(root)
    overrides = {"fractions": [0.05], "trials": 1, "val_every": 0, "concurrent_runs": 1}
    predicted = plan_cost({"sim": sim, "real": real}, profile="paper", store=root / "store",
                          overrides=overrides, workers=(1,))
    t0 = time.perf_counter()
    summary = run_sweep(SweepRequest(sim=str(sim), real=str(real), profile="paper",
                                     name="slice", out=str(root / "sweeps"),
                                     store=str(root / "store"), overrides=overrides),
                        PlainRunner())     # one run at a time, as planned (workers=1)
    return {"measured_s": time.perf_counter() - t0, "predicted_s": 3600 *
            predicted["wall_hours"][1], "counts": summary["counts"],
            "precision": predicted["precision"], "step_seconds": predicted["step_seconds"]}


def main() -> dict:
    out: dict = {"step_times": []}
    for name in ("smoke", "demo", "paper"):
        r = _step_time(name, n_frames=16 if name == "paper" else 24,
                       epochs=3 if name == "paper" else 4)
        out["step_times"].append(r)
        print(f"{name:6s} batch {r['batch_size']} threads {r['threads']} {r['precision']}: "
              f"{r['s_per_step_median']:.3f} s/step (median of {r['steps_timed']} steps)")
    with tempfile.TemporaryDirectory(prefix="sim2radar-bench-plan-") as tmp:
        plan = out["paper_plan"] = _paper_plan(Path(tmp))
        print(f"paper grid plan ({plan['precision']['finetune']} mixed precision): "
              f"{plan['jobs']['pretrain']['jobs']} pre-trainings x "
              f"{plan['jobs']['pretrain']['steps'] // max(1, plan['jobs']['pretrain']['jobs'])}"
              f" steps, {plan['jobs']['finetune']['jobs']} runs, "
              f"{plan['jobs']['finetune']['steps']:,} fine-tuning steps; "
              f"{plan['step_seconds']['finetune']:.3f} s/step here; compute "
              f"{plan['compute_hours']:.1f} h; wall {plan['wall_hours'][1]:.1f} h on 1 worker, "
              f"{plan['wall_hours'][8]:.1f} h on 8")
        if os.environ.get("SIM2RADAR_BENCH_PAPER_SLICE"):
            sl = out["paper_slice"] = _paper_slice(Path(tmp))
            print(f"paper slice (5 %, 1 trial, both conditions): {sl['measured_s'] / 60:.1f} "
                  f"min measured, {sl['predicted_s'] / 60:.1f} min predicted by the plan; "
                  f"{sl['counts']}")
    if os.environ.get("SIM2RADAR_BENCH_DEMO"):
        out["demo"] = _demo_wall_time()
        d = out["demo"]
        if "error" in d:
            print(f"demo FAILED: {d['error']}")
        else:
            print(f"sim2radar demo from scratch: {d['demo_first_s']:.0f} s; cached rerun "
                  f"{d['demo_cached_s']:.1f} s")
    if os.environ.get("SIM2RADAR_BENCH_PAPER_GRID"):
        out["paper_grid"] = _paper_grid()
        print(f"paper grid: {out['paper_grid']}")
    return out


if __name__ == "__main__":
    main()
