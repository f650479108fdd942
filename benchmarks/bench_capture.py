"""Capture-folder factory benchmark: seconds per scene and per step of ``generate --captures``
at the default settings (a 640 x 480 capture per scene, built-in reconstruction lidar/builtin/
prior, 54 radar poses per scene, ti-mmwcas), and the Prefect overhead of one task per step
against the plain loop on the same scenes, in one run:

* plain first run / cached rerun (``--no-prefect``: the ``captures`` job's driver
  :func:`sim2radar.tasks.capture.capture_dataset` with a
  :class:`~sim2radar.tasks.runner.PlainRunner`: the same per-scene function, plain calls)
* Prefect first run / cached rerun (the ``capture-dataset`` flow,
  :func:`sim2radar.flows.capture_dataset.capture_dataset` through
  :func:`~sim2radar.flows._states.run_flow`: a task per scene and per step)

Overhead per scene = (sum of the flow's per-scene wall times - the plain loop's) / scenes; the
per-scene wall time is measured inside the scene, so the API server's start-up is not in it
(it is in the flow's total wall, printed too). A warm-up run on a throw-away store comes
first, so imports, backends and the tracer's compiled kernels are paid by neither measured
run. Cached rerun share = rerun / first run.

    python -m benchmarks capture
    SIM2RADAR_BENCH_CAPTURE_SCENES=1 SIM2RADAR_BENCH_CAPTURE_FRAMES=12 python -m benchmarks capture
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time

N_SCENES = int(os.environ.get("SIM2RADAR_BENCH_CAPTURE_SCENES", "2"))
N_FRAMES = int(os.environ.get("SIM2RADAR_BENCH_CAPTURE_FRAMES", "54"))
STEPS = ("depth", "segments", "materials", "scene", "poses", "simulate")


def _run(captures: str, store: str, use_prefect: bool) -> tuple[dict, float]:
    from sim2radar.tasks.capture import CaptureRequest, capture_dataset

    t0 = time.perf_counter()
    request = CaptureRequest(captures=captures, store=store, dataset="bench",
                             spec={"poses": {"frames": N_FRAMES}})
    if use_prefect:
        from sim2radar.flows._states import run_flow
        from sim2radar.flows.capture_dataset import capture_dataset as capture_flow

        summary = run_flow(capture_flow, request=request)
    else:
        from sim2radar.tasks.runner import PlainRunner

        summary = capture_dataset(request, PlainRunner())
    return summary, time.perf_counter() - t0


def _scene_total(summary: dict) -> float:
    return sum(r["total_s"] for r in summary["stage_table"])


def main() -> dict:
    os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
    os.environ.setdefault("PREFECT_LOGGING_LEVEL", "WARNING")
    from sim2radar.factory.captures import write_capture_folder

    with tempfile.TemporaryDirectory(prefix="bench-capture-") as tmp:
        os.environ.setdefault("PREFECT_HOME", os.path.join(tmp, "prefect"))
        caps = os.path.join(tmp, "captures")
        t0 = time.perf_counter()
        write_capture_folder(caps, range(N_SCENES))
        folder_s = time.perf_counter() - t0
        # warm-up on a throw-away store: imports, backends and the tracer's compiled kernels
        # are then ready for both measured runs, so neither pays them alone
        _run(caps, os.path.join(tmp, "warmup"), False)
        plain, plain_wall = _run(caps, os.path.join(tmp, "plain"), False)
        plain2, plain2_wall = _run(caps, os.path.join(tmp, "plain"), False)
        flow, flow_wall = _run(caps, os.path.join(tmp, "flow"), True)
        flow2, flow2_wall = _run(caps, os.path.join(tmp, "flow"), True)
    rows = plain["stage_table"]
    per_step = {s: statistics.fmean(r[f"{s}_s"] for r in rows if r[f"{s}_s"] is not None)
                for s in STEPS}
    frames = sum(r["frames"] for r in rows)
    out = {
        "scenes": N_SCENES, "frames_per_scene": N_FRAMES, "frames": frames,
        "failed": plain["counts"]["failed"] + flow["counts"]["failed"],
        "capture_folder_s": folder_s,
        "seconds_per_scene_plain": _scene_total(plain) / N_SCENES,
        "seconds_per_step_plain": per_step,
        "seconds_per_frame_simulate": per_step["simulate"] * N_SCENES / max(frames, 1),
        "points_per_frame": statistics.fmean(r["points_per_frame"] for r in rows),
        "plain_wall_s": plain_wall, "plain_cached_wall_s": plain2_wall,
        "flow_wall_s": flow_wall, "flow_cached_wall_s": flow2_wall,
        "seconds_per_scene_flow": _scene_total(flow) / N_SCENES,
        "prefect_overhead_per_scene_s": (_scene_total(flow) - _scene_total(plain)) / N_SCENES,
        "cached_share_plain": _scene_total(plain2) / _scene_total(plain),
        "cached_share_flow": _scene_total(flow2) / _scene_total(flow),
    }
    print(f"capture folder: {N_SCENES} scene(s) rendered in {folder_s:.1f} s; {frames} radar "
          f"frames ({N_FRAMES} poses per scene), {out['points_per_frame']:.0f} points per frame, "
          f"{out['failed']} failed")
    print(f"plain loop: {out['seconds_per_scene_plain']:.2f} s per scene; per step "
          + ", ".join(f"{s} {v:.2f}" for s, v in per_step.items())
          + f" s; simulate {out['seconds_per_frame_simulate']:.3f} s per frame")
    print(f"Prefect tasks per step: {out['seconds_per_scene_flow']:.2f} s per scene -> overhead "
          f"{out['prefect_overhead_per_scene_s']:+.2f} s per scene (goal <= 1 s)")
    print(f"cached rerun: plain {100 * out['cached_share_plain']:.1f} %, flow "
          f"{100 * out['cached_share_flow']:.1f} % of the first run's per-scene time (goal <= 5 %)")
    print(f"wall: plain {plain_wall:.1f} s / cached {plain2_wall:.1f} s; flow {flow_wall:.1f} s "
          f"(API start-up included) / cached {flow2_wall:.1f} s")
    return out


if __name__ == "__main__":
    main()
