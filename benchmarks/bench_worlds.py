"""Procedural worlds benchmark: world generation time and per-frame render time at 640 x 480.

Figures: generation time per world (median over 20 seeds, no rendering), Mitsuba scene build
time per world, and per frame (default RigConfig: 640 x 480, 16 spp, max_depth 3, denoised,
16-beam LiDAR) the total and its parts — exact maps (depth/normals/masks), LiDAR, path
tracing, denoising. The first frame of the first world JIT-compiles Dr.Jit kernels and is
reported separately; the medians are over the following frames (two worlds). CPU time (all
threads) and the load average are printed too, since wall times on a shared 2-core machine
depend on what else runs.

    python -m benchmarks worlds
"""

from __future__ import annotations

import os
import statistics
import time

from sim2radar.hardware import mitsuba_variant
from sim2radar.worlds import RigConfig, generate_world, render_frame, trajectory

N_GEN_SEEDS = 20
WORLD_SEEDS = (1, 2)
FRAMES_PER_WORLD = 3


def main() -> dict:
    variant = mitsuba_variant()
    gen_s = []
    for seed in range(N_GEN_SEEDS):
        t0 = time.perf_counter()
        w = generate_world(seed)
        gen_s.append(time.perf_counter() - t0)
    tris = sum(len(m.faces) for m in w.meshes)

    rig = RigConfig()
    per_frame, per_frame_cpu, parts, scene_s, first = [], [], {}, [], None
    load_before = os.getloadavg()[0]
    for seed in WORLD_SEEDS:
        world = generate_world(seed)
        for pose in trajectory(world, FRAMES_PER_WORLD, seed=0):
            t0, c0 = time.perf_counter(), time.process_time()
            frame = render_frame(world, pose, rig)
            dt, dc = time.perf_counter() - t0, time.process_time() - c0
            t = frame.timings_s
            if t["scene_s"] > 1e-3:
                scene_s.append(t["scene_s"])
            if first is None:
                first = dt
                continue
            per_frame.append(dt - t["scene_s"])
            per_frame_cpu.append(dc)
            for k in ("maps_s", "lidar_s", "path_trace_s", "rgb_s"):
                parts.setdefault(k, []).append(t.get(k, 0.0))
    med = {k: statistics.median(v) for k, v in parts.items()}
    out = {
        "variant": variant,
        "image": f"{rig.width}x{rig.height}",
        "spp": rig.spp,
        "generate_world_s_median": statistics.median(gen_s),
        "generate_world_s_max": max(gen_s),
        "triangles_last_world": tris,
        "scene_build_s_median": statistics.median(scene_s) if scene_s else 0.0,
        "first_frame_s_incl_jit": first,
        "frame_s_median": statistics.median(per_frame),
        "frame_s_max": max(per_frame),
        "maps_s_median": med["maps_s"],
        "lidar_s_median": med["lidar_s"],
        "path_trace_s_median": med["path_trace_s"],
        "denoise_tonemap_s_median": med["rgb_s"] - med["path_trace_s"],
        "frame_cpu_s_median": statistics.median(per_frame_cpu),
        "frames_timed": len(per_frame),
        "load_average_1min": (load_before, os.getloadavg()[0]),
    }
    print(f"mitsuba variant {variant}; rig {out['image']} @ {rig.spp} spp, max_depth "
          f"{rig.max_depth}, LiDAR {rig.lidar_beams} beams")
    print(f"world generation: median {out['generate_world_s_median'] * 1e3:.0f} ms "
          f"(max {out['generate_world_s_max'] * 1e3:.0f} ms) over {N_GEN_SEEDS} seeds")
    print(f"Mitsuba scene build per world: {out['scene_build_s_median']:.2f} s")
    print(f"first frame incl. JIT: {first:.2f} s")
    print(f"per frame (median of {len(per_frame)}): {out['frame_s_median']:.2f} s "
          f"(max {out['frame_s_max']:.2f} s) = maps {med['maps_s']:.2f} + LiDAR "
          f"{med['lidar_s']:.2f} + path trace {med['path_trace_s']:.2f} + denoise/tonemap "
          f"{out['denoise_tonemap_s_median']:.2f} s")
    print(f"CPU time per frame (all threads): median {out['frame_cpu_s_median']:.2f} s; "
          f"1-min load average before/after {load_before:.1f}/{os.getloadavg()[0]:.1f} "
          "(wall times are inflated when other jobs share the cores)")
    return out


if __name__ == "__main__":
    main()
