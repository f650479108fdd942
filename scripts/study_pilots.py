"""Baseline-only pilots for the ``study`` profile: learning curves and the spread of baseline AP
across trial seeds, from which the study's model, lr and steps are chosen and its MDE is
predicted — before any sim-pretrain run (configs/experiment/study.yaml records the outcome).

    python scripts/study_pilots.py REAL_DATASET --out /work/study_out/pilots \
        --pilot small-lr0.003 --pilot small-lr0.01

Every pilot is a real sweep (conditions: baseline only; fractions 5 % and 100 %; 3 trials; the
study's datasets), so its runs are cached, resumable and recorded like any other; the script
then prints per pilot and fraction: baseline AP (3D R40 @ 0.3) per trial, mean, sd, the last
validation APs (is the curve still rising?), the wall time per run, and the MDE at 100 % that a
5-trial sweep would have if the paired differences had sd sqrt(2) x the baseline's sd (the
conditions' runs uncorrelated: conservative when pre-training and baseline runs share a seed's
subset and data order) at Holm's first-step level 0.05 / 5.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
from pathlib import Path

#: pilot name -> profile overrides on top of configs/experiment/study.yaml's protocol
PILOTS: dict[str, dict] = {
    # the demo's small CPU detector (0.2 m pillars, backbone [32, 64]) at the paper's epochs
    "small-lr0.003": {"lr": 0.003},
    "small-lr0.01": {"lr": 0.01},
    # 0.1 m pillars (64 x 104 grid), backbone [32, 64, 128]
    "mid-lr0.003": {"lr": 0.003, "detector_overrides": {
        "model": {"voxel_size_m": [0.1, 0.1, 4.0], "vfe_filters": [32], "layer_nums": [1, 2, 2],
                  "layer_strides": [2, 2, 2], "num_filters": [32, 64, 128],
                  "upsample_strides": [1, 2, 4], "num_upsample_filters": [32, 32, 32],
                  "bn_momentum": 0.1},
        "runtime": {"device": "cpu", "checkpoint_every": 25}}},
}
BASE = {"conditions": ["baseline"], "fractions": [0.05, 1.0], "trials": 3, "val_every": 10,
        "max_val_points": 10, "concurrent_runs": 2, "threads_per_run": 1}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("real", help="the study's real (proxy-real) dataset folder")
    ap.add_argument("--out", required=True, help="folder for the pilot sweeps and their store")
    ap.add_argument("--pilot", action="append", choices=sorted(PILOTS), required=True)
    ap.add_argument("--profile", default=str(Path(__file__).resolve().parents[1] / "configs"
                                             / "experiment" / "study.yaml"))
    args = ap.parse_args()

    import pyarrow.parquet as pq

    from sim2radar.experiment import load_profile
    from sim2radar.experiment.stats import minimum_detectable_effect
    from sim2radar.flows.run_experiment import run_experiment

    base = load_profile(args.profile)
    out = Path(args.out)
    report = {}
    for name in args.pilot:
        over = {**BASE, **PILOTS[name]}
        if "detector_overrides" in PILOTS[name]:
            over["detector_overrides"] = PILOTS[name]["detector_overrides"]
        else:
            over["detector_overrides"] = base.detector_overrides
        summary = run_experiment(args.real, args.real, profile=args.profile, name=f"pilot-{name}",
                                 out=out / "sweeps", store=out / "store", overrides=over)
        rows = pq.read_table(Path(summary["sweep_dir"]) / "runs.parquet").to_pylist()
        per = {}
        for f in BASE["fractions"]:
            cell = sorted((r for r in rows if r["fraction"] == f), key=lambda r: r["trial"])
            aps = [r["ap_3d_r40_iou03"] for r in cell]
            sd = statistics.stdev(aps) if len(aps) > 1 else float("nan")
            per[f] = {"ap": aps, "mean": statistics.mean(aps), "sd": sd,
                      "steps": cell[0]["steps"], "wall_s": [r["wall_time_s"] for r in cell],
                      "val_tail": [r["history_val_ap"][-3:] for r in cell],
                      "mde_5_trials": minimum_detectable_effect(5, math.sqrt(2) * sd,
                                                                0.05 / 5).mde}
            shown = ", ".join(f"{a:.1f}" for a in aps)
            wall = statistics.mean(per[f]["wall_s"])
            print(f"{name} {100 * f:g} %: AP [{shown}] mean {per[f]['mean']:.1f} sd {sd:.2f}; "
                  f"{per[f]['steps']} steps, {wall:.0f} s per run; last val APs "
                  f"{per[f]['val_tail']}; predicted MDE (5 trials) {per[f]['mde_5_trials']:.1f}")
        report[name] = per
    (out / "pilots.json").write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
