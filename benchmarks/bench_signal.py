"""Signal-level reference radar benchmark: seconds per frame and peak memory.

First synthetic corridor path sets (diffuse points on walls, floor, ceiling and an end wall,
20 % two-bounce paths whose departure and arrival points differ) at the ``ti-mmwcas-reference``
preset (12 TX x 16 RX = 192 channels, 256 samples, 64 loops: the full chirp cube, TI's chain),
moving at a walking speed: synthesis, processing and total seconds per frame (median of the
timed frames after one warm-up frame; points only, as the factory runs it: no range-azimuth
heatmap), the torch device, peak resident memory. Then the
reference radar as the factory runs it: procedural corridors (worlds 100000-100002, 3 frames
each along the rig's trajectory), the rig walking at a speed drawn per frame (0.5-1.5 m/s, as
``sim2radar reference``), a new seed per frame — traced paths -> IF -> points, with seconds per
frame (trace, synthesis, processing), Dr.Jit kernels compiled after the first frame, paths and
points per frame and the peak resident memory.

    python -m benchmarks signal
    SIM2RADAR_BENCH_BEV=docs/reference_frame_bev.png python -m benchmarks signal   # + a picture
"""

from __future__ import annotations

import math
import os
import resource
import statistics
import time

import numpy as np

from sim2radar.radar import load_radar_config
from sim2radar.radar.paths import PATH_KINDS, PathSet
from sim2radar.radar.signal import simulate_signal_frame

PATH_COUNTS = (10_000, 30_000, 50_000)
N_FRAMES = 3


def synthetic_paths(n_paths: int, seed: int = 0, speed_mps: float = 1.0) -> PathSet:
    """A corridor-like PathSet: ``n_paths`` diffuse returns, 80 % single-, 20 % two-bounce.

    Points lie on the walls (y = +-1.2 m), floor (z = -1.0 m), ceiling (z = 1.5 m) and an end
    wall (x = 8 m) within 0.5-8 m; each has RCS ~ Exp(mean 1e-3 m^2) and a uniform phase.
    """
    rng = np.random.default_rng(seed)
    surf = rng.integers(0, 5, n_paths)
    x = rng.uniform(0.5, 8.0, n_paths)
    y = rng.uniform(-1.2, 1.2, n_paths)
    z = rng.uniform(-1.0, 1.5, n_paths)
    y = np.where(surf == 0, 1.2, np.where(surf == 1, -1.2, y))
    z = np.where(surf == 2, -1.0, np.where(surf == 3, 1.5, z))
    x = np.where(surf == 4, 8.0, x)
    pts = np.column_stack([x, y, z])
    base = PathSet.point_targets(pts, rng.exponential(1e-3, n_paths),
                                 phase_rad=rng.uniform(0, 2 * math.pi, n_paths))
    two = rng.random(n_paths) < 0.2
    arr = pts.copy()
    arr[two] = pts[rng.permutation(np.nonzero(two)[0])]  # arrive from another point
    inner = np.where(two, np.linalg.norm(arr - pts, axis=1), 0.0)
    length = np.linalg.norm(pts, axis=1) + inner + np.linalg.norm(arr, axis=1)
    amp = base.amplitude * np.where(two, 0.3, 1.0)
    u_dep = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    u_arr = arr / np.linalg.norm(arr, axis=1, keepdims=True)
    rate = -0.5 * (u_dep[:, 0] + u_arr[:, 0]) * speed_mps     # the rig moves along +x
    return PathSet(amplitude=amp, path_length_m=length, departure_point_m=pts,
                   arrival_point_m=arr, range_rate_mps=rate,
                   n_interactions=np.where(two, 2, 1).astype(np.int8),
                   kind=np.full(n_paths, PATH_KINDS["diffuse"], np.int8))


def _peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main() -> dict:
    radar = load_radar_config("ti-mmwcas-reference")
    simulate_signal_frame(synthetic_paths(1000, 99), radar, seed=0)  # warm-up (imports, caches)
    out: dict = {}
    for n in PATH_COUNTS:
        paths = synthetic_paths(n, seed=n)
        rss0 = _peak_rss_mib()
        frames = []
        for i in range(N_FRAMES + 1):
            t0 = time.perf_counter()
            frame = simulate_signal_frame(paths, radar, seed=i, heatmap=False)
            wall = time.perf_counter() - t0
            if i:
                frames.append((frame.stats["seconds_if_total"],
                               frame.stats["seconds_processing"], wall))
        synth, proc, total = (statistics.median(c) for c in zip(*frames, strict=True))
        out[n] = {
            "seconds_synthesis": round(synth, 3),
            "seconds_processing": round(proc, 3),
            "seconds_total": round(total, 3),
            "points": frame.n_points,
            "device": frame.stats["device"],
            "peak_rss_growth_mib": round(_peak_rss_mib() - rss0, 1),
            "peak_rss_mib": round(_peak_rss_mib(), 1),
        }
        print(f"{n:>6} paths: synthesis {synth:.3f} s, processing {proc:.3f} s, total "
              f"{total:.3f} s per frame, {frame.n_points} points, device {frame.stats['device']}, "
              f"peak RSS {out[n]['peak_rss_mib']:.0f} MiB (+{out[n]['peak_rss_growth_mib']:.0f})")
    out["corridors"] = corridor_frames()
    return out


def corridor_frames(seeds=(100_000, 100_001, 100_002), n_frames: int = 3) -> dict:
    """The reference radar on procedural corridors, as ``sim2radar reference`` runs it: the rig
    walking along its heading at a speed drawn per frame, a new seed per frame."""
    import drjit as dr

    from sim2radar.factory import LabelConfig, frame_seed, radar_visibility, scene_ray_caster
    from sim2radar.factory.seeds import frame_speed
    from sim2radar.radar import RadarScene
    from sim2radar.radar.frame import simulate_scene_frame
    from sim2radar.tasks.reference import REFERENCE_SPEED_MPS
    from sim2radar.worlds import RigConfig, generate_world, render_frame, rig_velocity, trajectory

    radar = load_radar_config("ti-mmwcas-reference")
    rows, first, compiled = [], None, 0
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    for seed in seeds:
        world = generate_world(seed)
        scene = RadarScene(list(world.meshes))
        for pose in trajectory(world, n_frames, seed=seed):
            wf = render_frame(world, pose, RigConfig(width=64, height=48, spp=1))
            speed = frame_speed(REFERENCE_SPEED_MPS, 0, seed, pose.index)
            dr.kernel_history()
            t0 = time.perf_counter()
            frame = simulate_scene_frame(scene, radar, wf.radar_to_world,
                                         seed=frame_seed(0, seed, pose.index),
                                         velocity_mps=rig_velocity(wf.radar_to_world, speed))
            wall = time.perf_counter() - t0
            if pose.index > 0:  # a world's first frame may compile for its new scene
                compiled += sum(1 for h in dr.kernel_history() if not h.get("cache_hit", True))
            sec = frame.stats["seconds"]
            rows.append((wall, sec["trace"], sec["synthesis"], sec["processing"],
                         frame.stats["n_paths"], frame.n_points))
            if first is None:
                first = (world, scene, wf, frame)
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    wall, trace, synth, proc, paths, points = (np.array(c, float)
                                               for c in zip(*rows[1:], strict=True))
    res = {
        "frames_timed": len(rows) - 1,
        "seconds_per_frame_median": round(float(np.median(wall)), 3),
        "seconds_per_frame_max": round(float(wall.max()), 3),
        "seconds_trace_median": round(float(np.median(trace)), 3),
        "seconds_synthesis_median": round(float(np.median(synth)), 3),
        "seconds_processing_median": round(float(np.median(proc)), 3),
        "kernels_compiled_after_first_frame": compiled,
        "paths_per_frame_median": int(np.median(paths)),
        "points_per_frame_median": int(np.median(points)),
        "points_per_frame_range": [int(points.min()), int(points.max())],
        "peak_rss_mib": round(_peak_rss_mib(), 1),
    }
    print(f"corridors ({res['frames_timed']} frames after the first, moving rig, a new seed "
          f"each): {res['seconds_per_frame_median']:.2f} s per frame (trace "
          f"{res['seconds_trace_median']:.2f}, synthesis {res['seconds_synthesis_median']:.2f}, "
          f"processing {res['seconds_processing_median']:.2f}; max "
          f"{res['seconds_per_frame_max']:.2f}), {compiled} kernels compiled after each world's "
          f"first frame, {res['paths_per_frame_median']} paths, {res['points_per_frame_median']} "
          f"points per frame (range {res['points_per_frame_range']}), peak RSS "
          f"{res['peak_rss_mib']:.0f} MiB")
    print(f"goals: <= 0.5 s per frame {'met' if res['seconds_per_frame_median'] <= 0.5 else 'NOT met'}"
          f"; <= 2 GiB {'met' if res['peak_rss_mib'] <= 2048 else 'NOT met'}")
    bev_path = os.environ.get("SIM2RADAR_BENCH_BEV")
    if bev_path:
        from sim2radar.visualize import bev_png

        world, scene, wf, frame = first
        labels = LabelConfig()
        view = (radar.azimuth_fov_deg, radar.elevation_fov_deg, radar.max_range_m)
        vis = radar_visibility(wf.door_boxes_radar, scene_ray_caster(scene, wf.radar_to_world),
                               view, labels)
        boxes = wf.door_boxes_radar[vis >= labels.min_visibility]
        bev_png(frame.points, boxes=boxes, box_labels=["door"] * len(boxes),
                fov_deg=radar.azimuth_fov_deg, max_range_m=radar.max_range_m,
                title=f"reference radar (proxy-real), world {seeds[0]} frame 0: "
                      f"{frame.n_points} points", path=bev_path)
        print(f"BEV picture: {bev_path}")
    return res


if __name__ == "__main__":
    main()
