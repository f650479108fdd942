"""End-to-end dataset generation benchmark: seconds per frame of the factory's main job at the
default configs (640 x 480 rig at 16 spp, ti-mmwcas, built-in reconstruction lidar/builtin/prior)
for each geometry mode, with the stages split out:

* ``render``       — Mitsuba RGB + depth + masks + LiDAR of the frame (procedural world)
* ``reconstruct``  — RGB + LiDAR -> material-labelled meshes + door boxes (paper §3)
* ``simulate_*``   — radar simulation on the ground-truth / reconstructed meshes

``ground_truth`` end-to-end = render + simulate_ground_truth; ``reconstructed`` = render +
reconstruct + simulate_reconstructed. Also the whole run's wall time per frame (world generation
and Parquet I/O included) and a cached re-run (content keys: nothing recomputed). Both runs go
through the ``generate`` job's driver with a plain runner
(:func:`sim2radar.tasks.generate.generate_dataset` + :class:`~sim2radar.tasks.runner.PlainRunner`:
what ``--no-prefect`` runs, without Prefect's overhead).

    python -m benchmarks generate
    SIM2RADAR_BENCH_GENERATE_FRAMES=6 python -m benchmarks generate
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time

from sim2radar.factory.spec import DatasetSpec
from sim2radar.tasks.generate import GenerateRequest, generate_dataset
from sim2radar.tasks.runner import PlainRunner

N_FRAMES = int(os.environ.get("SIM2RADAR_BENCH_GENERATE_FRAMES", "3"))
WORLD_SEED = 0


def _median(values) -> float:
    values = [float(v) for v in values]
    return statistics.median(values) if values else float("nan")


def main() -> dict:
    spec = DatasetSpec(frames_per_world=N_FRAMES, geometry="both")
    with tempfile.TemporaryDirectory(prefix="bench-generate-") as tmp:
        request = GenerateRequest(spec=spec, seeds=[WORLD_SEED], store=os.path.join(tmp, "store"),
                                  dataset="bench")
        t0 = time.perf_counter()
        summary = generate_dataset(request, PlainRunner())
        wall_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        again = generate_dataset(request, PlainRunner())
        cached_s = time.perf_counter() - t0
    frames = summary["outcomes"][0]["parts"]
    failed = [f["id"] for f in frames if f["status"] == "failed"]
    stages = ("render", "reconstruct", "simulate_ground_truth", "simulate_reconstructed")
    med = {s: _median(f["timings_s"][s] for f in frames if s in f["timings_s"]) for s in stages}
    mean = {s: statistics.fmean(f["timings_s"][s] for f in frames if s in f["timings_s"])
            for s in stages if any(s in f["timings_s"] for f in frames)}
    e2e_gt = med["render"] + med["simulate_ground_truth"]
    e2e_rec = med["render"] + med["reconstruct"] + med["simulate_reconstructed"]
    g = summary["geometry"]
    rig = spec.rig
    print(f"world seed {WORLD_SEED}, {N_FRAMES} frames, rig {rig.width}x{rig.height} "
          f"spp {rig.spp}, radar {spec.radar.name} ({spec.radar.n_rays} rays), reconstruction "
          f"{spec.reconstruction.depth.name}/{spec.reconstruction.segments.name}/"
          f"{spec.reconstruction.materials.name}")
    if failed:
        print(f"FAILED frames: {failed}")
    print("stage                     median s/frame   mean s/frame")
    for s in stages:
        print(f"  {s:<24}{med[s]:>10.2f}{mean.get(s, float('nan')):>15.2f}")
    print(f"end-to-end ground_truth : {e2e_gt:.2f} s/frame (render + simulate)")
    print(f"end-to-end reconstructed: {e2e_rec:.2f} s/frame (render + reconstruct + simulate)")
    print(f"whole run (both modes, world generation + I/O): {wall_s / N_FRAMES:.2f} s/frame; "
          f"cached re-run {cached_s / N_FRAMES:.3f} s/frame "
          f"({again['frame_counts']['skipped']} of {N_FRAMES} frames skipped)")
    for mode, s in g.items():
        print(f"  {mode:<14} points/frame {s['points_per_frame']:.0f}, labels/frame "
              f"{s['labels_per_frame']:.2f}, GT doors/frame {s['gt_doors_per_frame']:.2f}, "
              f"frames with a label {s['frac_frames_with_label']:.0%}, label recall/precision "
              f"@IoU0.3 {s['label_recall']:.0%}/{s['label_precision']:.0%}")
    comp = summary.get("comparison", {})
    if comp:
        print(f"reconstructed vs ground truth: points ratio {comp['points_ratio']:.2f}, "
              f"radar Chamfer {comp['chamfer_m']:.3f} m")
    return {
        "frames": N_FRAMES,
        "median_s_per_frame": med,
        "end_to_end_s_per_frame": {"ground_truth": e2e_gt, "reconstructed": e2e_rec},
        "run_wall_s_per_frame": wall_s / N_FRAMES,
        "cached_rerun_s_per_frame": cached_s / N_FRAMES,
        "geometry": g,
        "comparison": {k: v for k, v in comp.items() if k != "frames"},
        "failed_frames": failed,
    }


if __name__ == "__main__":
    main()
