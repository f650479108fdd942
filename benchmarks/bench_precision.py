"""Mixed precision (bfloat16 autocast) against float32: seconds per training step, and a paired
A/B of the baseline's AP on the same seeds — the evidence behind ``runtime.amp: auto``.

    python -m benchmarks precision                 # step times + A/B (~10 min on 2 cores)
    SIM2RADAR_BENCH_AB_DATA=out/openpcdet/proxy_real python -m benchmarks precision

Step times: the ``paper`` model (batch 8, 2 threads) and the ``demo`` model (batch 8, 1 thread,
as the demo runs it) on synthetic corridors at IFR's density (2,000 points per frame), median
seconds per optimiser step over the epochs after the first, float32 then bfloat16.

A/B: the ``demo`` profile's baseline (training from scratch on real data only) over its 5
fractions x 3 trials, once in float32 and once with bfloat16 autocast, every other input
identical (same subsets, seeds, data order). Pairs are (fraction, trial); the decision rule,
fixed before the first A/B ran: bfloat16 is "unchanged within noise" when the paired t-test
(scipy.stats.ttest_rel over the 15 pairs) gives p >= 0.05 **and** the mean paired difference
is smaller than the float32 baseline's own trial-to-trial standard deviation (pooled over
fractions). Data: ``SIM2RADAR_BENCH_AB_DATA`` (an OpenPCDet dataset folder with train / val /
test splits; ``make demo`` leaves one in ``out/openpcdet/proxy_real``), else the demo's
``out/openpcdet/proxy_real`` when it exists, else synthetic frames (stated in the output).
"""

from __future__ import annotations

import math
import os
import statistics
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
POINTS_PER_FRAME = 2000


def step_seconds(profile_name: str, amp: bool, threads: int, n_frames: int = 24,
                 epochs: int = 4) -> float:
    """Median seconds per optimiser step of a profile's fine-tuning model."""
    import torch

    from sim2radar.datasets import make_door_frames
    from sim2radar.detect.train import train
    from sim2radar.experiment import load_profile

    cfg = load_profile(profile_name).detector_config("finetune").with_updates(
        runtime={"amp": amp, "num_threads": threads, "device": "cpu"})
    torch.set_num_threads(threads)
    frames = make_door_frames(n_frames, seed=0, points_per_frame=POINTS_PER_FRAME)
    with tempfile.TemporaryDirectory() as tmp:
        res = train(cfg, out_dir=tmp, frames=frames, epochs=epochs, seed=0)
    per_epoch = res.steps // res.epochs
    return statistics.median(h["seconds"] / per_epoch for h in res.history[1:])


def _ab_data(tmp: Path) -> tuple[Path, str]:
    chosen = os.environ.get("SIM2RADAR_BENCH_AB_DATA")
    if chosen:
        return Path(chosen), chosen
    demo = REPO / "out" / "openpcdet" / "proxy_real"
    if (demo / "ImageSets" / "test.txt").is_file():
        return demo, str(demo)
    from sim2radar.datasets import make_door_frames, write_dataset, write_metadata

    frames = make_door_frames(120, seed=2, points_per_frame=400)
    ids = [f.frame_id for f in frames]
    write_dataset(tmp / "real", frames, {"train": ids[:72], "val": ids[72:90],
                                         "test": ids[90:]})
    write_metadata(tmp / "real", {"domain": "synthetic benchmark frames"})
    return tmp / "real", "synthetic door frames (no demo dataset found)"


def paired_ab(real: Path, out: Path) -> dict:
    """The demo profile's baseline in float32 and in bfloat16 on ``real``; paired statistics."""
    import numpy as np
    from scipy import stats

    from sim2radar.experiment import load_profile
    from sim2radar.tasks.runner import PlainRunner
    from sim2radar.tasks.sweep import SweepRequest, run_sweep

    demo = load_profile("demo")
    aps: dict[bool, dict[tuple[float, int], float]] = {}
    for amp in (False, True):
        overrides = {"conditions": ["baseline"], "detector_overrides": {
            **demo.detector_overrides,
            "runtime": {**demo.detector_overrides.get("runtime", {}), "amp": amp}}}
        summary = run_sweep(SweepRequest(
            sim=str(real), real=str(real), profile="demo", name=f"ab-amp-{amp}".lower(),
            out=str(out / "sweeps"), store=str(out / "store"), overrides=overrides),
            PlainRunner())
        import pyarrow.parquet as pq

        rows = pq.read_table(Path(summary["sweep_dir"]) / "runs.parquet").to_pylist()
        aps[amp] = {(r["fraction"], r["trial"]): r["ap_3d_r40_iou03"] for r in rows
                    if r["status"] in ("ok", "skipped")}
    pairs = sorted(set(aps[False]) & set(aps[True]))
    a = np.array([aps[False][p] for p in pairs])
    b = np.array([aps[True][p] for p in pairs])
    d = b - a
    t = stats.ttest_rel(b, a)
    ci = t.confidence_interval(0.95)
    by_fraction: dict[float, list[float]] = {}
    for (f, _trial), v in aps[False].items():
        by_fraction.setdefault(f, []).append(v)
    pooled_sd = math.sqrt(statistics.mean(statistics.variance(v) for v in by_fraction.values()
                                          if len(v) > 1))
    unchanged = bool(t.pvalue >= 0.05 and abs(d.mean()) < pooled_sd)
    return {"pairs": len(pairs), "fp32_mean": float(a.mean()), "bf16_mean": float(b.mean()),
            "mean_diff": float(d.mean()), "sd_diff": float(d.std(ddof=1)),
            "ci95": [float(ci.low), float(ci.high)], "p": float(t.pvalue),
            "fp32_trial_sd_pooled": pooled_sd, "unchanged_within_noise": unchanged,
            "per_pair": [{"fraction": f, "trial": tr, "fp32": aps[False][(f, tr)],
                          "bf16": aps[True][(f, tr)]} for f, tr in pairs]}


def main() -> dict:
    from sim2radar.hardware import cpu_has_native_bf16

    out: dict = {"cpu_native_bf16": cpu_has_native_bf16(), "step_s": {}}
    print(f"CPU with native bfloat16 (avx512_bf16 / amx_bf16): {out['cpu_native_bf16']}")
    for name, threads in (("paper", 2), ("demo", 1)):
        fp32 = step_seconds(name, False, threads, n_frames=16 if name == "paper" else 24,
                            epochs=3 if name == "paper" else 4)
        bf16 = step_seconds(name, True, threads, n_frames=16 if name == "paper" else 24,
                            epochs=3 if name == "paper" else 4)
        out["step_s"][name] = {"threads": threads, "fp32": fp32, "bf16": bf16}
        print(f"{name:5s} model, batch 8, {threads} thread(s): float32 {fp32:.3f} s/step, "
              f"bfloat16 {bf16:.3f} s/step ({fp32 / bf16:.2f}x)")
    with tempfile.TemporaryDirectory(prefix="sim2radar-bench-ab-") as tmp:
        real, what = _ab_data(Path(tmp))
        print(f"A/B data: {what}")
        ab = paired_ab(real, Path(tmp))
    out["ab"] = {**ab, "data": what}
    print(f"A/B, demo baseline, {ab['pairs']} pairs (fraction x trial), 3D AP R40 @ 0.3: "
          f"float32 {ab['fp32_mean']:.1f}, bfloat16 {ab['bf16_mean']:.1f}; paired difference "
          f"{ab['mean_diff']:+.2f} [{ab['ci95'][0]:+.2f}, {ab['ci95'][1]:+.2f}] (sd "
          f"{ab['sd_diff']:.2f}), p = {ab['p']:.3f}; float32 trial-to-trial sd "
          f"{ab['fp32_trial_sd_pooled']:.2f}: "
          + ("unchanged within noise" if ab["unchanged_within_noise"] else "CHANGED"))
    for r in ab["per_pair"]:
        print(f"  {100 * r['fraction']:5.0f} % trial {r['trial']}: float32 {r['fp32']:.1f}  "
              f"bfloat16 {r['bf16']:.1f}")
    return out


if __name__ == "__main__":
    main()
